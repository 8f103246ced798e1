"""Seed 004: measurement flooding + density-peaks clustering against distributed GM-PHD filters.

The offline Monte Carlo of docs/seed004.md on ``sim/scenarios/seed004.toml``: 20 sensors on a
connected random geometric graph of diameter 4, three targets, Pd = 0.95, clutter 10 per sensor.
Every run draws one truth and one scan per sensor per time step (seeded by ``(seed, run)``) and
feeds the same scans to every method:

- ``IDPC``: after complete flooding (``flooding.iterations`` = diameter) every peer holds every
  scan and clusters the pooled plane points with :func:`tracking.idpc.idpc`; all peers compute the
  same estimate. After ``t`` < diameter iterations peer ``i`` holds the scans within ``t`` hops
  (``peers.flooding.flood`` on a loss-free network, tested) and clusters those
  (``S`` = scans held, or all ``S`` sensors with ``flooding.assumed_scans = "all"``): the
  OSPA-against-iterations curve.
- ``FTC``: DBSCAN + k-means (:func:`tracking.idpc.ftc`) on the same pooled set.
- ``local``: each peer's own GM-PHD, no exchange.
- ``GCI L=l`` / ``AA L=l``: every peer runs its GM-PHD on its own scan and publishes its
  posterior (components above ``filter.publish_threshold``); ``l`` consensus rounds follow, each
  fusing a peer's density with its neighbours' by GCI (``cardinality`` rule of the scenario) or
  arithmetic averaging, Metropolis weights; the peer reports the extraction of its fused
  density. The local filters keep their own posteriors (no feedback: our reading).
- ``IC``: the iterated corrector (sensor-by-sensor update) of one GM-PHD over the 20 scans in the
  depth-first order of the graph from sensor 0 (:func:`iterated_corrector`, order
  :func:`peers.flooding.corrector_order`); the density travels along that order. In the network
  (``sensornet run seed004 --set flooding.estimator=ic``) every flooding peer runs the same
  corrector over its pooled scans (:class:`peers.flooding.IcFloodEstimator`).
- ``centralised``: the same iterated-corrector GM-PHD at the peer of least eccentricity, fed by
  every scan routed to it over shortest paths: the estimates are IC's, the cost differs.

Costs are the seed's tuples per peer per scan (a Gaussian component 15, a cardinality 1, a 2-D
measurement 2): flooding ``deg_i sum_{hop(i,j) <= t-1} 2|Z_j|`` (:func:`peers.flooding.
flooding_tuples`); consensus ``deg_i (15 n_i + 1)`` per round; IC ``hops(next) (15 n + 1)`` per
sensor; centralised ``hops(j, centre) 2|Z_j|`` per scan, averaged over the peers. CPU is the
process CPU time (``time.process_time``, so a loaded machine does not inflate it) of the
method's own computation per peer per scan in this single-threaded worker; for GCI and AA it
includes the peer's local GM-PHD step.

``python -m sim.seed004 --runs 20 --jobs 2 --out runs/seed004`` prints the table and writes
``seed004_table.csv``, ``seed004_iterations.csv`` and ``seed004_tradeoff.png``. Runs are
0..N-1 from ``--first-run``; nothing here is tuned on them (the parameters in the TOML were set
before any run).
"""

from __future__ import annotations

import argparse
import csv
import sys
import time
import tomllib
import zlib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import sklearn.cluster  # noqa: F401  (FTC's DBSCAN: imported here, not inside a timed call)
from scipy.sparse.csgraph import shortest_path

from peers.faults import FaultInjector
from peers.flooding import (
    TUPLES_PER_MEASUREMENT,
    Deliver,
    corrector_order,
    flood,
    flooding_bytes,
    flooding_tuples,
)
from protocol.codec import encode
from protocol.messages import Estimate, Scan
from sim.faultplan import FaultPlan, LinkFaults, Uniform
from sim.scenario import FLOOD_ESTIMATORS, MAX_COORDINATE, MAX_ROUNDS, MAX_SENSORS
from sim.studies.pool import map_runs
from tracking.fusion import aa_fuse, gci_fuse, metropolis_weights
from tracking.gmphd import GMPHDFilter, SensorParams, extract, update
from tracking.idpc import ClusterParams, ftc, idpc, polar_to_cartesian
from tracking.metrics import ospa
from tracking.mixture import GaussianMixture
from tracking.models import ConstantVelocity, LinearPosition, RangeBearing
from tracking.reduction import Reducer, keep_above

SCENARIO = Path(__file__).with_name("scenarios") / "seed004.toml"
TUPLES_COMPONENT = 15
"""A 4-D Gaussian component: weight 1, mean 4, covariance 10 (seed 004)."""
TUPLES_CARDINALITY = 1
VARIANTS = ("linear", "range-bearing", "mixed")

# -- scenario ---------------------------------------------------------------------------------


