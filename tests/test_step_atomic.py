"""A labelled estimator's step is all or nothing (issue 33, robustness; peers.step_atomic).

One exception inside a GM-PHD peer's step (an IndexError in the re-identification, 0156cca)
left its labels out of step with its components for the rest of the run: 32 counted internal
errors, the peer alive but not fusing. Here an exception is injected at several points of a
step (after the real call, so the part has already changed its state): the estimator and its
label bookkeeping must be exactly as before the step, the next step must give what an
estimator that never saw the failing scan gives on the same scans (to the bit), and labels
stay one per component. Through a twin peer: the error is counted once and the peer fuses
every later scan."""

from __future__ import annotations

import copy

import numpy as np
import pytest
import sensornet.peers.estimators as est_mod
import sensornet.peers.gmphd_own_times as gm_own
import sensornet.peers.lmb_estimator as lmb_mod
from sensornet.peers.estimators import GmphdEstimator
from sensornet.peers.labelling import label_fused
from sensornet.peers.lmb_estimator import LmbEstimator
from sensornet.peers.lmb_own_times import OwnTimes
from sensornet.peers.stamp_moves import MovingStamps
from sensornet.protocol.codec import decode
from sensornet.protocol.keys import Keys
from sensornet.sim.run.peers import make_peer
from sensornet.sim.run.twin import run_twin
from sensornet.sim.scenario import load_scenario
from sensornet.sim.world.birth import MeasurementBirthGMPHD
from sensornet.tracking.elapsed import ElapsedMotion
from sensornet.tracking.gmphd import GMPHDFilter, SensorParams
from sensornet.tracking.label_confirmation import Publication
from sensornet.tracking.lmb import LmbFilter
from sensornet.tracking.mixture import GaussianMixture
from sensornet.tracking.models import ConstantVelocity, LinearPosition
from sensornet.tracking.reduction import Reducer
from sensornet.tracking.reidentify import Reidentification

SCANS = 16
FAIL_AT = (6, 11)
"""Scans whose step of peer ``a`` raises (a target dark at 5-6 and back: the memories hold
labels then)."""


class Injected(RuntimeError):
    pass


def _plots(k: int, rng: np.random.Generator, pd_miss: set[int]) -> np.ndarray:
    """Three targets (one dark at scans 5-6), two clutter plots a scan, 5 m noise."""
    x = np.array([[2.0 * k, 10.0], [100.0 - 3.0 * k, 60.0 + k], [-80.0, -50.0 + 2.0 * k]])
    keep = [i for i in range(3) if not (i == 1 and k in pd_miss)]
    z = x[keep] + rng.normal(0, 5.0, (len(keep), 2))
    return np.concatenate([z, rng.uniform(-200, 200, (2, 2))])


def _scans(seed: int) -> dict[int, tuple[np.ndarray, np.ndarray]]:
    rng = np.random.default_rng(seed)
    return {k: (_plots(k, rng, {5, 6}), _plots(k, rng, set())) for k in range(1, SCANS + 1)}


OWN = OwnTimes(0.5, 1.0, ElapsedMotion(1.0, 2.0), 0.99, 2.5e-6, None, 0.95)
"""Plots at their own times, one slice a tick (no beam): the own-times code path."""


def _gmphd(origin: int, kind: str) -> GmphdEstimator:
    """``kind``: ``"fixed"`` births (own labels), ``"shared"`` (fixed, labelled alike at every
    peer), ``"measurements"`` (births from the last scan's plots: a filter with state),
    ``"own_times"`` (measurement births, plots at their own times)."""
    motion = ConstantVelocity(1.0, 2.0)
    reducer = Reducer(prune_threshold=1e-5, merge_threshold=4.0, max_components=30)
    sensors = [SensorParams(LinearPosition(5.0), 0.95, 2.5e-6)]
    if kind in ("fixed", "shared"):
        birth = GaussianMixture(np.full(3, 0.05), np.array(
            [[0.0, 0, 10, 0], [100.0, 0, 60, 0], [-80.0, 0, -50, 0]]),
            np.tile(np.diag([400.0, 25, 400, 25]), (3, 1, 1)))
        f = GMPHDFilter(motion, sensors, birth, 0.99, reducer)
    else:
        f = MeasurementBirthGMPHD(motion=motion, sensors=sensors, birth=GaussianMixture.empty(4),
                                  survival_probability=0.99, reducer=reducer,
                                  birth_weight=0.05, birth_speed=10.0)
    return GmphdEstimator(f, origin=origin, shared_births=kind == "shared", corroborate_scans=2,
                          own_times=OWN if kind == "own_times" else None)


