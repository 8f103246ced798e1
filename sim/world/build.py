"""From a :class:`~sim.scenario.Scenario` to the estimation core's objects.

The one place where scenario settings become ``tracking`` models, sensor parameters, birth
intensities, reducers and filters, so the world, the peers and the experiments build them the
same way. The measurement-space box of a sensor lives here too: clutter is drawn uniformly over
it (``sim.world``) and the filter's clutter intensity is ``lambda_c / V`` over the same box.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from sensornet.peers.faults import FaultInjector
from sensornet.sim.scenario import Scenario, ScenarioError, SensorSpec
from sensornet.sim.world.birth import MeasurementBirthGMPHD, beam_of
from sensornet.tracking.gmphd import GMPHDFilter, SensorParams
from sensornet.tracking.mixture import GaussianMixture
from sensornet.tracking.models import ConstantVelocity, LinearPosition, RangeBearing
from sensornet.tracking.reduction import Reducer


def motion_model(scn: Scenario) -> ConstantVelocity:
    """The filters' motion model (``"cv"``: ``F``, ``Q = sigma_w^2 G G^T``, §1)."""
    return ConstantVelocity(T=scn.scan_period, sigma_w=scn.sigma_w)


def sensor_model(spec: SensorSpec) -> LinearPosition | RangeBearing:
    """The measurement model of one sensor (``tracking.models``)."""
    if spec.kind == "linear":  # plot_sigma: a radar's x-y plots (recorded traffic)
        return LinearPosition(sigma_r=spec.plot_sigma or spec.sigma_r, position=spec.position)
    if spec.kind == "range-bearing":
        return RangeBearing(sigma_r=spec.sigma_r, sigma_theta=spec.sigma_theta,
                            position=spec.position)
    raise ValueError(f"unknown sensor kind {spec.kind!r}")  # validated on load: a bug here


def measurement_box(scn: Scenario, spec: SensorSpec) -> tuple[np.ndarray, np.ndarray]:
    """Lower and upper corners ``(2,), (2,)`` of the sensor's clutter box in measurement space.

    Linear sensors: the surveillance region ``[xmin, xmax) x [ymin, ymax)``. Range-bearing:
    ``[0, r_max) x [-pi, pi)``, ``r_max`` the distance from the radar to the farthest region
    corner (so every clutter return the region could produce is covered).
    """
    (x0, x1), (y0, y1) = scn.region
    if spec.kind == "linear":
        return np.array([x0, y0]), np.array([x1, y1])
    sx, sy = spec.position
    r_max = max(math.hypot(x - sx, y - sy) for x in (x0, x1) for y in (y0, y1))
    return np.array([0.0, -math.pi]), np.array([r_max, math.pi])


def sweep_fraction(scn: Scenario, spec: SensorSpec) -> float:
    """The share of a rotating radar's circle its beam sweeps in one scan interval,
    ``min(1, scan_period / rotation_period)`` (1 for a sensor without rotation): a scan holds
    the plots of that sector only (``sim.traffic.recorded``)."""
    if spec.rotation_period is None:
        return 1.0
    return min(1.0, scn.scan_period / spec.rotation_period)


def clutter_intensity(scn: Scenario, sensor: SensorSpec | str) -> float:
    """``kappa = lambda_c / V``: clutter per unit measurement volume (m^2, or m * rad).

    A sensor with ``max_range`` (recorded traffic) has its clutter over its coverage disc:
    ``V = pi r_max^2`` (x-y) or ``r_max 2 pi`` (range-bearing: uniform in range and bearing,
    an approximation of clutter uniform in area), and ``lambda_c`` per rotation, so per scan
    ``lambda_c`` times the :func:`sweep_fraction`."""
    spec = scn.sensor(sensor) if isinstance(sensor, str) else sensor
    if spec.max_range is not None:
        r = spec.max_range
        volume = math.pi * r * r if spec.kind == "linear" else 2.0 * math.pi * r
        return spec.clutter_rate * sweep_fraction(scn, spec) / volume
    low, high = measurement_box(scn, spec)
    return spec.clutter_rate / float(np.prod(high - low))


def sensor_params(scn: Scenario, name: str) -> SensorParams:
    """What a GM-PHD update needs about sensor ``name``: model, ``Pd`` (times the
    :func:`sweep_fraction` of a rotating radar), ``kappa``."""
    spec = scn.sensor(name)
    return SensorParams(
        model=sensor_model(spec),
        detection_probability=spec.detection_probability * sweep_fraction(scn, spec),
        clutter_intensity=clutter_intensity(scn, spec),
    )