@dataclass(frozen=True)
class Seed004:
    """The seed-004 scenario (``sim/scenarios/seed004.toml``; every field documented there)."""

    seed: int = 4
    scan_period: float = 1.0
    num_scans: int = 60
    region: tuple[tuple[float, float], tuple[float, float]] = ((-1000.0, 1000.0),
                                                               (-1000.0, 1000.0))
    variant: str = "linear"
    truth_sigma_w: float = 0.0
    starts: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))
    detection_probability: float = 0.95
    clutter_rate: float = 10.0
    sigma: float = 10.0
    sigma_range: float = 10.0
    sigma_bearing_deg: float = 0.5
    radius: float = 800.0
    positions: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    sigma_w: float = 2.0
    survival_probability: float = 0.98
    birth_weight: float = 0.05
    birth_cov_diag: tuple[float, ...] = (100.0, 25.0, 100.0, 25.0)
    prune_threshold: float = 1e-5
    merge_threshold: float = 4.0
    max_components: int = 100
    publish_threshold: float = 0.01
    cardinality: str = "separate"
    clustering: ClusterParams = ClusterParams()
    assumed_scans: str = "held"
    estimator: str = "idpc"
    iterations: int = 4
    rounds: tuple[int, ...] = (1, 2, 3, 4)
    ospa_cutoff: float = 100.0
    ospa_order: float = 2.0

    @property
    def adjacency(self) -> np.ndarray:
        p = self.positions
        d = np.linalg.norm(p[:, None, :] - p[None, :, :], axis=-1)
        return (d <= self.radius) & ~np.eye(len(p), dtype=bool)

    @property
    def hops(self) -> np.ndarray:
        return shortest_path(self.adjacency, unweighted=True)

    @property
    def area(self) -> float:
        (x0, x1), (y0, y1) = self.region
        return (x1 - x0) * (y1 - y0)

    def models(self) -> list[LinearPosition | RangeBearing]:
        """One measurement model per sensor, by ``variant``."""
        out = []
        for i, p in enumerate(self.positions):
            pos = (float(p[0]), float(p[1]))
            radar = self.variant == "range-bearing" or (self.variant == "mixed" and i % 2 == 1)
            out.append(RangeBearing(self.sigma_range, float(np.deg2rad(self.sigma_bearing_deg)),
                                    pos) if radar else LinearPosition(self.sigma, pos))
        return out

    def r_max(self, position) -> float:
        """Farthest region corner from ``position`` (range-bearing clutter extent)."""
        (x0, x1), (y0, y1) = self.region
        c = np.array([[x0, y0], [x0, y1], [x1, y0], [x1, y1]])
        return float(np.linalg.norm(c - np.asarray(position), axis=1).max())

    def sensor_params(self, model) -> SensorParams:
        if isinstance(model, RangeBearing):
            kappa = self.clutter_rate / (self.r_max(model.position) * 2 * np.pi)
        else:
            kappa = self.clutter_rate / self.area
        return SensorParams(model, self.detection_probability, kappa)

    def birth(self) -> GaussianMixture:
        n = len(self.starts)
        return GaussianMixture(np.full(n, self.birth_weight), self.starts,
                               np.tile(np.diag(self.birth_cov_diag), (n, 1, 1)))

    def reducer(self) -> Reducer:
        return Reducer(self.prune_threshold, self.merge_threshold, self.max_components)


_KEYS = {
    "scenario": {"name": None, "study": None, "seed": "seed", "scan_period": "scan_period",
                 "num_scans": "num_scans", "region": "region", "variant": "variant"},
    "truth": {"sigma_w": "truth_sigma_w", "starts": "starts"},
    "sensors": {"detection_probability": "detection_probability",
                "clutter_rate": "clutter_rate", "sigma": "sigma", "sigma_range": "sigma_range",
                "sigma_bearing_deg": "sigma_bearing_deg", "radius": "radius",
                "positions": "positions"},
    "filter": {k: k for k in ("sigma_w", "survival_probability", "birth_weight",
                              "birth_cov_diag", "prune_threshold", "merge_threshold",
                              "max_components", "publish_threshold", "cardinality")},
    "clustering": {k: k for k in ("cutoff", "zeta", "radius_factor", "split_factor")},
    "flooding": {"iterations": "iterations", "assumed_scans": "assumed_scans",
                 "estimator": "estimator"},
    "consensus": {"rounds": "rounds"},
    "metrics": {"ospa_cutoff": "ospa_cutoff", "ospa_order": "ospa_order"},
}


class ScenarioError(ValueError):
    """A scenario file or ``--set`` value the loader refuses (one line naming the key)."""


def load(path: Path = SCENARIO, overrides: Sequence[str] | Mapping[str, Any] = ()) -> Seed004:
    """Read a seed-004 TOML; ``overrides`` are ``TABLE.KEY=VALUE`` strings (TOML values) or
    ``{"TABLE.KEY": value}`` (already parsed)."""
    try:
        doc = tomllib.loads(Path(path).read_text())
        items = (overrides.items() if isinstance(overrides, Mapping) else
                 ((k, v) for k, _, v in (item.partition("=") for item in overrides)))
        for key, value in items:
            table, dot, name = key.partition(".")
            if not dot or not name:
                raise ScenarioError(f"--set {key!r}: expected TABLE.KEY=VALUE")
            if not isinstance(overrides, Mapping):
                value = tomllib.loads(f"v = {value}")["v"]
            doc.setdefault(table, {})[name] = value
    except tomllib.TOMLDecodeError as e:
        raise ScenarioError(f"{path}: {e}") from None
    return from_document(doc, path)


