"""A run's outputs (issues 33 item 5 and 35 item 6): track-level numbers in the summaries, the
run's table (killed peers, legend, verdict, a run without scans), ``--out`` reuse refused,
progress without "nan", report intervals of non-negative metrics, plots by track id. The
process side is in tests/test_run_outputs_network.py."""

from __future__ import annotations

import io
import json
import math

import numpy as np
import pytest
from sensornet.peers.scan_results import write_part
from sensornet.sim.campaign import load_campaign, run_campaign
from sensornet.sim.campaign.report import bounds, write_report
from sensornet.sim.report import run_plots
from sensornet.sim.run import launcher
from sensornet.sim.run.progress import Progress
from sensornet.sim.run.run_handle import RunHandle
from sensornet.sim.run.run_summary import (
    add_track_summary,
    format_summary,
    read_tables,
    verdict,
)
from sensornet.sim.run.track_summary import WINDOW, track_columns, track_summary
from sensornet.sim.run.twin import run_twin
from sensornet.sim.scenario import load_scenario
from sensornet.tracking.track_metrics import TrackTable, label_agreement, track_report

from sensornet.api import Run
from sensornet.cli import main
from sensornet.cli.commands.run import _exit_code
from sensornet.cli.parser import build_parser

POS = [0, 2]


@pytest.fixture(scope="module")
def twin():
    scn = load_scenario("seed000", overrides={"scenario.num_scans": 40})
    result = run_twin(scn, 0)
    tables = {n: result.peers[n].scorer.results.table(n) for n in scn.sensor_names}
    return scn, result, tables


def _reference(tables, which):
    """Per peer a TrackTable built row by row (ids coded by a dict, first row of an id in a
    scan kept), and the truth's: the independent path the summary is checked against."""
    code: dict[tuple, int] = {}
    out, truth = {}, {}
    for p, t in tables.items():
        S, I, X = [], [], []
        for k, e, tr, ids, tru, tids in zip(t["scan"], t["estimate"], t["tracks"],
                                            t["track_ids"], t["truth"], t["truth_ids"],
                                            strict=True):
            for x, i in zip(tru, tids, strict=True):
                truth[(k, i)] = [x[0], x[2]]
            if e != which:
                continue
            seen: set = set()
            for x, i in zip(tr, ids, strict=True):
                if tuple(i) not in seen:
                    seen.add(tuple(i))
                    S.append(k)
                    I.append(code.setdefault(tuple(i), len(code)))
                    X.append([x[0], x[2]])
        out[p] = TrackTable(np.array(S), np.array(I), np.array(X).reshape(-1, 2))
    keys = sorted(truth)
    return out, TrackTable(np.array([k for k, _ in keys]), np.array([i for _, i in keys]),
                           np.array([truth[k] for k in keys]))


def test_track_summary_equals_the_metrics_computed_directly(twin):
    scn, _, tables = twin
    c = scn.metrics.ospa_cutoff
    ts = track_summary(tables, POS, c)
    scans = np.unique(np.concatenate([t["scan"] for t in tables.values()]))
    for which in ("local", "fused"):
        ref, truth = _reference(tables, which)
        for p, tab in ref.items():
            r = track_report(truth, tab, c=c, window=WINDOW, scans=scans, with_hota=False,
                             with_tgospa=False)
            got = ts["peers"][p][which]
            assert got["ospa2"] == pytest.approx(r["ospa2_mean"], rel=1e-12)
            assert got["ospa2_run"] == pytest.approx(r["ospa2"], rel=1e-12)
            assert got["switches"] == r["switches"]
            assert got["switches_per_1000"] == pytest.approx(r["switches_per_1000"])
            assert got["truth_scans"] == r["truth_scans"] > 50
    fused, truth = _reference(tables, "fused")
    net = label_agreement(fused, truth, gate=c)
    assert ts["label_agreement"] == pytest.approx(net["agreement"])
    assert ts["confirmed"] == net["confirmed"] > 50
    names = list(fused)
    for p in names:  # three peers: a peer's agreement counts the scans it and another matched
        pair = [label_agreement({p: fused[p], q: fused[q]}, truth, gate=c) for q in names
                if q != p]
        assert 0.0 <= ts["peers"][p]["agreement"] <= 1.0
        assert ts["peers"][p]["agreement"] >= min(x["agreement"] for x in pair) - 1e-12
    cols = track_columns(ts)
    assert cols["fused_ospa2"] == pytest.approx(np.mean([ts["peers"][p]["fused"]["ospa2"]
                                                         for p in names]))
    assert set(cols) == {"fused_ospa2", "local_ospa2", "fused_switches_per_1000",
                         "label_agreement"}


