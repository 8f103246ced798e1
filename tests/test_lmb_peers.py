"""LMB peers (issue 33 item 1; sim/kinds/lmb.py, peers/lmb_estimator.py): the published PHD
against a direct evaluation of the LMB's first moment, the estimator's predict, feedback and
relabel, and the seed-000 twin with ``network.filter = "lmb"`` (every scan processed, fusion
better than the local filters, one id per target across peers). The README feature-table row
is run by tests/test_feature_table.py (its ``seed000-lmb`` case)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import multivariate_normal
from sensornet.peers.lmb_estimator import (
    PUBLISHED_BASE,
    LmbEstimator,
    lmb_from_mixture,
    phd_mixture,
)
from sensornet.sim.kinds import kind
from sensornet.sim.kinds.lmb import make_lmb_filter
from sensornet.sim.run.twin import run_twin
from sensornet.sim.scenario import ScenarioError, load_scenario
from sensornet.tracking.gmphd import SensorParams
from sensornet.tracking.labels import LabelMatch, new_labels
from sensornet.tracking.lmb import LmbFilter, LmbState
from sensornet.tracking.lmb_sets import LabelledBernoulliSet
from sensornet.tracking.models import ConstantVelocity, LinearPosition
from sensornet.tracking.track_metrics import label_agreement, track_report

from tests.labelled_tables import twin_tables


def _filter(origin: int = 0) -> LmbFilter:
    return LmbFilter(ConstantVelocity(1.0, 2.0), SensorParams(LinearPosition(10.0), 0.95, 1e-6),
                     origin=origin)


def _state(rng: np.random.Generator, n: int = 4) -> LmbState:
    sizes = rng.integers(1, 4, n)
    owner = np.repeat(np.arange(n), sizes)
    c = len(owner)
    A = rng.normal(size=(c, 4, 4))
    w = rng.uniform(0.1, 1.0, c)
    w /= np.bincount(owner, w)[owner]
    tracks = LabelledBernoulliSet(new_labels(1, 3, n), rng.uniform(0.05, 1.0, n), w,
                                  rng.normal(0, 50, (c, 4)), A @ A.swapaxes(1, 2) + 5 * np.eye(4),
                                  owner)
    return LmbState(tracks, np.arange(n, dtype=np.int64), 3, _filter().initial().pending)


def test_published_phd_is_the_lmb_first_moment():
    """``D(x) = sum_i r_i sum_k w_ik N(x; m_ik, P_ik)`` evaluated directly (scipy) at random
    points equals the published mixture's density; its mass is the expected number of
    targets ``sum_i r_i``; every row carries its track's label."""
    rng = np.random.default_rng(3)
    for _ in range(20):
        st = _state(rng, int(rng.integers(1, 6)))
        mix, labels = phd_mixture(st)
        t = st.tracks
        x = rng.normal(0, 50, (7, 4))
        direct = np.zeros(len(x))
        for i in range(len(t)):
            for j in np.flatnonzero(t.owner == i):
                direct += t.existence[i] * t.weights[j] * multivariate_normal(
                    t.means[j], t.covs[j]).pdf(x)
        ours = np.array([sum(w * multivariate_normal(m, P).pdf(xi) for w, m, P in
                             zip(mix.weights, mix.means, mix.covs, strict=True)) for xi in x])
        np.testing.assert_allclose(ours, direct, rtol=1e-12)
        assert mix.mass == pytest.approx(t.existence.sum(), rel=1e-12)
        np.testing.assert_array_equal(labels, t.labels[t.owner])


def test_mixture_back_to_lmb_is_the_same_tracks():
    """Feedback's conversion undoes :func:`phd_mixture` (existence, labels, densities)."""
    rng = np.random.default_rng(4)
    for _ in range(20):
        st = _state(rng, int(rng.integers(1, 6)))
        mix, labels = phd_mixture(st)
        back = lmb_from_mixture(mix, labels, 0, 5)
        np.testing.assert_array_equal(back.labels, st.tracks.labels)  # sorted labels already
        np.testing.assert_allclose(back.existence, st.tracks.existence, rtol=1e-12)
        np.testing.assert_allclose(back.weights, st.tracks.weights, rtol=1e-12)
        np.testing.assert_array_equal(back.owner, st.tracks.owner)
    unl = lmb_from_mixture(mix, None, 2, 9)
    assert len(unl) == len(mix) and (unl.labels[:, :2] == [2, 9]).all()