def from_document(doc: dict, path: str | Path = "seed004.toml") -> Seed004:
    """The scenario from a parsed seed-004 TOML document (``[network]`` is for the peers)."""
    kw: dict = {}
    cluster: dict = {}
    for table, values in doc.items():
        if table == "network":
            continue  # the peers' settings (network_document)
        if table not in _KEYS:
            raise ScenarioError(f"{path}: unknown table [{table}]")
        for k, v in values.items():
            if k not in _KEYS[table]:
                raise ScenarioError(f"{path}: unknown key {table}.{k}")
            if table == "clustering":
                cluster[k] = float(v)
            elif _KEYS[table][k] is not None:
                kw[_KEYS[table][k]] = v
    for k in ("starts", "positions"):
        if k in kw:
            kw[k] = np.asarray(kw[k], dtype=float)
    for k in ("region", "birth_cov_diag", "rounds"):
        if k in kw:
            kw[k] = tuple(tuple(r) if isinstance(r, list) else r for r in kw[k])
    scn = Seed004(**kw)
    _check_sizes(scn, path)
    if scn.assumed_scans not in ("held", "all"):
        raise ScenarioError(f"{path}: flooding.assumed_scans {scn.assumed_scans!r}: "
                            f"expected 'held' or 'all'")
    if scn.estimator not in FLOOD_ESTIMATORS:
        raise ScenarioError(f"{path}: flooding.estimator {scn.estimator!r}: expected one of "
                            f"{', '.join(map(repr, FLOOD_ESTIMATORS))}")
    if scn.variant not in VARIANTS:
        raise ScenarioError(f"{path}: scenario.variant {scn.variant!r}: expected {VARIANTS}")
    scn = replace(scn, clustering=ClusterParams(**cluster, detection_probability=float(
        scn.detection_probability)))
    if not np.isfinite(scn.hops).all():
        raise ScenarioError(f"{path}: sensors.radius {scn.radius} leaves the graph disconnected")
    return scn


def _check_sizes(scn: Seed004, path: str | Path) -> None:
    """The bounds of ``sim.scenario`` (MAX_SENSORS, MAX_ROUNDS, MAX_COORDINATE), checked
    before anything is built from the sizes (the graph is sensors x sensors)."""
    n = len(scn.positions)
    if scn.positions.ndim != 2 or scn.positions.shape[1] != 2:
        raise ScenarioError(f"{path}: sensors.positions must be a list of [x, y] pairs")
    if n > MAX_SENSORS:
        raise ScenarioError(f"{path}: sensors.positions lists {n:,} sensors, over the limit "
                            f"of {MAX_SENSORS}")
    rounds = [scn.iterations, *scn.rounds]
    if not all(isinstance(r, int) and 1 <= r <= MAX_ROUNDS for r in rounds):
        raise ScenarioError(f"{path}: flooding.iterations and consensus.rounds must be "
                            f"integers in 1..{MAX_ROUNDS}, got {scn.iterations!r} and "
                            f"{list(scn.rounds)!r}")
    try:
        region = np.asarray(scn.region, dtype=float).reshape(2, 2)
        coords = np.concatenate([region.ravel(), scn.positions.ravel()])
    except (TypeError, ValueError):
        raise ScenarioError(f"{path}: scenario.region must be [[xmin, xmax], [ymin, ymax]] "
                            f"(m)") from None
    if not (region[:, 0] < region[:, 1]).all():
        raise ScenarioError(f"{path}: scenario.region must have xmin < xmax and ymin < ymax "
                            f"(a non-empty area)")
    if not (np.isfinite(coords).all() and (np.abs(coords) <= MAX_COORDINATE).all()):
        raise ScenarioError(f"{path}: scenario.region and sensors.positions must be finite "
                            f"and within +-{MAX_COORDINATE:g} m")