def _columns(peer, rows):
    """A peer's columns from ``(scan, estimate, [(id, x, y)], [(truth id, x, y)])`` rows."""
    cols = {k: [] for k in ("peer", "scan", "estimate", "tracks", "track_ids", "truth",
                            "truth_ids")}
    for k, e, tracks, truth in rows:
        cols["peer"].append(peer)
        cols["scan"].append(k)
        cols["estimate"].append(e)
        cols["tracks"].append([[x, 0.0, y, 0.0] for _, x, y in tracks])
        cols["track_ids"].append([list(i) for i, _, _ in tracks])
        cols["truth"].append([[x, 0.0, y, 0.0] for _, x, y in truth])
        cols["truth_ids"].append([i for i, _, _ in truth])
    return cols


def test_a_switch_and_a_disagreeing_peer_by_hand():
    """Two targets over 4 scans. Peer a: ids A, B throughout. Peer b: A, B for two scans, then
    its ids swap targets (two switches); its local tracks have no ids (a kind without labels:
    None, not a number). Label agreement: the last two scans of both targets disagree, 4 of 8
    target-scans matched at both peers agree."""
    A, B = (0, 1, 0), (1, 1, 0)
    truth = lambda k: [(7, 0.0, 10.0 * k), (9, 500.0, 10.0 * k)]  # noqa: E731
    a = _columns("a", [(k, "fused", [(A, 1.0, 10.0 * k), (B, 501.0, 10.0 * k)], truth(k))
                       for k in range(1, 5)])
    rows_b = [(k, "fused", [(A, 1.0, 10.0 * k), (B, 501.0, 10.0 * k)] if k <= 2
               else [(B, 1.0, 10.0 * k), (A, 501.0, 10.0 * k)], truth(k)) for k in range(1, 5)]
    b = _columns("b", rows_b)
    for k in range(1, 5):  # b's local tracks: states without ids
        b["peer"].append("b")
        b["scan"].append(k)
        b["estimate"].append("local")
        b["tracks"].append([[1.0, 0, 10.0 * k, 0]])
        b["track_ids"].append([])
        b["truth"].append([[x, 0, y, 0] for _, x, y in truth(k)])
        b["truth_ids"].append([7, 9])
    ts = track_summary({"a": a, "b": b}, POS, cutoff=100.0)
    assert ts["peers"]["a"]["fused"]["switches"] == 0
    assert ts["peers"]["b"]["fused"]["switches"] == 2
    assert ts["peers"]["b"]["fused"]["switches_per_1000"] == pytest.approx(1000 * 2 / 8)
    assert ts["peers"]["b"]["local"] is None
    assert ts["label_agreement"] == pytest.approx(0.5) and ts["confirmed"] == 8
    assert ts["peers"]["a"]["agreement"] == pytest.approx(0.5)
    # without truth ids nothing can be scored by id
    a["truth_ids"] = [[] for _ in a["truth_ids"]]
    assert track_summary({"a": a}, POS, cutoff=100.0) == {}


def _summary(scans=10, local=30.0, fused=20.0):
    return {"scans": scans, "mean_ospa_local": local, "mean_ospa_fused": fused,
            "messages_sent": 20, "messages_received": 40, "bytes_sent": 4000,
            "bytes_received": 8000, "rejected_total": 0, "mean_estimate_age": 0.0,
            "latency_ms_median": 4.0, "latency_ms_p99": 7.0}


def test_table_has_track_columns_a_killed_peer_a_legend_and_a_verdict():
    s1 = dict(_summary(), tracks={"local": {"ospa2": 80.0}, "fused": {
        "ospa2": 40.0, "switches_per_1000": 2.5}, "agreement": 0.995})
    text = format_summary({"s1": s1, "s2": _summary(local=25.0, fused=28.0)},
                          missing={"s3": "killed at scan 5"}, cutoff=200.0)
    lines = text.splitlines()
    assert "| OSPA(2) local | OSPA(2) fused | ID sw / 1k | label agr. |" in lines[0]
    assert "| s1 | 10 | 30.0 | 20.0 | 80.0 | 40.0 | 2.5 | 99.5 % |" in text
    assert "| s2 | 10 | 30.0" not in text and "| s2 | 10 | 25.0 | 28.0 | - | - | - | - |" in text
    killed = next(ln for ln in lines if ln.startswith("| s3"))
    assert "killed at scan 5" in killed and "scored a miss" in killed
    assert killed.count("| 200.0 ") == 4  # OSPA and OSPA(2), local and fused: the cut-off
    assert len(killed.split("|")) == len(lines[0].split("|"))  # as many cells as the head
    legend = next(ln for ln in lines if ln.startswith("columns:"))
    assert "in m, cut-off 200 m" in legend and "lower is better" in legend
    assert "higher is better" in legend  # label agreement
    line = next(ln for ln in lines if ln.startswith("verdict:"))
    assert "helped at 1 of 2 peers, not at s2 25.0 -> 28.0" in line and "s3" in line
    assert "nan" not in text