def _lmb(origin: int, own_times: bool = False) -> LmbEstimator:
    f = LmbFilter(ConstantVelocity(1.0, 2.0), SensorParams(LinearPosition(5.0), 0.95, 2.5e-6),
                  origin=origin, method="gibbs", gibbs_samples=50, seed=origin)
    return LmbEstimator(f, origin=origin, tentative_threshold=0.15, corroborate_scans=2,
                        republish_gap=1, own_times=OWN if own_times else None)


def _state(est) -> list:
    """Deep copies of what a step may change: each part's attributes (not the filter's
    settings) and the Generators' states."""
    skip = ("filter", "reducer", "own_times", "_gap_filter")
    parts = [copy.deepcopy({n: v for n, v in vars(p).items() if n not in skip})
             for p in est.atomic_parts() if p is not None]
    return [parts, [copy.deepcopy(g.bit_generator.state) for g in est.atomic_streams()
                    if g is not None]]


def _assert_same(a, b, path: str = "") -> None:
    """Equal to the bit: arrays (shape, dtype, values), containers, objects' attributes."""
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        assert isinstance(a, np.ndarray) and isinstance(b, np.ndarray), path
        assert a.dtype == b.dtype and a.shape == b.shape, path
        np.testing.assert_array_equal(a, b, err_msg=path)
    elif isinstance(a, dict):
        assert isinstance(b, dict) and a.keys() == b.keys(), path
        for key in a:
            _assert_same(a[key], b[key], f"{path}.{key}")
    elif isinstance(a, list | tuple):
        assert type(a) is type(b) and len(a) == len(b), path
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            _assert_same(x, y, f"{path}[{i}]")
    elif hasattr(a, "__dict__") and not callable(a):
        assert type(a) is type(b), path
        _assert_same(vars(a), vars(b), path)
    elif hasattr(a, "__dataclass_fields__"):
        assert type(a) is type(b), path
        for name in a.__dataclass_fields__:
            _assert_same(getattr(a, name), getattr(b, name), f"{path}.{name}")
    else:
        assert a == b, (path, a, b)


def _run(a, b, scans, fail: dict[int, object] | None, skip: tuple[int, ...] = ()):
    """Peers ``a`` and ``b``, one fusion round a scan (own first, the neighbour's labelled
    estimate, ``a``'s fresh stamps), as the consensus runs it. At the scans of ``fail`` ``a``'s
    step runs with the injection ``fail[k]`` (a context manager) and must raise and leave ``a``
    as it was; at ``skip`` scans ``a`` never sees the scan. Either way ``a`` publishes nothing
    then and its next step covers the scans it missed (as the consensus does). Returns ``a``'s
    outputs per scan."""
    outs: dict[int, object] = {}
    last = 0
    for k in range(1, SCANS + 1):
        za, zb = scans[k]
        out_a = None
        if fail and k in fail:
            a.begin_scan(k)
            before = _state(a)
            with fail[k], pytest.raises(Injected):
                a.step(k - last, za)
            _assert_same(before, _state(a), f"scan {k}")
        elif k not in skip:
            a.begin_scan(k)
            out_a = a.step(k - last, za)
            last = k
        b.begin_scan(k)
        out_b = b.step(1, zb)
        for e, mine, theirs in ((a, out_a, out_b), (b, out_b, out_a)):
            if mine is None:
                continue
            ins = [(mine.published["posterior"], mine.labels["posterior"])]
            if theirs is not None:
                ins.append((theirs.published["posterior"], theirs.labels["posterior"]))
            fused = ins[0][0] if len(ins[0][0]) else ins[-1][0]
            if len(fused):
                e.relabel(label_fused(fused, ins, e.origin, k, bump=e.fresh_stamps()).own)
        if out_a is not None:
            outs[k] = out_a
            assert len(out_a.density_labels) == len(out_a.density)  # one label a component
    return outs