def network_document(doc: dict, label: str = "seed004.toml") -> dict:
    """The seed-004 document as a network scenario (``sim.scenario``'s format): sensors
    ``s1..s20`` at the recorded positions, the graph as custom edges, the three straight-line
    targets over the whole run, the paper's births, and the ``[network]`` table (flooding peers
    by default: ``filter = "flooding"``, ``rounds`` = the flooding iterations)."""
    import sim.scenario as sc

    passed = ("faults", "security")  # network-scenario tables, taken as they are
    try:
        scn = from_document({k: v for k, v in doc.items() if k not in (*passed, "fusion")},
                            label)
    except (ScenarioError, TypeError, ValueError) as e:
        raise sc.ScenarioError(str(e) if str(e).startswith(label) else f"{label}: {e}") \
            from None
    names = [f"s{i + 1}" for i in range(len(scn.positions))]
    K, T = scn.num_scans, scn.scan_period
    sensors = []
    for i, model in enumerate(scn.models()):
        radar = isinstance(model, RangeBearing)
        spec = {"name": names[i], "kind": "range-bearing" if radar else "linear",
                "position": [float(v) for v in scn.positions[i]],
                "sigma_r": scn.sigma_range if radar else scn.sigma,
                "detection_probability": scn.detection_probability,
                "clutter_rate": scn.clutter_rate}
        if radar:
            spec["sigma_theta_deg"] = scn.sigma_bearing_deg
        sensors.append(spec)
    targets = [{"birth_scan": 1, "death_scan": K, "start": [float(x[0]), float(x[2])],
                "end": [float(x[0] + x[1] * (K - 1) * T), float(x[2] + x[3] * (K - 1) * T)]}
               for x in scn.starts]
    cov = np.diag(scn.birth_cov_diag).tolist()
    A = scn.adjacency
    edges = [[names[i], names[j]] for i, j in zip(*np.nonzero(np.triu(A)), strict=True)]
    network = {"topology": "custom", "edges": edges, "rounds": scn.iterations,
               "filter": "flooding", "speed": 10.0, "deadline": 0.8, **doc.get("network", {})}
    c = scn.clustering
    return {
        "scenario": {"name": doc.get("scenario", {}).get("name", "seed004"), "seed": scn.seed,
                     "scan_period": T, "num_scans": K,
                     "region": [list(r) for r in scn.region],
                     "truth_sigma_w": scn.truth_sigma_w},
        "motion": {"model": "cv", "sigma_w": scn.sigma_w,
                   "survival_probability": scn.survival_probability},
        "targets": targets,
        "sensors": sensors,
        "birth": {"model": "paper", "paper": [
            {"weight": scn.birth_weight, "mean": [float(v) for v in m], "cov": cov}
            for m in scn.starts]},
        "filter": {"prune_threshold": scn.prune_threshold,
                   "merge_threshold": scn.merge_threshold,
                   "max_components": scn.max_components, "extraction": "cardinality"},
        "fusion": {"level2_threshold": scn.publish_threshold,  # the default rule (hybrid)
                   "cardinality": scn.cardinality, **doc.get("fusion", {})},
        "metrics": {"ospa_cutoff": scn.ospa_cutoff, "ospa_order": scn.ospa_order},
        "network": network,
        **{k: doc[k] for k in passed if k in doc},
        "clustering": {"cutoff": c.cutoff, "zeta": c.zeta, "radius_factor": c.radius_factor,
                       "split_factor": c.split_factor, "assumed_scans": scn.assumed_scans,
                       "estimator": scn.estimator},
    }


# -- truth and scans --------------------------------------------------------------------------


def truth(scn: Seed004, rng: np.random.Generator) -> np.ndarray:
    """``(K, n, 4)`` target states (every target alive at every scan, our reading)."""
    cv = ConstantVelocity(scn.scan_period, scn.truth_sigma_w)
    F, Q = cv.transition(1)
    X = np.empty((scn.num_scans, len(scn.starts), 4))
    X[0] = scn.starts
    for k in range(1, scn.num_scans):
        X[k] = X[k - 1] @ F.T
        if scn.truth_sigma_w > 0:
            X[k] += rng.multivariate_normal(np.zeros(4), Q, size=len(scn.starts))
    return X


def measure(scn: Seed004, models, x: np.ndarray, rng: np.random.Generator) -> list[np.ndarray]:
    """One scan per sensor ``(m_i, 2)`` in its measurement space: detections, then clutter."""
    (x0, x1), (y0, y1) = scn.region
    out = []
    for model in models:
        seen = x[rng.random(len(x)) < scn.detection_probability]
        z, _ = model.predict(seen) if len(seen) else (np.zeros((0, 2)), None)
        z = z + rng.standard_normal(z.shape) @ np.linalg.cholesky(model.R).T
        nc = rng.poisson(scn.clutter_rate)
        if isinstance(model, RangeBearing):
            c = np.column_stack((rng.uniform(0, scn.r_max(model.position), nc),
                                 rng.uniform(-np.pi, np.pi, nc)))
        else:
            c = np.column_stack((rng.uniform(x0, x1, nc), rng.uniform(y0, y1, nc)))
        out.append(np.concatenate((z.reshape(-1, 2), c)))
    return out


def to_plane(models, scans: Sequence[np.ndarray]) -> list[np.ndarray]:
    """Scans projected to plane points (range-bearing converted to Cartesian)."""
    return [polar_to_cartesian(z, m.position) if isinstance(m, RangeBearing) else z
            for m, z in zip(models, scans, strict=True)]


# -- one run ----------------------------------------------------------------------------------


@dataclass
class Tally:
    """Sums over scans (and peers) for one method in one run."""

    ospa: float = 0.0
    card_err: float = 0.0
    card_ok: float = 0.0
    tuples: float = 0.0
    cpu: float = 0.0
    bytes: float = 0.0
    n: int = 0

    def add(self, est: np.ndarray, x: np.ndarray, scn: Seed004, tuples: float = 0.0,
            cpu: float = 0.0, nbytes: float = 0.0) -> None:
        self.ospa += ospa(est, x, scn.ospa_cutoff, scn.ospa_order)
        err = abs(len(est) - len(x))
        self.card_err += err
        self.card_ok += err == 0
        self.tuples += tuples
        self.cpu += cpu
        self.bytes += nbytes
        self.n += 1

    def means(self) -> dict[str, float]:
        n = max(self.n, 1)
        return {"ospa": self.ospa / n, "card_err": self.card_err / n,
                "card_ok": self.card_ok / n, "tuples": self.tuples / n,
                "cpu_ms": 1e3 * self.cpu / n, "bytes": self.bytes / n}


