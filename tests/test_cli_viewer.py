"""The Rerun view explains itself (issue 16): a legend panel, distinct peer colours, local dashed
and fused solid, truth cardinality, the region outline and grid, a view centred on a single
target, and the IMM model probabilities in view for IMM scenarios."""

from __future__ import annotations

import subprocess
import sys
from itertools import combinations
from pathlib import Path

import numpy as np
import pytest
from sensornet.peers import rerun_sink
from sensornet.peers.rerun_sink import (
    COLOR_NAMES,
    PALETTE,
    RerunSink,
    color_of,
    dashed,
    default_blueprint,
    ellipses,
    grid_lines,
    legend_markdown,
    lighter,
    nice_step,
    region_outline,
)


def test_first_peer_colours_are_far_apart():
    first = np.array(PALETTE[:6], dtype=float)
    gaps = [np.linalg.norm(a - b) for a, b in combinations(first, 2)]
    assert min(gaps) > 100, gaps  # no two near-identical greens among six lines
    assert len(COLOR_NAMES) == len(PALETTE) and len(set(COLOR_NAMES)) == len(COLOR_NAMES)
    assert color_of(len(PALETTE)) == color_of(0)
    assert all(a >= b for a, b in zip(lighter(PALETTE[0]), PALETTE[0], strict=True))


def test_dashed_ellipse_keeps_every_other_segment():
    E = ellipses(np.array([[0.0, 0.0, 0.0, 0.0]]), np.eye(4)[None] * 4.0)  # (1, 33, 2)
    D = dashed(E)
    assert D.shape == (16, 2, 2)
    np.testing.assert_allclose(D[0], E[0, 0:2])
    np.testing.assert_allclose(D[1], E[0, 2:4])
    assert dashed(np.zeros((0, 33, 2))).shape == (0, 2, 2)


def test_region_outline_and_grid():
    region = ((-1000.0, 1000.0), (-1000.0, 1000.0))
    outline = region_outline(region)
    assert outline.shape == (5, 2) and (outline[0] == outline[-1]).all()
    assert nice_step(2000.0) == 500.0 and nice_step(20000.0) == 5000.0
    lines, ticks, labels = grid_lines(region)
    assert len(lines) == 10 and len(ticks) == len(labels) == 10
    assert "x -1000 m" in labels and "y 500 m" in labels
    # labels sit outside the frame: x below its bottom edge, y left of its left edge, so a
    # sensor on the edge or in a corner (seed 001's radars at y = 0) keeps its label clear
    xs = [t for t, lab in zip(ticks, labels, strict=True) if lab.startswith("x")]
    ys = [t for t, lab in zip(ticks, labels, strict=True) if lab.startswith("y")]
    assert all(t[1] < -1000.0 for t in xs) and all(t[0] < -1000.0 for t in ys)
    seed001 = grid_lines(((0.0, 20000.0), (0.0, 12000.0)))[1]
    radars = np.array([[0.0, 0.0], [12000.0, 0.0]])
    assert np.linalg.norm(seed001[:, None] - radars[None], axis=-1).min() >= 0.03 * 20000 - 1e-9


def test_legend_names_every_peer_and_mark():
    text = legend_markdown(["s1", "s2", "s3"])
    for needle in ("s1** red", "s2** blue", "s3** orange", "gold", "dashed", "solid",
                   "dotted = local", "grey frame"):
        assert needle in text, needle
    imm = legend_markdown(["r1", "r2"], single_target=True, imm=True, follow_radius=400)
    assert "around the target" in imm and "particles" in imm and "CA dotted" in imm


def _views(blueprint) -> list:
    """Every view in a blueprint (walks containers)."""
    out, stack = [], [blueprint.root_container]
    while stack:
        item = stack.pop()
        if hasattr(item, "column_shares"):  # a container (views have no shares)
            stack.extend(item.contents)
        else:
            out.append(item)
    return out


def test_blueprint_opens_on_scans_and_fixes_the_axes_that_need_it():
    bp = default_blueprint(["r1", "r2"], imm=True, ospa_cutoff=100.0)
    assert bp.time_panel.timeline == "scan"
    views = {v.name: v for v in _views(bp)}
    prob = views["model probabilities (IMM)"].properties["ScalarAxis"]
    assert prob.range.as_arrow_array().to_pylist() == [[0.0, 1.0]]
    ospa = views["OSPA (m; grey: cut-off)"].properties["ScalarAxis"]
    assert ospa.range.as_arrow_array().to_pylist() == [[0.0, 105.0]]