def _assert_same_outputs(got: dict, ref: dict) -> None:
    assert got.keys() == ref.keys()
    for k in ref:
        g, r = got[k], ref[k]
        for x, y in ((g.density, r.density), (g.published["posterior"],
                                                r.published["posterior"])):
            for name in ("weights", "means", "covs"):
                np.testing.assert_array_equal(getattr(x, name), getattr(y, name), err_msg=k)
        np.testing.assert_array_equal(g.density_labels, r.density_labels, err_msg=str(k))
        np.testing.assert_array_equal(g.labels["posterior"], r.labels["posterior"])


def _after(cls, name: str, monkeypatch):
    """A context that makes ``cls.name`` raise after the real call (its changes made)."""
    real = getattr(cls, name)

    class Ctx:
        def __enter__(self):
            def boom(*args, **kwargs):
                real(*args, **kwargs)
                raise Injected(f"after {cls.__name__}.{name}")
            monkeypatch.setattr(cls, name, boom)

        def __exit__(self, *exc):
            monkeypatch.setattr(cls, name, real)
            return False

    return Ctx()


GMPHD_POINTS = [(Publication, "stamp"), (Reidentification, "apply"),
                (MovingStamps, "returning"), (MovingStamps, "offer"), (Publication, "adopt"),
                (est_mod, "split_duplicates")]
GMPHD_CASES = ([(kind, p) for kind in ("fixed", "shared", "measurements", "own_times")
                for p in GMPHD_POINTS]
               + [("fixed", (est_mod, "correct_parents")), ("shared", (est_mod, "correct_parents")),
                  ("measurements", (MeasurementBirthGMPHD, "correct_parents")),
                  ("own_times", (gm_own, "step_at_own_times"))])


@pytest.mark.parametrize(("kind", "point"), GMPHD_CASES,
                         ids=lambda p: p if isinstance(p, str) else f"{p[0].__name__}.{p[1]}")
def test_a_gmphd_step_that_raises_leaves_the_estimator_as_before(kind, point, monkeypatch):
    scans = _scans(3)
    if kind == "own_times":
        ages = {k: np.linspace(0.0, 1.0, len(scans[k][0])) for k in scans}
        monkeypatch.setattr(GmphdEstimator, "begin_scan", _with_ages(
            GmphdEstimator, lambda e, k: e.plot_ages(ages[k] if e.origin == 1 else None)))
    ref = _run(_gmphd(1, kind), _gmphd(2, kind), scans, None, skip=FAIL_AT)
    if point == (gm_own, "step_at_own_times"):
        point = (est_mod, "step_at_own_times")  # the name the estimator calls
    elif kind == "own_times" and point == (est_mod, "split_duplicates"):
        point = (gm_own, "split_duplicates")  # the slices' duplicate rule
    fail = {k: _after(*point, monkeypatch) for k in FAIL_AT}
    got = _run(_gmphd(1, kind), _gmphd(2, kind), scans, fail)
    _assert_same_outputs(got, ref)
    assert any(len(o.labels["posterior"]) for o in got.values())  # tracks were published


def test_a_gmphd_relabel_that_raises_leaves_the_estimator_as_before(monkeypatch):
    scans = _scans(4)
    a, b = _gmphd(1, "shared"), _gmphd(2, "shared")
    _run(a, b, scans, None)
    match = label_fused(*_fused_pair(a, b, scans[SCANS], SCANS + 1))
    assert len(match.own), "the case must move a label"
    before = _state(a)
    with _after(Publication, "adopt", monkeypatch), pytest.raises(Injected):
        a.relabel(match.own)
    _assert_same(before, _state(a))


def _fused_pair(a, b, z, k):
    """``label_fused`` arguments for ``a`` after both step at scan ``k`` (``b`` shifted so its
    labels win: a match that moves ``a``'s labels)."""
    outs = []
    for e in (a, b):
        e.begin_scan(k)
        outs.append(e.step(1, z[0]))
    ins = [(o.published["posterior"], o.labels["posterior"]) for o in outs]
    nbr = ins[1][1].copy()
    nbr[:, 1] -= 100  # earlier births: the neighbour's labels win every pair
    return ins[0][0], [ins[0], (ins[1][0], nbr)], a.origin, k


LMB_POINTS = [(LmbEstimator, "_stamp_first_publication"), (LmbEstimator, "_publishing"),
              (lmb_mod, "phd_mixture"), (LmbFilter, "correct"), (LmbEstimator, "_remember")]