def test_neighbour_prediction_is_the_lmb_prediction():
    """``predict(mix, s)`` of a published PHD is the PHD of the LMB predicted ``s`` scans
    (no births), row for row, so a neighbour's labels still fit."""
    rng = np.random.default_rng(5)
    est = LmbEstimator(_filter(), origin=0)
    st = _state(rng)
    mix, _ = phd_mixture(st)
    for steps in (1, 3):
        from_lmb = est.filter.predict(st, st.k + steps)  # no fixed births, none pending
        expect, _ = phd_mixture(from_lmb)
        got = est.predict(mix, steps)
        np.testing.assert_allclose(got.weights, expect.weights, rtol=1e-12)
        np.testing.assert_allclose(got.means, expect.means, rtol=1e-12)
        np.testing.assert_allclose(got.covs, expect.covs, rtol=1e-12)
    assert est.predict(mix, 0) is mix


def _targets_scans(rng, k: int) -> list[np.ndarray]:
    truth = np.array([[0.0, 0.0], [300.0, -200.0]])
    v = np.array([[5.0, 2.0], [-3.0, 4.0]])
    return [truth + v * i + rng.normal(0, 10, (2, 2)) for i in range(k)]


def test_step_tracks_ids_and_relabel():
    """Two targets: after a few scans both are extracted as tracks of our origin, with the
    LMB's own states and existence; a relabel gives a track the earlier label it was matched
    with, and not a label another own track holds."""
    rng = np.random.default_rng(6)
    est = LmbEstimator(_filter(origin=2), origin=2)
    for k, z in enumerate(_targets_scans(rng, 6), start=1):
        est.begin_scan(k)
        out = est.step(1, z)
    assert out.density_labels.shape == (len(out.density), 3)
    assert len(out.labels["posterior"]) == len(out.published["posterior"])
    tr = est.extract_tracks(out.density, out.density_labels)
    lmb = est.filter.extract(est.state)
    assert len(tr.ids) == 2 and (tr.ids[:, 0] == 2).all()
    np.testing.assert_array_equal(tr.states, lmb.states)
    np.testing.assert_array_equal(tr.ids, lmb.labels)
    np.testing.assert_array_equal(est.extract(out.density), lmb.states)
    a, b = lmb.labels
    winner = np.array([[0, 1, 0]])  # born at scan 1 by origin 0: earlier than ours
    est.relabel(LabelMatch(a[None], winner, np.zeros(1)))
    assert (est.state.tracks.labels == winner).all(axis=1).sum() == 1
    est.relabel(LabelMatch(b[None], winner, np.zeros(1)))  # held by the other track: no
    assert (est.state.tracks.labels == b).all(axis=1).sum() == 1


def test_a_track_takes_its_label_when_first_published_and_keeps_it():
    """An own-born track is relabelled ``(origin, k, PUBLISHED_BASE + i)`` at the scan its
    existence first exceeds the publish threshold (so "earliest birth" means earliest on the
    network), keeps that label on later scans, and a label taken from the network (relabel)
    is never restamped."""
    rng = np.random.default_rng(6)
    est = LmbEstimator(_filter(origin=2), origin=2)
    first: set[tuple] = set()
    for k, z in enumerate(_targets_scans(rng, 8), start=1):
        est.begin_scan(k)
        out = est.step(1, z)
        t = est.state.tracks
        pub = t.existence > est.publish_threshold
        np.testing.assert_array_equal(out.labels["posterior"], t.labels[t.owner][pub[t.owner]])
        for lab in t.labels[pub].tolist():
            if lab != [0, 1, 0]:  # every published own label stamped
                assert lab[0] == 2 and lab[2] >= PUBLISHED_BASE
                first.add(tuple(lab))
        if k == 5:
            a = t.labels[pub][0]
            est.relabel(LabelMatch(a[None], np.array([[0, 1, 0]]), np.zeros(1)))
    labels = est.state.tracks.labels
    assert len(first) == 2  # two targets, each stamped once, at its first publication
    assert (labels == [0, 1, 0]).all(axis=1).sum() == 1  # the network's label stays
    assert sum((labels == lab).all(axis=1).sum() for lab in first) == 1


def test_bad_settings_are_one_line_errors():
    with pytest.raises(ValueError, match="origin"):
        LmbEstimator(_filter(origin=1), origin=2)
    with pytest.raises(ValueError, match="publish_threshold"):
        LmbEstimator(_filter(), publish_threshold=1.5)
    with pytest.raises(ValueError, match="extraction rule"):
        LmbEstimator(_filter(), extraction="nope")
    with pytest.raises(ScenarioError, match="need birth components"):
        load_scenario("seed001", {"network.filter": "lmb", "fusion.rule": "hybrid",
                                  "birth.model": "measurements"})
    with pytest.raises(ScenarioError, match="'ratio', which 'lmb' peers do not take"):
        load_scenario("seed000", {"network.filter": "lmb", "fusion.rule": "ratio"})


