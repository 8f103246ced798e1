"""Per-scan results (issue 26): every run writes one Parquet table of what each peer estimated
and scored at each scan, and ``sensornet plot`` draws it. The table must agree with the
summary's means (a missing output is a row scored at the cut-off) and with a recomputation of
OSPA from its own tracks and truth columns."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from sensornet.peers.scan_results import COLUMNS, ScanResults, read_table, write_part
from sensornet.peers.scoring import Scorer
from sensornet.tracking.metrics import gospa, ospa

from sensornet.cli import main

ROOT = Path(__file__).resolve().parents[1]


def _recomputed(cols: dict, meta: dict, i: int) -> float:
    pos = meta["position_index"]
    est = np.asarray(cols["tracks"][i], float)
    true = np.asarray(cols["truth"][i], float)
    est = est[:, pos] if est.size else np.zeros((0, 2))
    true = true[:, pos] if true.size else np.zeros((0, 2))
    return ospa(est, true, meta["cutoff"], meta["order"])


def test_missing_outputs_are_rows_at_the_cut_off_and_means_agree(tmp_path):
    """A scorer that saw two outputs, a skipped scan and an output that never came: the table
    has a row for each, the misses at the cut-off with every true target missed, and the
    table's mean is the scorer's mean."""
    truth = {k: np.array([[0.0, 1.0, 10.0 * k, 0.0], [50.0, 0.0, 0.0, 0.0]]) for k in range(9)}
    s = Scorer(100.0, 2.0, (0, 2), truth=truth.get)
    for k in (1, 2, 5):
        s.expect(k)
    s.output("fused", 1, truth[1][:1] + 3.0)
    s.output("fused", 2, np.zeros((0, 4)))
    s.skipped(range(3, 5))
    s.finish()  # scan 5's fused and every local output never came
    write_part(s.results, "s9", tmp_path / "p.scans.msgpack")
    from sensornet.peers.scan_results import merge_parts

    merge_parts([tmp_path / "p.scans.msgpack"], tmp_path / "results.parquet")
    cols, meta = read_table(tmp_path / "results.parquet")
    assert tuple(cols) == COLUMNS and meta["cutoff"] == 100.0
    fused = [i for i, w in enumerate(cols["estimate"]) if w == "fused"]
    assert [cols["scan"][i] for i in fused] == [1, 2, 3, 4, 5]
    assert [cols["scored"][i] for i in fused] == [True, True, False, False, False]
    for i in fused:
        assert cols["ospa"][i] == pytest.approx(_recomputed(cols, meta, i))
        if not cols["scored"][i]:
            assert cols["ospa"][i] == 100.0 and cols["gospa_missed"][i] == 2
            assert cols["tracks"][i] == []
    assert np.mean([cols["ospa"][i] for i in fused]) == pytest.approx(s.mean("fused"))
    local = [i for i, w in enumerate(cols["estimate"]) if w == "local"]
    assert np.mean([cols["ospa"][i] for i in local]) == pytest.approx(s.mean("local"))
    assert len(local) == 5  # 1, 2, 5 never came; 3, 4 skipped


def test_gospa_columns_match_the_metric():
    r = ScanResults(40.0, 2.0, (0, 1))
    X = np.array([[0.0, 0.0], [100.0, 0.0]])
    Y = np.array([[1.0, 1.0], [300.0, 0.0], [0.0, 90.0]])
    r.scored(1, "fused", X, Y)
    row = dict(zip(COLUMNS, ("s", *r.rows[0][:10]), strict=False))
    assert row["gospa"] == pytest.approx(gospa(X, Y, 40.0, 2.0))
    assert (row["gospa_missed"], row["gospa_false"]) == (2, 1)
    assert row["gospa_localisation"] == pytest.approx(2.0)


def test_run_sim_writes_the_table_and_plot_draws_it(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["run", "seed000", "--sim", "--set", "scenario.num_scans=15",
                 "--out", str(out)]) == 0
    assert "per-scan results:" in capsys.readouterr().out
    cols, meta = read_table(out / "results.parquet")
    assert sorted(set(cols["peer"])) == ["s1", "s2", "s3"]
    assert len(cols["scan"]) == 3 * 15 * 2
    for i in range(0, len(cols["scan"]), 7):
        assert cols["ospa"][i] == pytest.approx(_recomputed(cols, meta, i))
    assert main(["plot", str(out), "--out", str(tmp_path / "fig")]) == 0
    for name in ("tracks.png", "metrics.png"):
        assert (tmp_path / "fig" / name).read_bytes()[:4] == b"\x89PNG"


def test_plot_of_a_folder_without_results_is_one_line(tmp_path, capsys):
    assert main(["plot", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no per-scan results" in err[0]


@pytest.mark.network
def test_a_process_run_writes_the_table_with_latency_and_matches_the_summaries(tmp_path):
    out = tmp_path / "run"
    env = {**os.environ, "PYTHONPATH": str(ROOT), "RERUN_ANALYTICS": "0"}
    proc = subprocess.run([sys.executable, "-m", "sensornet", "run", "seed000", "--no-rerun",
                           "--set", "scenario.num_scans=12", "--out", str(out)],
                          capture_output=True, text=True, timeout=240, cwd=tmp_path, env=env)
    assert proc.returncode == 0, proc.stderr + proc.stdout
    cols, meta = read_table(out / "results.parquet")
    peer = np.array(cols["peer"])
    which = np.array(cols["estimate"])
    value = np.array(cols["ospa"])
    for name in ("s1", "s2", "s3"):
        summary = json.loads((out / f"peer-{name}.json").read_text())
        for w in ("local", "fused"):
            sel = (peer == name) & (which == w)
            assert sel.sum() == 12
            assert value[sel].mean() == pytest.approx(summary[f"mean_ospa_{w}"], rel=1e-9)
            gospa = np.array(cols["gospa"])[sel]
            assert gospa.mean() == pytest.approx(summary[f"mean_gospa_{w}"], rel=1e-9)
        lat = np.array(cols["latency_ms"])[(peer == name) & (which == "fused")]
        assert np.isfinite(lat).sum() >= 10 and (lat[np.isfinite(lat)] > 0).all()