def _positions(mix: GaussianMixture) -> np.ndarray:
    return extract(mix, 0.5, "cardinality")[:, [0, 2]]


def _n_bytes(mix: GaussianMixture, k: int, rnd: int = 0) -> int:
    """Encoded size of ``mix`` as one estimate message (the peers' wire format)."""
    return len(encode(Estimate("s20", k, mix, round=rnd, seq=k, send_time=float(k))))


def _n_tuples(mix: GaussianMixture) -> int:
    return TUPLES_COMPONENT * len(mix) + TUPLES_CARDINALITY


REFERENCE_MIXTURE = (4, 4)
"""The reference's GM-exchange count (docs/seed004.md): 4-component mixtures, 4 rounds."""


def gm_exchange_tuples(adjacency: np.ndarray, components: int, rounds: int) -> float:
    """Closed form of the tuples per peer per scan of ``rounds`` consensus rounds in which every
    peer sends a ``components``-component mixture and its cardinality to each neighbour:
    ``mean_i deg_i (15 components + 1) rounds``."""
    deg = np.asarray(adjacency, dtype=bool).sum(axis=1)
    return float(deg.mean() * (TUPLES_COMPONENT * components + TUPLES_CARDINALITY) * rounds)


def reference_comparison(result: dict[str, dict[str, float]], adjacency: np.ndarray) -> str:
    """One line: flooding's tuples against the reference's GM exchange (closed form on this
    graph) and against the measured GCI/AA rows with as many rounds."""
    comps, rounds = REFERENCE_MIXTURE
    gm = gm_exchange_tuples(adjacency, comps, rounds)
    flood = result["IDPC"]["tuples"]
    line = (f"flooding {flood:.0f} tuples / peer / scan = {flood / gm:.2f} x the reference's "
            f"exchange of {comps}-component mixtures over {rounds} rounds ({gm:.0f}, closed "
            f"form on this graph; reference: about 4,100 against 2,000)")
    measured = [f"{flood / result[n]['tuples']:.2f} x {n}" for n in (f"GCI L={rounds}",
                                                                     f"AA L={rounds}")
                if n in result and result[n]["tuples"] > 0]
    return line + (f"; measured: {', '.join(measured)}" if measured else "")


def iterated_corrector(mix: GaussianMixture, scans: Sequence[np.ndarray],
                       sensors: Sequence[SensorParams], order: Sequence[int], reducer: Reducer,
                       prune_threshold: float) -> list[GaussianMixture]:
    """The IC of seed 004 (docs/seed004.md): the prediction ``mix`` corrected with ``scans[s]``
    by ``sensors[s]`` for ``s`` in ``order``, reduced after each sensor; the density after each
    sensor (the last is the posterior)."""
    out = []
    for s in order:
        mix = reducer(update(mix, scans[s], sensors[s], None, prune_threshold))
        out.append(mix)
    return out


