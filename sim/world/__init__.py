"""The simulated world: true target states and every sensor's scans.

Our reading of seed 000's truth: docs/algorithms.md "Seed-000 scenario".

Scans are 1-based (scan ``k`` at time ``k T``); lists are indexed by ``k - 1``.

Randomness: every draw takes a ``numpy.random.Generator``. :func:`generate_run` derives
independent streams from ``SeedSequence([seed, run])`` (what ``default_rng([seed, run])``
uses): one for the truth, and one per sensor keyed by the sensor's *name* (not its position in
the file), so adding, removing or reordering sensors leaves the other sensors' scans unchanged.
"""

from __future__ import annotations

import zlib
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from sensornet.sim.scenario import Scenario, SensorSpec
from sensornet.sim.truths import TruthModel, truth_model
from sensornet.sim.world.build import measurement_box, sensor_model
from sensornet.tracking.models import ConstantVelocity


@dataclass(frozen=True)
class Truth:
    """True multi-target states per scan.

    states: ``states[k-1]`` is ``(n_k, 4)`` in ``[px, vx, py, vy]`` for scan ``k``.
    ids:    ``ids[k-1]`` is ``(n_k,)`` target ids: the 1-based index in ``scenario.targets``.
    """

    states: list[np.ndarray]
    ids: list[np.ndarray]

    @property
    def num_scans(self) -> int:
        return len(self.states)

    def counts(self) -> np.ndarray:
        """Number of true targets per scan, ``(K,)``."""
        return np.array([len(x) for x in self.states], dtype=int)

    def positions(self, k: int) -> np.ndarray:
        """True positions ``(n_k, 2)`` at scan ``k`` (1-based), e.g. for OSPA."""
        return self.states[k - 1][:, [0, 2]]


def generate_truth(scn: Scenario, rng: np.random.Generator | None = None) -> Truth:
    """True states of every target over ``scn.num_scans`` scans, by the scenario's truth model
    (:mod:`sim.truths`); ``rng``: the run's truth stream (:func:`truth_rng`)."""
    return truth_model(scn.truth).truth(scn, rng)


def initial_state(scn: Scenario) -> tuple[np.ndarray, np.ndarray]:
    """The one target's initial state and spread ``(x0 (d,), P0 (d, d))`` single-target peers
    start from; :class:`ValueError` if the truth model has none."""
    model = truth_model(scn.truth)
    if model.initial is None:
        raise ValueError(f"{scn.name}: truth model {scn.truth!r} has no known initial state "
                         f"(single-target peers need one)")
    return model.initial(scn)


def straight_truth(scn: Scenario, rng: np.random.Generator | None = None) -> Truth:
    """True states of every target over ``scn.num_scans`` scans (``truth = "straight"``).

    A target lives at scans ``birth_scan..death_scan`` (inclusive, clipped to the run) moving at
    the constant velocity ``(end - start) / ((death_scan - birth_scan) T)``: at ``start`` on its
    first scan, at ``end`` on its last (our reading of §10's start → end table). With
    ``truth_sigma_w > 0`` a CV random deviation (``Q`` with that ``sigma_w``, starting at 0) is
    added, so the truth is a CV trajectory with process noise around the straight line; ``rng``
    is then required.
    """
    K, T = scn.num_scans, scn.scan_period
    noisy = scn.truth_sigma_w > 0
    if noisy and rng is None:
        raise ValueError("generate_truth needs an rng when truth_sigma_w > 0")
    cv = ConstantVelocity(T=T, sigma_w=scn.truth_sigma_w)
    per_scan: list[list[np.ndarray]] = [[] for _ in range(K)]
    per_ids: list[list[int]] = [[] for _ in range(K)]
    for tid, tgt in enumerate(scn.targets, start=1):
        first, last = tgt.birth_scan, min(tgt.death_scan, K)
        if first > K:
            continue
        start, end = np.array(tgt.start), np.array(tgt.end)
        span = tgt.death_scan - tgt.birth_scan
        vel = (end - start) / (span * T) if span else np.zeros(2)
        t = (np.arange(first, last + 1) - first) * T  # (L,) seconds since birth
        pos = start + t[:, None] * vel  # (L, 2)
        states = np.column_stack([pos[:, 0], np.full(len(t), vel[0]),
                                  pos[:, 1], np.full(len(t), vel[1])])  # (L, 4)
        if noisy:
            states += _cv_deviation(cv, len(t), rng)
        for i, k in enumerate(range(first, last + 1)):
            per_scan[k - 1].append(states[i])
            per_ids[k - 1].append(tid)
    return Truth(
        states=[np.array(s).reshape(-1, 4) for s in per_scan],
        ids=[np.array(i, dtype=int) for i in per_ids],
    )


def _cv_deviation(cv: ConstantVelocity, length: int, rng: np.random.Generator) -> np.ndarray:
    """A CV random walk ``e_0 = 0, e_i = F e_(i-1) + w_i``, ``w ~ N(0, Q)``: ``(length, 4)``.

    ``w = G a`` with accelerations ``a ~ N(0, sigma_w^2 I_2)``, so ``cov w = Q = sigma_w^2 G G^T``
    exactly (``Q`` has rank 2: a Cholesky factor of it does not exist).
    """
    T = cv.T
    G = np.array([[T * T / 2, 0], [T, 0], [0, T * T / 2], [0, T]])
    noise = rng.normal(0.0, cv.sigma_w, size=(max(length - 1, 0), 2)) @ G.T  # (length-1, 4)
    dev = np.zeros((length, 4))
    for i in range(1, length):
        dev[i] = cv.F @ dev[i - 1] + noise[i - 1]
    return dev


