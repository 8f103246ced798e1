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

``python -m sensornet.sim.studies.seed004.montecarlo --runs 20 --jobs 2 --out runs/seed004`` prints
the table and
writes
``seed004_table.csv``, ``seed004_iterations.csv`` and ``seed004_tradeoff.png``. Runs are
0..N-1 from ``--first-run``; nothing here is tuned on them (the parameters in the TOML were set
before any run).
"""

from __future__ import annotations

import sys
import time
import zlib
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

try:  # FTC's DBSCAN: imported here, not inside a timed call (optional: 'sensornet[baselines]')
    import sklearn.cluster  # noqa: F401
except ImportError:  # the FTC rows then say what to install (tracking.idpc.dbscan_class)
    pass

from sensornet.peers.faultplan import FaultPlan
from sensornet.peers.faults import FaultInjector
from sensornet.peers.flooding import (
    TUPLES_PER_MEASUREMENT,
    Deliver,
    corrector_order,
    flood,
    flooding_bytes,
    flooding_tuples,
)
from sensornet.protocol.codec import encode
from sensornet.protocol.messages import Estimate, Scan
from sensornet.sim import studies
from sensornet.sim.run.pool import map_runs
from sensornet.sim.studies.seed004.output import (  # noqa: F401  (re-exported)
    REFERENCE_MIXTURE,
    TABLE_ROWS,
    format_table,
    gm_exchange_tuples,
    read_outputs,
    reference_comparison,
    report_text,
    table_rows,
    table_title,
    write_outputs,
)
from sensornet.sim.studies.seed004.scenario import (  # noqa: F401  (re-exported)
    SCENARIO,
    TUPLES_CARDINALITY,
    TUPLES_COMPONENT,
    VARIANTS,
    ScenarioError,
    Seed004,
    from_document,
    load,
    measure,
    network_document,
    to_plane,
    truth,
)
from sensornet.tracking.fusion import gci_fuse
from sensornet.tracking.fusion_rules import aa_fuse, metropolis_weights
from sensornet.tracking.gmphd import GMPHDFilter, SensorParams, extract, update
from sensornet.tracking.idpc import dbscan_class, ftc, idpc
from sensornet.tracking.metrics import ospa
from sensornet.tracking.mixture import GaussianMixture
from sensornet.tracking.models import ConstantVelocity
from sensornet.tracking.reduction import Reducer, keep_above

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


@dataclass(frozen=True)
class _Net:
    """The graph quantities of a run (seed 004's 20-sensor random geometric graph)."""

    A: np.ndarray
    """(S, S) adjacency."""
    hops: np.ndarray
    """(S, S) shortest-path hop counts."""
    full: int
    """Flooding iterations run: at least the diameter, so every scan is pooled."""
    names: list[str]
    """Sensor names ``s1..sS``, as the network scenario names them."""

    @property
    def size(self) -> int:
        return len(self.A)


def _tally(tallies: dict[str, Tally], name: str) -> Tally:
    return tallies.setdefault(name, Tally())


def run_once(scn: Seed004, run: int, consensus: bool = True) -> dict[str, dict[str, float]]:
    """Every method on run ``run``'s truth and scans; per-method means over scans and peers.

    ``consensus=False`` leaves out the GCI and AA rounds (most of the time of a run).
    """
    root = np.random.default_rng([scn.seed, run])
    rng_truth, rng_scan, rng_cluster = root.spawn(3)
    models = scn.models()
    A, hops = scn.adjacency, scn.hops
    net = _Net(A, hops, max(scn.iterations, int(hops.max())),
               [f"s{i + 1}" for i in range(len(models))])
    cv = ConstantVelocity(scn.scan_period, scn.sigma_w)
    birth, reducer = scn.birth(), scn.reducer()
    sensors = [scn.sensor_params(m) for m in models]
    local = [GMPHDFilter(cv, [s], birth, scn.survival_probability, reducer) for s in sensors]
    mixes = [f.initial() for f in local]
    order = corrector_order(A)
    ic_mix = GaussianMixture.empty(4)
    tallies: dict[str, Tally] = {}
    X = truth(scn, rng_truth)
    for k in range(scn.num_scans):
        x = X[k][:, [0, 2]]
        scans = measure(scn, models, X[k], rng_scan)
        _flooding_step(scn, net, k, x, scans, to_plane(models, scans), rng_cluster, tallies)
        cpu_local = np.zeros(net.size)
        for i in range(net.size):
            t0 = time.process_time()
            mixes[i] = local[i].step(mixes[i], scans[i])
            cpu_local[i] = time.process_time() - t0
            _tally(tallies, "local").add(_positions(mixes[i]), x, scn, 0.0, cpu_local[i])
        if consensus:
            for rule, fuse in (("GCI", _gci(scn, reducer)), ("AA", _aa(reducer))):
                _consensus_step(scn, net, k, x, rule, fuse, mixes, cpu_local, tallies)
        ic_mix = _corrector_step(scn, net, k, x, scans, local[0].predict(ic_mix), sensors,
                                 order, reducer, tallies)
    return {name: t.means() for name, t in tallies.items()}


def _flooding_step(scn: Seed004, net: _Net, k: int, x: np.ndarray, scans: list[np.ndarray],
                   plane: list[np.ndarray], rng: np.random.Generator,
                   tallies: dict[str, Tally]) -> None:
    """Scan ``k`` of flooding + clustering: IDPC and FTC on the full pooled set ``plane``
    (per-sensor ``(m_i, 2)`` plane points), then IDPC on what ``t`` < diameter iterations
    leave each peer."""
    S, hops = net.size, net.hops
    sizes = np.array([len(z) for z in scans])
    pooled = np.concatenate(plane)
    t0 = time.process_time()
    est_idpc = idpc(pooled, S, scn.clustering, rng).centres
    dt = time.process_time() - t0
    flood_cost = float(flooding_tuples(hops, sizes, net.full).mean())
    flood_bytes = flooding_bytes(hops, scans, net.full, net.names, k + 1).cumsum(axis=1)
    _tally(tallies, "IDPC").add(est_idpc, x, scn, flood_cost, dt, flood_bytes[:, -1].mean())
    t0 = time.process_time()
    est = ftc(pooled, S, scn.clustering, rng).centres
    _tally(tallies, "FTC").add(est, x, scn, flood_cost, time.process_time() - t0,
                               flood_bytes[:, -1].mean())
    for t in range(1, net.full + 1):
        cost = flooding_tuples(hops, sizes, t)
        for i in range(S):
            held = hops[i] <= t
            t0 = time.process_time()
            if held.all():
                out, dt_i = est_idpc, dt
            else:
                n_scans = int(held.sum()) if scn.assumed_scans == "held" else S
                out = idpc(np.concatenate([plane[j] for j in np.flatnonzero(held)]),
                           n_scans, scn.clustering, rng).centres
                dt_i = time.process_time() - t0
            _tally(tallies, f"IDPC t={t}").add(out, x, scn, float(cost[i]), dt_i,
                                               float(flood_bytes[i, t - 1]))


def _consensus_step(scn: Seed004, net: _Net, k: int, x: np.ndarray, rule: str, fuse,
                    mixes: list[GaussianMixture], cpu_local: np.ndarray,
                    tallies: dict[str, Tally]) -> None:
    """Scan ``k`` of consensus ``rule`` (``fuse(group, weights)``, Metropolis weights) on what
    the local filters publish, tallied after each round in ``scn.rounds``."""
    S, A = net.size, net.A
    deg, W = A.sum(axis=1), metropolis_weights(A)
    nbrs = [np.flatnonzero(A[i]) for i in range(S)]
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
                _tally(tallies, f"{rule} L={r}").add(_positions(new[i]), x, scn, tuples[i],
                                                     cpu[i], nbytes[i])


def _corrector_step(scn: Seed004, net: _Net, k: int, x: np.ndarray, scans: list[np.ndarray],
                    predicted: GaussianMixture, sensors: list[SensorParams],
                    order: np.ndarray, reducer: Reducer,
                    tallies: dict[str, Tally]) -> GaussianMixture:
    """Scan ``k`` of the iterated corrector along the depth-first ``order`` and of the
    centralised filter (the same estimate, the scans routed to the most central sensor);
    the IC posterior."""
    S, hops = net.size, net.hops
    centre = int(np.argmin(hops.max(axis=1)))
    t0 = time.process_time()
    passes = iterated_corrector(predicted, scans, sensors, order, reducer, scn.prune_threshold)
    ic_mix = passes[-1]
    ic_tuples, ic_bytes = 0.0, 0.0
    for s, nxt, mix in zip(order, np.roll(order, -1), passes, strict=True):
        ic_tuples += hops[s, nxt] * _n_tuples(mix)
        ic_bytes += hops[s, nxt] * _n_bytes(mix, k + 1)
    dt = time.process_time() - t0
    est = _positions(ic_mix)
    _tally(tallies, "IC").add(est, x, scn, ic_tuples / S, dt / S, ic_bytes / S)
    sizes = np.array([len(z) for z in scans])
    routed = float((hops[:, centre] * TUPLES_PER_MEASUREMENT * sizes).sum())
    routed_bytes = sum(hops[j, centre] * len(encode(Scan(net.names[j], k + 1, scans[j],
                                                         seq=k + 1, send_time=float(k + 1))))
                       for j in range(S))
    _tally(tallies, "centralised").add(est, x, scn, routed / S, dt / S, routed_bytes / S)
    return ic_mix


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
    dbscan_class()  # the FTC rows need scikit-learn (optional): say so before any run
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


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m sensornet.sim.studies.seed004.montecarlo``: the study's command line
    (:func:`sim.studies.seed004.study.main`)."""
    return studies.main("seed004", None if argv is None else list(argv))


if __name__ == "__main__":
    sys.exit(main())