def test_verdict_lines():
    assert verdict({"a": _summary(), "b": _summary(local=40.0, fused=10.0)}).startswith(
        "verdict: fusion helped at every peer (2): fused OSPA 10.0-20.0 m against local "
        "30.0-40.0 m (mean change -54 %)")
    assert "did not help at any peer" in verdict({"a": _summary(local=10.0, fused=12.0)})
    assert verdict({"a": _summary(local=math.nan)}) is None


def test_a_run_without_scans_says_so_instead_of_a_table_of_nan():
    text = format_summary({n: _summary(scans=0, local=math.nan, fused=math.nan)
                           for n in ("s1", "s2")}, cutoff=200.0)
    assert text.startswith("no scan was played") and "nan" not in text and "|" not in text


def test_summary_files_and_parts_gain_the_track_numbers(twin, tmp_path):
    """read_tables concatenates a restarted peer's parts; add_track_summary writes the numbers
    into each peer's newest summary file and nothing else changes in it."""
    scn, result, tables = twin
    for n in scn.sensor_names:
        write_part(result.peers[n].scorer.results, n, tmp_path / f"peer-{n}.scans.msgpack")
        (tmp_path / f"peer-{n}.json").write_text(json.dumps({"peer": n, "scans": 1}))
    (tmp_path / "peer-s1.restart1.json").write_text(json.dumps({"peer": "s1", "scans": 2}))
    got, meta = read_tables(tmp_path)
    assert set(got) == set(scn.sensor_names) and meta["position_index"] == POS
    assert got["s2"]["scan"] == tables["s2"]["scan"]
    summaries = launcher.read_summaries(tmp_path, scn.sensor_names)
    ts = add_track_summary(summaries, got, meta, tmp_path)
    assert ts == track_summary(tables, POS, meta["cutoff"])
    on_disk = json.loads((tmp_path / "peer-s1.restart1.json").read_text())
    assert on_disk["scans"] == 2 and "summary_files" not in on_disk
    assert on_disk["tracks"]["fused"] == ts["peers"]["s1"]["fused"]
    assert on_disk["tracks"]["label_agreement"] == ts["label_agreement"]
    assert "tracks" not in json.loads((tmp_path / "peer-s1.json").read_text())


def test_run_sim_prints_track_columns_and_refuses_a_used_out(tmp_path, capsys):
    out = tmp_path / "run"
    argv = ["run", "--sim", "--set", "scenario.num_scans=20", "--out", str(out)]
    assert main(argv) == 0
    text = capsys.readouterr().out
    row = next(ln for ln in text.splitlines() if ln.startswith("| s1 | 20 |"))
    assert row.count("%") == 1  # label agreement
    assert any(ln.startswith("columns:") for ln in text.splitlines())
    assert any(ln.startswith("verdict:") for ln in text.splitlines())
    before = sorted(p.name for p in out.iterdir())
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert f"--out {out} already holds a run" in err and len(err.strip().splitlines()) == 1
    assert sorted(p.name for p in out.iterdir()) == before


def test_one_host_process_is_singular(tmp_path, capsys, monkeypatch):
    def stop_here(*a, **k):
        raise RuntimeError("stopped before starting anything")

    monkeypatch.setattr(launcher, "start_run", stop_here)
    with pytest.raises(RuntimeError, match="stopped before"):
        main(["run", "seed000", "--per-process", "3", "--no-rerun", "--out",
              str(tmp_path / "o")])
    first = capsys.readouterr().out.splitlines()[0]
    assert "peers in 1 host process over Zenoh" in first, first


def test_network_default_said_alike_by_run_and_echo():
    """run's default network is a fresh random name (the launcher's run-XXXXXXXX); echo's help
    says so too, not "the scenario's name"."""
    sub = next(a for a in build_parser()._actions if a.dest == "command").choices
    run_help = next(a.help for a in sub["run"]._actions if a.dest == "network")
    echo_help = next(a.help for a in sub["echo"]._actions if a.dest == "network")
    for h in (run_help, echo_help):
        assert "random name" in h and "run-XXXXXXXX" in h and "scenario" not in h


