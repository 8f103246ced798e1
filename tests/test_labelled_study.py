"""The labelled centralised references and the labelled-tracking study (issue 33 item 6;
sim/studies/labelled): one sensor's centralised LMB is that sensor's LMB, the labelled
centralised GM-PHD is the unlabelled one of the offline experiment, and the study's rows are
the track metrics of the twin's tables."""

from __future__ import annotations

import numpy as np
import pytest
from sensornet.sim.kinds.lmb import make_lmb_filter
from sensornet.sim.run.twin import run_twin
from sensornet.sim.scenario import load_scenario
from sensornet.sim.studies.labelled.centralised import (
    CentralLmb,
    central_gmphd,
    central_lmb,
    run_central,
)
from sensornet.sim.studies.labelled.study import (
    Graph,
    format_markdown,
    one_run,
    peer_tables,
    scenario_of,
    summarise,
    targets,
    truth_table,
)
from sensornet.sim.studies.seed000.montecarlo import run_once
from sensornet.sim.world import generate_run
from sensornet.sim.world.build import make_filter
from sensornet.tracking.track_metrics import label_agreement, track_report


def _scn(kind: str, scans: int = 25, **extra):
    return load_scenario("seed000", {"network.filter": kind, "scenario.num_scans": scans,
                                     **extra})


def test_one_sensor_central_lmb_is_that_sensors_lmb():
    scn = _scn("lmb")
    truth, scans = generate_run(scn, 0)
    f = make_lmb_filter(scn, "s1", 0)
    central = CentralLmb([make_lmb_filter(scn, "s1", 0)])
    a, b = f.initial(), central.initial()
    for k, z in enumerate(scans[0], start=1):
        a, b = f.step(a, z, k), central.step(b, [z], k)
        for x, y in ((a.tracks.labels, b.tracks.labels), (a.tracks.existence,
                     b.tracks.existence), (a.tracks.means, b.tracks.means), (a.hits, b.hits),
                     (a.pending.means, b.pending.means)):
            np.testing.assert_array_equal(x, y)
    assert len(f.extract(a)) >= 2  # it tracks


def test_central_lmb_counts_a_scan_once_and_tracks():
    scn = _scn("lmb")
    truth, scans = generate_run(scn, 0)
    central = central_lmb(scn)
    state = central.initial()
    for k in range(1, scn.num_scans + 1):
        state = central.step(state, [s[k - 1] for s in scans], k)
        assert state.hits.max(initial=0) <= k  # three correctors, one count per scan
    tracks, _ = run_central(central_lmb(scn), scans)
    assert len(tracks) == scn.num_scans and len(tracks[-1].states) == len(truth.states[-1])
    assert tracks[-1].status.all()
    with pytest.raises(ValueError, match="births"):
        CentralLmb(central.filters, births="all")
    with pytest.raises(ValueError, match="expected 3 scans"):
        central.step(state, scans[:1])


def test_labelled_central_gmphd_is_the_experiments_centralised_filter():
    """The same states as the unlabelled iterated corrector (sensornet experiment's), and the
    labels: one per extracted state."""
    scn = _scn("gmphd")
    truth, scans = generate_run(scn, 0)
    f = make_filter(scn, scn.sensor_names)
    tracks, _ = run_central(central_gmphd(scn), scans)
    mix = f.initial()
    for k, e in enumerate(tracks):
        mix = f.step(mix, *[s[k] for s in scans])
        np.testing.assert_array_equal(e.states, f.extract(mix))
        assert len(e.labels) == len(e.states) == len(e.status)


def test_study_rows_are_the_track_metrics_of_the_twin():
    """A 1-run, 12-scan slice: the fused row recomputed from the twin's results tables by
    tracking.track_metrics, the centralised GM-PHD row's OSPA equal to the offline
    experiment's centralised OSPA (sim.studies.seed000.montecarlo)."""
    g = Graph("seed000", "seed000", 1)
    rows = one_run(g, 0.99, 10.0, "gmphd", 0, ("hybrid",), 12, True)
    assert [r["estimate"] for r in rows] == ["local", "fused", "centralised"]
    fused = rows[1]
    scn = scenario_of(g, "gmphd", 0.99, 10.0, 12, {"fusion.rule": "hybrid"})
    twin = run_twin(scn, 0)
    truth, _ = generate_run(scn, 0)
    T = truth_table(truth)
    code: dict = {}
    tabs = peer_tables(twin, scn.sensor_names, "fused", code)
    c = scn.metrics.ospa_cutoff
    reps = [track_report(T, t, c=c, window=10, scans=np.arange(1, 13), with_hota=False)
            for t in tabs.values()]
    assert fused["ospa2"] == pytest.approx(np.mean([r["ospa2_mean"] for r in reps]))
    assert fused["tgospa"] == pytest.approx(np.mean([r["tgospa_per_scan"] for r in reps]))
    assert fused["switches_max"] == max(r["switches_per_1000"] for r in reps)
    assert fused["agreement"] == label_agreement(tabs, T, gate=c)["agreement"]
    assert fused["ospa"] == pytest.approx(np.mean([twin.mean_ospa(p) for p in
                                                   scn.sensor_names]))
    assert 0 < fused["ospa2"] < c and fused["tuples"] > 0 and fused["cpu_ms"] > 0
    exp = run_once(scenario_of(g, "gmphd", 0.99, 10.0, 12), 0)
    assert rows[2]["ospa"] == pytest.approx(exp.ospa["centralized"].mean(), rel=1e-12)
    summary = summarise(rows)
    text = format_markdown(summary) + targets(summary)
    assert text.count("\n") == 2 + 3 + 2 + 1 and "| seed000 | 0.99 | gmphd | fused |" in text