def run_once(scn: Seed004, run: int, consensus: bool = True) -> dict[str, dict[str, float]]:
    """Every method on run ``run``'s truth and scans; per-method means over scans and peers.

    ``consensus=False`` leaves out the GCI and AA rounds (most of the time of a run).
    """
    root = np.random.default_rng([scn.seed, run])
    rng_truth, rng_scan, rng_cluster = root.spawn(3)
    models = scn.models()
    S, A, hops = len(models), scn.adjacency, scn.hops
    deg = A.sum(axis=1)
    diameter = int(hops.max())
    full = max(scn.iterations, diameter)
    W = metropolis_weights(A)
    nbrs = [np.flatnonzero(A[i]) for i in range(S)]
    cv = ConstantVelocity(scn.scan_period, scn.sigma_w)
    birth, reducer = scn.birth(), scn.reducer()
    sensors = [scn.sensor_params(m) for m in models]
    local = [GMPHDFilter(cv, [s], birth, scn.survival_probability, reducer) for s in sensors]
    mixes = [f.initial() for f in local]
    order = corrector_order(A)
    ecc = hops.max(axis=1)
    centre = int(np.argmin(ecc))
    ic_mix = GaussianMixture.empty(4)
    tallies: dict[str, Tally] = {}

    def tally(name: str) -> Tally:
        return tallies.setdefault(name, Tally())

    X = truth(scn, rng_truth)
    names = [f"s{i + 1}" for i in range(S)]  # as the network scenario names them
    for k in range(scn.num_scans):
        x = X[k][:, [0, 2]]
        scans = measure(scn, models, X[k], rng_scan)
        plane = to_plane(models, scans)
        sizes = np.array([len(z) for z in scans])
        # flooding + clustering: the full pooled set, then what t < diameter iterations leave
        pooled = np.concatenate(plane)
        t0 = time.process_time()
        est_idpc = idpc(pooled, S, scn.clustering, rng_cluster).centres
        dt = time.process_time() - t0
        flood_cost = float(flooding_tuples(hops, sizes, full).mean())
        flood_bytes = flooding_bytes(hops, scans, full, names, k + 1).cumsum(axis=1)
        tally("IDPC").add(est_idpc, x, scn, flood_cost, dt, flood_bytes[:, -1].mean())
        t0 = time.process_time()
        est = ftc(pooled, S, scn.clustering, rng_cluster).centres
        tally("FTC").add(est, x, scn, flood_cost, time.process_time() - t0,
                         flood_bytes[:, -1].mean())
        for t in range(1, full + 1):
            cost = flooding_tuples(hops, sizes, t)
            for i in range(S):
                held = hops[i] <= t
                t0 = time.process_time()
                if held.all():
                    out, dt_i = est_idpc, dt
                else:
                    n_scans = int(held.sum()) if scn.assumed_scans == "held" else S
                    out = idpc(np.concatenate([plane[j] for j in np.flatnonzero(held)]),
                               n_scans, scn.clustering, rng_cluster).centres
                    dt_i = time.process_time() - t0
                tally(f"IDPC t={t}").add(out, x, scn, float(cost[i]), dt_i,
                                         float(flood_bytes[i, t - 1]))
        # local GM-PHD filters, then consensus on what they publish
        cpu_local = np.zeros(S)
        for i in range(S):
            t0 = time.process_time()
            mixes[i] = local[i].step(mixes[i], scans[i])
            cpu_local[i] = time.process_time() - t0
            tally("local").add(_positions(mixes[i]), x, scn, 0.0, cpu_local[i])
        rules = (("GCI", _gci(scn, reducer)), ("AA", _aa(reducer))) if consensus else ()
        for rule, fuse in rules:
            dens = [keep_above(m, scn.publish_threshold) for m in mixes]
            tuples, cpu, nbytes = np.zeros(S), cpu_local.copy(), np.zeros(S)
            for r in range(1, max(scn.rounds) + 1):
                tuples += deg * np.array([_n_tuples(d) for d in dens])
                nbytes += deg * np.array([_n_bytes(d, k + 1, r - 1) for d in dens])
                new = []
                for i in range(S):
                    t0 = time.process_time()
                    group = [dens[i]] + [dens[j] for j in nbrs[i]]
                    w = np.concatenate(([W[i, i]], W[i, nbrs[i]]))
                    new.append(fuse(group, w / w.sum()))
                    cpu[i] += time.process_time() - t0
                dens = [keep_above(d, scn.publish_threshold) for d in new]
                if r in scn.rounds:
                    for i in range(S):
                        tally(f"{rule} L={r}").add(_positions(new[i]), x, scn, tuples[i], cpu[i],
                                                   nbytes[i])
        # iterated corrector along the depth-first order; centralised: the same at the centre
        t0 = time.process_time()
        passes = iterated_corrector(local[0].predict(ic_mix), scans, sensors, order, reducer,
                                    scn.prune_threshold)
        ic_mix = passes[-1]
        ic_tuples, ic_bytes = 0.0, 0.0
        for s, nxt, mix in zip(order, np.roll(order, -1), passes, strict=True):
            ic_tuples += hops[s, nxt] * _n_tuples(mix)
            ic_bytes += hops[s, nxt] * _n_bytes(mix, k + 1)
        dt = time.process_time() - t0
        est = _positions(ic_mix)
        tally("IC").add(est, x, scn, ic_tuples / S, dt / S, ic_bytes / S)
        routed = float((hops[:, centre] * TUPLES_PER_MEASUREMENT * sizes).sum())
        routed_bytes = sum(hops[j, centre] * len(encode(Scan(names[j], k + 1, scans[j], seq=k + 1,
                                                             send_time=float(k + 1))))
                           for j in range(S))
        tally("centralised").add(est, x, scn, routed / S, dt / S, routed_bytes / S)
    return {name: t.means() for name, t in tallies.items()}


def _gci(scn: Seed004, reducer: Reducer):
    def fuse(group, w):
        return gci_fuse(group, w, reduce=reducer, cardinality=scn.cardinality)
    return fuse


def _aa(reducer: Reducer):
    def fuse(group, w):
        return aa_fuse(group, w, reduce=reducer)
    return fuse


# -- flooding under the fault layer ----------------------------------------------------------


def fault_delivery(injector: FaultInjector, names: Sequence[str], k: int, interval: float,
                   slot: float) -> Deliver:
    """``peers.flooding.flood``'s ``deliver`` from the fault layer: each forward of scan
    ``(origin, k)`` in iteration ``it`` on ``s -> r`` is one message to
    :meth:`peers.faults.FaultInjector.decide`, keyed ``(k, it, crc32("flood/" + origin))`` at
    the scan time ``k * interval``; its delays are returned in iterations of ``slot`` s."""
    def deliver(i: int, j: int, key: tuple[int, int], it: int) -> list[float]:
        origin = names[key[0]]
        delays = injector.decide(names[i], names[j], k * interval, f"flood/{origin}/{k}/{it}",
                                 (k & 0xFFFFFFFF, it, zlib.crc32(f"flood/{origin}".encode())))
        return [d / slot for d in delays]
    return deliver