def test_progress_says_no_eta_rather_than_nan():
    stream = io.StringIO()
    with Progress(3, "runs", stream=stream) as bar:
        for _ in range(3):
            bar.advance()
    text = stream.getvalue()
    assert "nan" not in text
    first = text.splitlines()[0]
    assert first.endswith("eta ?") and "0/3 runs" in first
    assert "eta " in text.splitlines()[1] and text.splitlines()[-1].endswith("done")


def test_bounds_clip_a_non_negative_metric_at_zero():
    assert bounds(0.1, 0.3, True) == (0.0, pytest.approx(0.4), True)
    assert bounds(0.1, 0.3, False) == (pytest.approx(-0.2), pytest.approx(0.4), False)
    assert bounds(5.0, 1.0, True) == (4.0, 6.0, False)


def test_report_shows_track_columns_and_no_interval_below_zero(tmp_path):
    """A twin campaign: the track-level columns are in the rows and the report's overview; no
    interval of a metric that no run found negative goes below 0."""
    path = tmp_path / "c.toml"
    path.write_text('[campaign]\nname = "t-tracks"\nscenario = "seed000"\nrunner = "twin"\n'
                    'runs = 3\n\n[set]\n"scenario.num_scans" = 15\n')
    run_campaign(load_campaign(path), tmp_path / "camp", jobs=1, progress=False)
    write_report(tmp_path / "camp")
    md = (tmp_path / "camp" / "report" / "report.md").read_text()
    head = next(ln for ln in md.splitlines() if ln.startswith("| cell | runs |"))
    for col in ("fused_ospa2", "local_ospa2", "fused_switches_per_1000", "label_agreement"):
        assert col in head
    for ln in md.splitlines():  # every "[low, high]" interval: low >= 0 (no metric is signed)
        for part in ln.split("[")[1:]:
            low = part.split(",")[0]
            if low.replace(".", "").replace("-", "").isdigit():
                assert float(low) >= 0, ln
    assert "(clipped at 0)" in md or "–" in md


def test_plot_draws_one_line_per_track_id_in_its_colour(twin, tmp_path, monkeypatch):
    scn, result, _ = twin
    for n in scn.sensor_names:
        write_part(result.peers[n].scorer.results, n, tmp_path / f"peer-{n}.scans.msgpack")
    plt = run_plots.plt_module()
    figs = []
    monkeypatch.setattr(plt, "close", figs.append)
    run_plots.plot_run(tmp_path)
    assert (tmp_path / "tracks.png").stat().st_size > 10_000
    fig = figs[0]
    cols, meta = run_plots.load_results(tmp_path)
    api = Run(scn, result, cols, meta)  # an independent reading of the same table by id
    truth = api.truth_by_id()
    for ax, peer in zip(fig.axes, scn.sensor_names, strict=False):
        tracks = api.tracks_by_id(peer)
        assert tracks and ax.get_title() == f"{peer}: {len(tracks)} fused track ids"
        solid = [ln for ln in ax.lines if ln.get_linestyle() == "-"]
        grey = [ln for ln in solid if isinstance(ln.get_color(), str)]  # "0.55"
        lines = [ln for ln in solid if not isinstance(ln.get_color(), str)]
        assert len(grey) == len(truth) and len(lines) == len(tracks)
        for ln, (_, (_, states)), rgb in zip(
                lines, tracks.items(), run_plots.id_colour(np.array(list(tracks))),
                strict=True):
            np.testing.assert_allclose(ln.get_xydata(), states[:, POS])
            np.testing.assert_allclose(ln.get_color(), rgb)
        for ln, (_, states) in zip(grey, truth.values(), strict=True):
            np.testing.assert_allclose(ln.get_xydata(), states[:, POS])


def test_plot_colours_are_the_views():
    view = pytest.importorskip("sensornet.view")
    ids = np.array([[0, 1, 0], [2, 40, 3], [1, 0, 7]])
    np.testing.assert_allclose(run_plots.id_colour(ids), view.id_color(ids) / 255)


def test_a_run_stopped_at_its_timeout_says_so_in_one_line(tmp_path, capsys):
    """A run that outlived its length + --timeout was stopped by the launcher: the exit code is
    1 and one stderr line says why (it used to end silently with code 0, its last scans simply
    missing from the table)."""
    scn = load_scenario("seed000")
    summaries = {n: {"scans": 5, "mean_ospa_fused": 1.0} for n in scn.sensor_names}
    handle = RunHandle(out=tmp_path)
    codes = {"world": 0, **{n: 0 for n in scn.sensor_names}}
    assert _exit_code(scn, tmp_path, handle, codes, summaries, set(), []) == 0
    handle.timed_out = True
    assert _exit_code(scn, tmp_path, handle, codes, summaries, set(), []) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--timeout" in err[0] and "stopped" in err[0], err