def test_track_labels_follow_tracks_and_truth_paths_join_ids():
    from sensornet.peers.rerun_sink import TrackLabels, TruthPaths

    labels = TrackLabels(gate=50.0)
    assert labels.assign(np.array([[0.0, 0.0], [500.0, 0.0]])) == [0, 1]
    # the same two tracks, listed in the other order and moved a little: same numbers
    assert labels.assign(np.array([[510.0, 5.0], [8.0, 3.0]])) == [1, 0]
    # one jumps beyond the gate: a new number; a new track: another
    assert labels.assign(np.array([[8.0, 3.0], [900.0, 0.0], [700.0, 0.0]])) == [0, 2, 3]
    assert labels.assign(np.zeros((0, 2))) == []
    paths = TruthPaths()
    paths.add([4, 7], np.array([[0.0, 0.0], [10.0, 10.0]]))
    assert paths.strips() == []
    paths.add([7, 4], np.array([[11.0, 11.0], [1.0, 0.0]]))
    strips = sorted(paths.strips(), key=lambda a: a[0, 0])
    np.testing.assert_array_equal(strips[0], [[0.0, 0.0], [1.0, 0.0]])
    np.testing.assert_array_equal(strips[1], [[10.0, 10.0], [11.0, 11.0]])


def test_blueprint_has_a_legend_panel_and_adapts_to_the_scenario():
    import rerun.blueprint as rrb

    base = _views(default_blueprint(["s1", "s2", "s3"]))
    names = {v.name for v in base}
    assert {"map", "legend", "OSPA (m; grey: cut-off)", "cardinality (truth gold)"} <= names
    assert any(isinstance(v, rrb.TextDocumentView) for v in base)
    assert "around the target" not in names
    single = _views(default_blueprint(["r1", "r2"], single_target=True, imm=True))
    follow = [v for v in single if v.name == "around the target"]
    assert len(follow) == 1 and str(follow[0].origin) == "/follow"
    # the model probabilities are one of the always-visible plots for IMM peers, not a tab
    top = default_blueprint(["r1", "r2"], single_target=True, imm=True).root_container
    column = top.contents[1]
    assert "model probabilities (IMM)" in {getattr(v, "name", None) for v in column.contents}


@pytest.mark.network  # starts the world process
def test_world_recording_with_decorations_verifies(tmp_path):
    path = tmp_path / "world.rrd"
    sink = RerunSink().open("test-run", path, peers=["r1", "r2"], single_target=True,
                            imm=True, follow_radius=400.0)
    sink.decorate(["r1", "r2"], region=((0.0, 20000.0), (0.0, 12000.0)), imm=True,
                  single_target=True, follow_radius=400.0)
    for k in range(1, 4):
        sink.time(k, float(k))
        sink.points("world/truth", np.array([[6000.0 + k, 8400.0]]), (255, 215, 0))
        sink.scalar("metrics/cardinality/truth", 1)
        sink.follow([6000.0 + k, 8400.0])
    sink.close()
    assert path.stat().st_size > 0
    exe = str(Path(sys.executable).with_name("rerun"))
    check = subprocess.run([exe, "rrd", "verify", str(path)], capture_output=True, text=True,
                           timeout=120)
    assert check.returncode == 0, check.stderr


def test_a_peer_sends_no_blueprint(monkeypatch, tmp_path):
    """Only the world (which names the peers) sends the layout: one layout in the viewer."""
    sent = []
    import rerun as rr

    real = rr.set_sinks
    monkeypatch.setattr(rr, "set_sinks", lambda *s, default_blueprint=None:
                        (sent.append(default_blueprint), real(*s))[1])
    RerunSink().open("peer-run", tmp_path / "p.rrd").close()
    RerunSink().open("world-run", tmp_path / "w.rrd", peers=["s1"]).close()
    assert sent[0] is None and sent[1] is not None


def test_spawn_without_a_display_says_so_at_once(monkeypatch, capsys):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    monkeypatch.setattr(rerun_sink.sys if hasattr(rerun_sink, "sys") else sys, "platform",
                        "linux")
    port = 1  # nothing listens there
    assert rerun_sink.spawn_viewer(port) is False
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no display" in err[0]