def flooding_under_faults(scn: Seed004, plan: FaultPlan, scans: int = 60, seed: int = 0,
                          deadline: float = 0.5) -> dict[str, float]:
    """Flood ``scans`` scan indices through ``plan``'s faults, ``scn.iterations`` iterations of
    ``deadline * scan_period / iterations`` s each: the share of (peer, scan) pairs holding
    every scan, and missing, duplicate and late scans per peer per scan."""
    names = [f"s{i + 1}" for i in range(len(scn.positions))]
    injector = FaultInjector(plan, seed)
    slot = deadline * scn.scan_period / scn.iterations
    S = len(names)
    rng = np.random.default_rng([scn.seed, seed])
    complete = missing = dup = late = 0.0
    for k in range(1, scans + 1):
        z = [np.zeros((rng.poisson(scn.clutter_rate + 3 * scn.detection_probability), 2))
             for _ in range(S)]
        out = flood(scn.adjacency, z, scn.iterations, k,
                    deliver=fault_delivery(injector, names, k, scn.scan_period, slot))
        sizes = np.array([len(h) for h in out.held])
        complete += (sizes == S).sum()
        missing += (S - sizes).sum()
        dup += out.duplicates.sum()
        late += out.late.sum()
    n = scans * S
    return {"complete": complete / n, "missing": missing / n, "duplicates": dup / n,
            "late": late / n}


# -- Monte Carlo ------------------------------------------------------------------------------


def run_experiment(scn: Seed004, runs: Sequence[int], jobs: int = 1, progress: bool = True,
                   consensus: bool = True) -> dict[str, dict[str, float]]:
    """Mean over ``runs`` of every method's per-run means (and the OSPA standard error)."""
    per_run = map_runs(run_once, [(scn, r, consensus) for r in runs], jobs, "runs", progress)
    return aggregate(per_run)


def aggregate(per_run: list[dict[str, dict[str, float]]]) -> dict[str, dict[str, float]]:
    """Mean over runs (in run order) of every method's per-run means, and the OSPA s.e."""
    out: dict[str, dict[str, float]] = {}
    for name in per_run[0]:
        rows = [pr[name] for pr in per_run]
        out[name] = {k: float(np.mean([r[k] for r in rows])) for k in rows[0]}
        o = np.array([r["ospa"] for r in rows])
        out[name]["ospa_se"] = float(o.std(ddof=1) / np.sqrt(len(o))) if len(o) > 1 else 0.0
    return out


TABLE_ROWS = ("IDPC", "FTC", "GCI L=1", "GCI L=2", "GCI L=3", "GCI L=4", "AA L=1", "AA L=2",
              "AA L=3", "AA L=4", "IC", "centralised", "local")


def table_rows(result: dict[str, dict[str, float]]) -> list[str]:
    return [n for n in TABLE_ROWS if n in result]


def format_table(result: dict[str, dict[str, float]]) -> str:
    lines = ["| method | mean OSPA (m) | ± s.e. | card. error | scans card. right | "
             "tuples / peer / scan | bytes / peer / scan | CPU ms / peer / scan |",
             "|---|---|---|---|---|---|---|---|"]
    for n in table_rows(result) + [k for k in result if k.startswith("IDPC t=")]:
        r = result[n]
        lines.append(f"| {n} | {r['ospa']:.2f} | {r['ospa_se']:.2f} | {r['card_err']:.3f} | "
                     f"{100 * r['card_ok']:.1f} % | {r['tuples']:.0f} | "
                     f"{r.get('bytes', float('nan')):.0f} | {r['cpu_ms']:.2f} |")
    return "\n".join(lines)


def table_title(scn: Seed004, runs: range) -> str:
    """The line above the table: the variant, the graph, the clutter and the runs."""
    deg = scn.adjacency.sum(axis=1)
    return (f"seed 004, {scn.variant}, {len(scn.positions)} sensors (diameter "
            f"{int(scn.hops.max())}, mean degree {deg.mean():.1f}), clutter "
            f"{scn.clutter_rate:g}, runs {runs.start}..{runs.stop - 1}")