def birth_mixture(scn: Scenario) -> GaussianMixture:
    """The birth intensity per ``scn.birth.model`` (§10).

    ``"paper"``: the listed components. ``"truth"``: one component per target at its true start
    position with zero velocity, weight ``birth.truth_weight``, covariance ``birth.truth_cov``.
    """
    b = scn.birth
    if b.model == "paper":
        if not b.paper:
            return GaussianMixture.empty(4)
        return GaussianMixture(
            np.array([c.weight for c in b.paper]),
            np.array([c.mean for c in b.paper]),
            np.array([c.cov for c in b.paper]),
        )
    if b.model == "measurements":  # no fixed births: MeasurementBirthGMPHD makes them
        return GaussianMixture.empty(4)
    if b.model == "truth":
        n = len(scn.targets)
        if n == 0:
            return GaussianMixture.empty(4)
        means = np.zeros((n, 4))
        means[:, [0, 2]] = [t.start for t in scn.targets]
        return GaussianMixture(
            np.full(n, b.truth_weight), means, np.tile(np.array(b.truth_cov), (n, 1, 1))
        )
    raise ValueError(f"unknown birth model {b.model!r}")  # validated on load: a bug here


def make_reducer(scn: Scenario) -> Reducer:
    """The level-1 reducer from ``[filter]`` (prune, merge, cap, optional ISE re-fit)."""
    f = scn.filter
    return Reducer(
        prune_threshold=f.prune_threshold,
        merge_threshold=f.merge_threshold,
        max_components=f.max_components,
        merge_rule=f.merge_rule,
        refit=f.refit,
    )


def make_filter(scn: Scenario, sensor_names: Sequence[str]) -> GMPHDFilter:
    """A GM-PHD filter over ``sensor_names``: one name gives a local filter, several the
    iterated-corrector centralized filter (corrects with each sensor's scan in the given order).
    """
    if isinstance(sensor_names, str):
        sensor_names = [sensor_names]
    if not sensor_names:
        raise ScenarioError(f"{scn.name}: a filter needs at least one sensor")
    common = dict(
        motion=motion_model(scn),
        sensors=[sensor_params(scn, s) for s in sensor_names],
        birth=birth_mixture(scn),
        survival_probability=scn.survival_probability,
        reducer=make_reducer(scn),
        extraction_threshold=scn.filter.extraction_threshold,
        extraction=scn.filter.extraction,
        gate=scn.filter.gate,
    )
    if scn.birth.model == "measurements":
        b = scn.birth
        beams = tuple(beam_of(scn, scn.sensor(s)) for s in sensor_names)
        return MeasurementBirthGMPHD(**common, birth_weight=b.measurements_weight,
                                     birth_speed=b.measurements_speed,
                                     birth_gate=b.measurements_gate,
                                     beams=beams if any(beams) else None)
    return GMPHDFilter(**common)


__all__ = [
    "birth_mixture",
    "clutter_intensity",
    "make_filter",
    "make_reducer",
    "measurement_box",
    "motion_model",
    "sensor_model",
    "sensor_params",
    "sweep_fraction",
]


def adjacency(scn: Scenario) -> tuple[list[str], np.ndarray]:
    """Peer names (one per sensor) and the symmetric boolean adjacency ``(n, n)`` of the graph."""
    names = scn.sensor_names
    n = len(names)
    A = np.zeros((n, n), dtype=bool)
    topo = scn.network.topology
    if topo == "full":
        A[:] = True
    elif topo == "ring":
        for i in range(n):
            A[i, (i + 1) % n] = A[(i + 1) % n, i] = n > 1
    elif topo == "line":
        for i in range(n - 1):
            A[i, i + 1] = A[i + 1, i] = True
    elif topo == "star":
        hub = names.index(scn.fusion.fusing_sensor)
        A[hub, :] = A[:, hub] = True
    else:
        for a, b in scn.network.edges:
            A[names.index(a), names.index(b)] = A[names.index(b), names.index(a)] = True
    np.fill_diagonal(A, False)
    return names, A


def fault_injector(scn: Scenario, run: int = 0) -> FaultInjector | None:
    """The scenario's link faults for run ``run`` (``None`` without a ``[faults]`` table).

    Seeded from ``(scenario.seed, run)``; every decision is keyed by that seed, the link and
    the message (:mod:`peers.faults`), so the twin and the real processes of the same run take
    the same decisions.
    """
    if scn.faults is None:
        return None
    seed = int(np.random.SeedSequence([scn.seed, run, 0xFA17]).generate_state(1)[0])
    return FaultInjector(scn.faults, seed)