@pytest.mark.parametrize("own_times", [False, True])
@pytest.mark.parametrize("point", LMB_POINTS, ids=lambda p: f"{p[0].__name__}.{p[1]}")
def test_an_lmb_step_that_raises_leaves_the_estimator_as_before(point, own_times, monkeypatch):
    scans = _scans(5)
    if own_times:
        ages = {k: np.linspace(0.0, 1.0, len(scans[k][0])) for k in scans}
        monkeypatch.setattr(LmbEstimator, "begin_scan", _with_ages(
            LmbEstimator, lambda e, k: e.plot_ages(ages[k] if e.origin == 1 else None)))
    ref = _run(_lmb(1, own_times), _lmb(2), scans, None, skip=FAIL_AT)
    fail = {k: _after(*point, monkeypatch) for k in FAIL_AT}
    got = _run(_lmb(1, own_times), _lmb(2), scans, fail)
    _assert_same_outputs(got, ref)
    assert any(len(o.labels["posterior"]) for o in got.values())


def _with_ages(cls, plot_ages):
    """``cls.begin_scan`` that also gives the estimator its plots' ages."""
    real = cls.begin_scan

    def begin_scan(self, k):
        real(self, k)
        plot_ages(self, k)
    return begin_scan


def test_an_lmb_relabel_that_raises_leaves_the_estimator_as_before(monkeypatch):
    scans = _scans(6)
    a, b = _lmb(1), _lmb(2)
    _run(a, b, scans, None)
    match = label_fused(*_fused_pair(a, b, scans[SCANS], SCANS + 1))
    assert len(match.own)
    before = _state(a)
    with _after(LmbEstimator, "_remember", monkeypatch), pytest.raises(Injected):
        a.relabel(match.own)
    _assert_same(before, _state(a))


@pytest.mark.parametrize("kind", ["gmphd", "lmb"])
def test_a_peer_whose_step_raised_once_counts_it_and_fuses_as_if_the_scan_never_came(
        kind, monkeypatch):
    """The seed-000 twin, peer s1's step raising once at scan 10 (after its re-identification
    / its publication memory changed): one internal error, and every peer's fused tracks at
    every scan are those of the run in which s1 never received scan 10 (the consensus steps
    over both scans next, as after a gap). Before, the GM-PHD's labels out of step made every
    later step raise; the LMB kept the failed scan's state."""
    over = {"scenario.num_scans": 30}
    if kind == "lmb":
        over["network.filter"] = "lmb"
    scn = load_scenario("seed000", overrides=over)
    ref_peers = {n: make_peer(scn, n, 0, network="twin") for n in scn.sensor_names}
    core, scan_key = ref_peers["s1"], Keys("twin").scan("s1")
    receive = core.receive

    def without_scan_10(key, payload, now):
        if key == scan_key and decode(payload).k == 10:
            return []
        return receive(key, payload, now)

    core.receive = without_scan_10
    ref = run_twin(scn, 0, peers=ref_peers)
    cls, name = ((Reidentification, "apply") if kind == "gmphd"
                 else (LmbEstimator, "_stamp_first_publication"))
    real = getattr(cls, name)
    owner: list = []

    def boom(self, *args, **kwargs):
        out = real(self, *args, **kwargs)
        if any(self is o for o in owner) and args[-1] == 10:
            raise Injected("injected at scan 10")
        return out

    monkeypatch.setattr(cls, name, boom)
    peers = {n: make_peer(scn, n, 0, network="twin") for n in scn.sensor_names}
    est = peers["s1"].consensus.estimator
    owner.append(est.reid if kind == "gmphd" else est)
    res = run_twin(scn, 0, peers=peers)
    assert peers["s1"].snapshot()["internal_errors"] == {"Injected": 1}
    for n in scn.sensor_names:
        assert ref_peers[n].snapshot()["internal_errors"] == {}
        if n != "s1":
            assert peers[n].snapshot()["internal_errors"] == {}
        assert res.tracks[n].keys() == ref.tracks[n].keys(), n
        for k in ref.tracks[n]:
            np.testing.assert_array_equal(res.tracks[n][k], ref.tracks[n][k], err_msg=(n, k))
    assert set(range(11, 31)) <= set(res.tracks["s1"]) and 10 not in res.tracks["s1"]