def test_kind_builds_from_the_scenario():
    scn = load_scenario("seed000", {"network.filter": "lmb"})
    est, fuser = kind("lmb").build(scn, "s2", 0)
    f = make_lmb_filter(scn, "s2", 1)
    # network.birth_ids "shared" (default): own origins from 1, births alike at origin 0
    assert est.origin == 2 and est.filter.origin == 2 and est.filter.adaptive_birth
    assert est.filter.shared_origin == 0 and est.filter.birth_cell == scn.lmb.birth_cell
    own, _ = kind("lmb").build(load_scenario("seed000", {"network.filter": "lmb",
                                                         "network.birth_ids": "own"}), "s2", 0)
    assert own.origin == 1 and own.filter.origin == 1 and own.filter.shared_origin is None
    assert est.filter.sensor.clutter_intensity == f.sensor.clutter_intensity > 0
    assert est.publish_threshold == scn.fusion.level2_threshold
    assert type(fuser).__name__ == "HybridFuser"


# -- the seed-000 twin ---------------------------------------------------------------------


@pytest.fixture(scope="module")
def seed000():
    scn = load_scenario("seed000", {"network.filter": "lmb"})
    return scn, run_twin(scn, 0)


def test_seed000_every_scan_and_fusion_beats_local(seed000):
    """Measured (python -m pytest tests/test_lmb_peers.py -k seed000 -s): mean OSPA local
    28.2 / 29.2 / 28.0 m, fused 20.0 m at s1 / s2 / s3 (GM-PHD peers: 39.1 / 36.0 / 38.6,
    14.1; the LMB's adaptive births find a target 2 scans after it appears, the GM-PHD's
    truth births at once)."""
    scn, twin = seed000
    for p in scn.sensor_names:
        s = twin.summary(p)
        st = s["stats"]
        print(f"{p}: local {s['mean_ospa_local']:.2f} fused {s['mean_ospa_fused']:.2f}")
        assert s["scans"] == scn.num_scans and not s["internal_errors"]
        assert st["fusions"] == scn.num_scans and st["tracks_out"] == scn.num_scans
        assert s["ospa_scored"] == {"local": scn.num_scans, "fused": scn.num_scans}
        assert s["mean_ospa_fused"] < 0.8 * s["mean_ospa_local"]
        assert s["mean_ospa_local"] < 0.25 * scn.metrics.ospa_cutoff  # it tracks


def test_seed000_one_id_per_target(seed000):
    """Measured: fused label agreement 100 %, 0 identity switches of confirmed tracks at each
    peer; over all fused tracks 0 (1 before own tracks took their label at first publication:
    peers.lmb_estimator.PUBLISHED_BASE) until LMB peers published tentative tracks (pooled
    existence, the default since b2a0383): then 1 at s1 (4.48 per 1,000), so all tracks are held
    to the issue's seed-000 bound of 5 per 1,000 and confirmed ones to its 1 per 1,000; local
    tracks 2-5 switches (they take the network's ids as fusions spread them)."""
    scn, twin = seed000
    names, c = scn.sensor_names, scn.metrics.ospa_cutoff
    tabs, truth = twin_tables(twin, names, "fused")
    ag = label_agreement(tabs, truth, gate=c)
    conf = label_agreement(twin_tables(twin, names, "fused", confirmed=True)[0], truth, gate=c)
    print(f"fused agreement {ag['agreement']:.4f} of {ag['confirmed']}, confirmed "
          f"{conf['agreement']:.4f} of {conf['confirmed']}")
    assert ag["confirmed"] > 200 and ag["agreement"] >= 0.99 and conf["agreement"] >= 0.99
    confirmed = twin_tables(twin, names, "fused", confirmed=True)[0]
    for p, tab in tabs.items():
        r = track_report(truth, tab, c=c, with_hota=False, with_tgospa=False)
        rc = track_report(truth, confirmed[p], c=c, with_hota=False, with_tgospa=False)
        print(f"{p}: {r['switches']} switches, {r['switches_per_1000']:.2f} per 1,000; "
              f"confirmed {rc['switches']}")
        assert r["truth_scans"] > 200 and r["switches_per_1000"] <= 5.0
        assert rc["truth_scans"] > 200 and rc["switches_per_1000"] <= 1.0
    local, _ = twin_tables(twin, names, "local")
    for tab in local.values():
        assert len(tab.id) > 200 and np.unique(tab.id).size < 40


def test_seed000_feedback_runs():
    """With feedback the fused PHD becomes each LMB's prior (one Bernoulli per fused label):
    every scan processed, no error, and the targets still tracked."""
    scn = load_scenario("seed000", {"network.filter": "lmb", "network.feedback": True,
                                    "scenario.num_scans": 40})
    twin = run_twin(scn, 0)
    for p in scn.sensor_names:
        s = twin.summary(p)
        print(f"{p} feedback: local {s['mean_ospa_local']:.2f} fused {s['mean_ospa_fused']:.2f}")
        assert s["scans"] == 40 and not s["internal_errors"]
        assert s["mean_ospa_fused"] < 0.3 * scn.metrics.ospa_cutoff