def sensor_scans(scn: Scenario, spec: SensorSpec, truth: Truth,
                 rng: np.random.Generator) -> list[np.ndarray]:
    """One sensor's scans: ``scans[k-1]`` is ``(m_k, 2)`` for scan ``k``.

    Each true target is detected with ``Pd`` and measured with the sensor model
    (``tracking.models``; bearings wrapped to ``[-pi, pi)``); with an ``[extended]`` table a
    detected target gives ``Poisson(extended.rate)`` measurements instead of one (seed 002);
    ``Poisson(clutter_rate)`` clutter points are drawn uniformly over
    :func:`sim.world.build.measurement_box`; the rows are shuffled so a measurement's position in
    the
    scan says nothing about its origin.
    """
    return labelled_sensor_scans(scn, spec, truth, rng)[0]


def labelled_sensor_scans(scn: Scenario, spec: SensorSpec, truth: Truth,
                          rng: np.random.Generator) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """:func:`sensor_scans` and each measurement's origin: ``origins[k-1]`` is ``(m_k,)``, the
    target id (``truth.ids``) or 0 for clutter (for partition scores)."""
    model = sensor_model(spec)
    low, high = measurement_box(scn, spec)
    scans, origins = [], []
    for states, ids in zip(truth.states, truth.ids, strict=True):
        detected = rng.random(len(states)) < spec.detection_probability
        xs, who = states[detected], ids[detected]
        if xs.shape[1] == 6:  # [px, vx, ax, py, vy, ay] -> the models' [px, vx, py, vy]
            xs = xs[:, [0, 1, 3, 4]]
        if scn.extended is not None:  # extended targets: Poisson(rate) returns each
            n = rng.poisson(scn.extended.rate, len(xs))
            xs, who = np.repeat(xs, n, axis=0), np.repeat(who, n)
        z_targets = model.measure(xs, rng)  # (d, 2)
        clutter = rng.uniform(low, high, size=(rng.poisson(spec.clutter_rate), 2))  # (c, 2)
        scan = np.concatenate([z_targets, clutter]).reshape(-1, 2)
        origin = np.concatenate([who, np.zeros(len(clutter), dtype=int)]).astype(int)
        order = rng.permutation(len(scan))
        scans.append(scan[order])
        origins.append(origin[order])
    return scans, origins


def generate_scans(
    scn: Scenario,
    truth: Truth,
    rng: np.random.Generator | Sequence[np.random.Generator],
) -> list[list[np.ndarray]]:
    """Every sensor's scans: ``scans[s][k-1]`` is the ``(m, 2)`` scan of sensor ``s`` at scan ``k``.

    ``rng``: one generator per sensor (in ``scn.sensors`` order), or a single generator from
    which one child stream per sensor is spawned.
    """
    rngs = rng.spawn(len(scn.sensors)) if isinstance(rng, np.random.Generator) else list(rng)
    if len(rngs) != len(scn.sensors):
        raise ValueError(f"expected {len(scn.sensors)} generators, got {len(rngs)}")
    return [sensor_scans(scn, spec, truth, g) for spec, g in zip(scn.sensors, rngs, strict=True)]


# Stream keys under SeedSequence([seed, run]): truth (0,), sensor (1, crc32(name)).
_TRUTH_STREAM = 0
_SENSOR_STREAM = 1


def _stream(scn: Scenario, run: int, *key: int) -> np.random.Generator:
    if run < 0:
        raise ValueError(f"run must be >= 0, got {run}")
    root = np.random.SeedSequence([scn.seed, run])
    return np.random.default_rng(np.random.SeedSequence(root.entropy, spawn_key=key))


def truth_rng(scn: Scenario, run: int) -> np.random.Generator:
    """The truth's random stream for Monte Carlo run ``run``."""
    return _stream(scn, run, _TRUTH_STREAM)


def sensor_rng(scn: Scenario, run: int, name: str) -> np.random.Generator:
    """Sensor ``name``'s random stream for run ``run`` (independent of the other sensors)."""
    return _stream(scn, run, _SENSOR_STREAM, zlib.crc32(name.encode("utf-8")))


def generate_run(scn: Scenario, run: int) -> tuple[Truth, list[list[np.ndarray]]]:
    """Truth and all scans of Monte Carlo run ``run``, deterministic in ``(scn.seed, run)``
    (a truth model that draws its own runs draws them)."""
    model = truth_model(scn.truth)
    if model.run is not None:
        return model.run(scn, run)
    truth = generate_truth(scn, truth_rng(scn, run))
    scans = generate_scans(scn, truth, [sensor_rng(scn, run, s.name) for s in scn.sensors])
    return truth, scans


def plot_ages(scn: Scenario, run: int) -> list[list[np.ndarray]] | None:
    """``ages[s][k-1]`` ``(m,)``: how long before scan ``k``'s time each plot of
    :func:`generate_run`'s ``scans[s][k-1]`` was made (s), sent with the scans when the
    scenario takes plots at their own times (``lmb.time_slice`` or ``filter.time_slice`` > 0)
    and its truth model knows them (recorded traffic); else None (every plot at its scan's
    time)."""
    model = truth_model(scn.truth)
    if (scn.lmb.time_slice <= 0 and scn.filter.time_slice <= 0) or model.ages is None:
        return None
    return model.ages(scn, run)


STRAIGHT = TruthModel("straight", "targets on straight lines from start to end (seed 000)",
                      straight_truth)

__all__ = [
    "Truth",
    "generate_run",
    "generate_scans",
    "generate_truth",
    "initial_state",
    "labelled_sensor_scans",
    "plot_ages",
    "sensor_rng",
    "sensor_scans",
    "truth_rng",
]
