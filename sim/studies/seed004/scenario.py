"""Seed 004's scenario as the offline study's model (:class:`Seed004`, built from the file's
declared settings, :class:`sim.scenario.seed004.Seed004File`: errors are the scenario's one-line
``ScenarioError``), its network document for the peers, and its truth and measurements."""

from __future__ import annotations

import tomllib
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

import numpy as np
from scipy.sparse.csgraph import shortest_path
from sensornet.sim.scenario import ScenarioError, apply_overrides, parse_overrides
from sensornet.sim.scenario.seed004 import (  # noqa: F401  (VARIANTS re-exported)
    VARIANTS,
    Seed004File,
    read_seed004,
)
from sensornet.tracking.gmphd import SensorParams
from sensornet.tracking.idpc import ClusterParams, polar_to_cartesian
from sensornet.tracking.mixture import GaussianMixture
from sensornet.tracking.models import ConstantVelocity, LinearPosition, RangeBearing
from sensornet.tracking.reduction import Reducer

SCENARIO = Path(__file__).parents[2] / "scenarios" / "seed004.toml"
TUPLES_COMPONENT = 15
"""A 4-D Gaussian component: weight 1, mean 4, covariance 10 (seed 004)."""
TUPLES_CARDINALITY = 1

# -- scenario ---------------------------------------------------------------------------------


@dataclass(frozen=True)
class Seed004:
    """The seed-004 scenario as the offline study uses it: a :class:`sim.scenario.Seed004File`
    (every field declared and documented there) with the states and positions as arrays and
    the clustering settings as :class:`tracking.idpc.ClusterParams`."""

    seed: int
    scan_period: float
    num_scans: int
    region: tuple[tuple[float, float], tuple[float, float]]
    variant: str
    truth_sigma_w: float
    starts: np.ndarray
    """(n, 4) target states at scan 1."""
    detection_probability: float
    clutter_rate: float
    sigma: float
    sigma_range: float
    sigma_bearing_deg: float
    radius: float
    positions: np.ndarray
    """(S, 2) sensor positions."""
    sigma_w: float
    survival_probability: float
    birth_weight: float
    birth_cov_diag: tuple[float, ...]
    prune_threshold: float
    merge_threshold: float
    max_components: int
    publish_threshold: float
    cardinality: str
    clustering: ClusterParams
    assumed_scans: str
    estimator: str
    iterations: int
    rounds: tuple[int, ...]
    ospa_cutoff: float
    ospa_order: float

    @classmethod
    def of(cls, f: Seed004File) -> Seed004:
        """The model of the file's settings ``f``."""
        same = {k.name: getattr(f, k.name) for k in fields(cls)
                if k.name not in ("starts", "positions", "clustering")}
        return cls(**same, starts=np.asarray(f.starts, dtype=float).reshape(-1, 4),
                   positions=np.asarray(f.positions, dtype=float).reshape(-1, 2),
                   clustering=ClusterParams(f.cutoff, f.zeta, f.radius_factor, f.split_factor,
                                            detection_probability=f.detection_probability))

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


def load(path: Path = SCENARIO, overrides: Sequence[str] | Mapping[str, Any] = ()) -> Seed004:
    """Read a seed-004 TOML; ``overrides`` are ``KEY=VALUE`` strings (the one ``--set``
    grammar, :func:`sim.scenario.parse_overrides`) or ``{"TABLE.KEY": value}``; an error in an
    overridden key says so."""
    try:
        doc = tomllib.loads(Path(path).read_text())
    except tomllib.TOMLDecodeError as e:
        raise ScenarioError(f"{path}: {e}") from None
    items = overrides if isinstance(overrides, Mapping) else parse_overrides(overrides)
    return from_document(doc, path, apply_overrides(doc, items, str(path)))


def from_document(doc: dict, path: str | Path = "seed004.toml",
                  overridden: Iterable[str] = ()) -> Seed004:
    """The scenario from a parsed seed-004 TOML document (``[network]`` is for the peers),
    read as declared (:func:`sim.scenario.seed004.read_seed004`; ``overridden``: the dotted
    keys overrides wrote); the graph must be connected."""
    scn = Seed004.of(read_seed004({k: v for k, v in doc.items() if k != "network"}, str(path),
                                  overridden))
    if not np.isfinite(scn.hops).all():
        raise ScenarioError(f"{path}: sensors.radius {scn.radius} leaves the graph disconnected")
    return scn


def network_document(doc: dict, label: str = "seed004.toml") -> dict:
    """The seed-004 document as a network scenario (``sim.scenario``'s format): sensors
    ``s1..s20`` at the recorded positions, the graph as custom edges, the three straight-line
    targets over the whole run, the paper's births, and the ``[network]`` table (flooding peers
    by default: ``filter = "flooding"``, ``rounds`` = the flooding iterations)."""
    passed = ("faults", "security")  # network-scenario tables, taken as they are
    try:
        scn = from_document({k: v for k, v in doc.items() if k not in (*passed, "fusion")},
                            label)
    except (TypeError, ValueError) as e:  # ScenarioError too: its message names the label
        raise ScenarioError(str(e) if str(e).startswith(label) else f"{label}: {e}") from None
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