def write_outputs(result: dict[str, dict[str, float]], folder: Path, title: str) -> list[Path]:
    """``seed004_table.csv``, ``seed004_iterations.csv``, ``seed004_tradeoff.png``."""
    folder.mkdir(parents=True, exist_ok=True)
    keys = ("ospa", "ospa_se", "card_err", "card_ok", "tuples", "cpu_ms", "bytes")
    table = folder / "seed004_table.csv"
    with table.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(("method", *keys))
        for n in table_rows(result):
            w.writerow((n, *(f"{result[n][k]:.6g}" for k in keys)))
    iters = sorted((int(k.split("=")[1]), k) for k in result if k.startswith("IDPC t="))
    it_csv = folder / "seed004_iterations.csv"
    with it_csv.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(("iterations", *keys))
        for t, k in iters:
            w.writerow((t, *(f"{result[k][kk]:.6g}" for kk in keys)))
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a, b) = plt.subplots(1, 2, figsize=(12, 4.8))
    colours = plt.get_cmap("tab20").colors
    for i, n in enumerate(table_rows(result)):
        r = result[n]
        a.errorbar(max(r["tuples"], 1.0), r["ospa"], yerr=r["ospa_se"], fmt="osD^v"[i % 5],
                   color=colours[i % len(colours)], label=n, markersize=7)
    a.legend(fontsize=8, ncol=2, loc="lower left")
    a.set_xscale("log")
    a.set_xlabel("tuples per peer per scan (log; local = 1)")
    a.set_ylabel("mean OSPA (m), c = 100, p = 2")
    a.set_title("OSPA against communication cost")
    a.grid(True, which="both", alpha=0.3)
    ts = [t for t, _ in iters]
    b.errorbar(ts, [result[k]["ospa"] for _, k in iters],
               yerr=[result[k]["ospa_se"] for _, k in iters], fmt="o-", label="IDPC")
    b.set_xticks(ts)
    b.set_xlabel("flooding iterations completed (diameter 4)")
    b.set_ylabel("mean OSPA (m)")
    b.set_title("IDPC against incomplete flooding")
    b.grid(True, alpha=0.3)
    fig.suptitle(title)
    fig.tight_layout()
    png = folder / "seed004_tradeoff.png"
    fig.savefig(png, dpi=110)
    plt.close(fig)
    return [table, it_csv, png]


def read_outputs(folder: Path) -> dict[str, dict[str, float]]:
    """The result dict back from ``seed004_table.csv`` and ``seed004_iterations.csv``."""
    out: dict[str, dict[str, float]] = {}
    for row in csv.DictReader((folder / "seed004_table.csv").open()):
        name = row.pop("method")
        out[name] = {k: float(v) for k, v in row.items()}
    for row in csv.DictReader((folder / "seed004_iterations.csv").open()):
        t = row.pop("iterations")
        out[f"IDPC t={t}"] = {k: float(v) for k, v in row.items()}
    return out


def main(argv: Sequence[str] | None = None) -> int:
    doc = (__doc__ or "").split("\n")[0]
    p = argparse.ArgumentParser(prog="python -m sim.seed004", description=doc)
    p.add_argument("--runs", type=int, default=20, help="Monte Carlo runs")
    p.add_argument("--first-run", type=int, default=0, help="first run index")
    p.add_argument("--jobs", type=int, default=1, help="worker processes")
    p.add_argument("--scenario", type=Path, default=SCENARIO)
    p.add_argument("--set", action="append", default=[], metavar="TABLE.KEY=VALUE",
                   help="override a scenario value (TOML syntax), e.g. scenario.variant='mixed'")
    p.add_argument("--out", type=Path, help="write the CSVs and the PNG here")
    p.add_argument("--no-consensus", action="store_true",
                   help="leave out GCI and AA (fast: flooding, IC, centralised, local only)")
    p.add_argument("--flood-loss", metavar="P1,P2,...",
                   help="only measure flooding completion under these link-loss probabilities "
                        "(fault layer, 0-20 ms uniform delay, deadline 0.5 scan)")
    p.add_argument("--replot", metavar="TITLE",
                   help="redraw the PNG in --out from its CSVs (no runs) with this title")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    a = p.parse_args(argv)
    if a.replot is not None:
        if a.out is None:
            p.error("--replot needs --out")
        print(f"wrote {write_outputs(read_outputs(a.out), a.out, a.replot)[-1]}")
        return 0
    try:
        scn = load(a.scenario, a.set)
    except (ScenarioError, OSError) as e:
        print(f"seed004: {e}", file=sys.stderr)
        return 2
    if a.runs < 1 or a.jobs < 1:
        print("seed004: --runs and --jobs must be at least 1", file=sys.stderr)
        return 2
    if a.flood_loss:
        print("| link loss | (peer, scan) complete | missing / peer / scan | duplicates | late |")
        print("|---|---|---|---|---|")
        for p_loss in (float(x) for x in a.flood_loss.split(",")):
            plan = FaultPlan(LinkFaults(delay=Uniform(0.0, 0.02), loss=p_loss),
                             interval=scn.scan_period)
            r = flooding_under_faults(scn, plan, scn.num_scans, a.first_run)
            print(f"| {p_loss:g} | {100 * r['complete']:.1f} % | {r['missing']:.3f} | "
                  f"{r['duplicates']:.1f} | {r['late']:.3f} |")
        return 0
    runs = range(a.first_run, a.first_run + a.runs)
    t0 = time.monotonic()
    result = run_experiment(scn, runs, a.jobs, not a.quiet, not a.no_consensus)
    title = table_title(scn, runs)
    print(title)
    print(format_table(result))
    print(reference_comparison(result, scn.adjacency))
    print(f"({time.monotonic() - t0:.0f} s)")
    if a.out:
        for path in write_outputs(result, a.out, title):
            print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
