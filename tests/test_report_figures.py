"""What the campaign report's figures draw (issue 26): read back from the figure itself (its
lines and bands as matplotlib holds them), not from the PNG."""

from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np
import pytest
from matplotlib.figure import Figure
from sensornet.sim.campaign.report import ospa_time_figure, sweep_figure

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture
def drawn(monkeypatch):
    """Every figure saved, kept for inspection (the report closes them after saving)."""
    figures: list[Figure] = []
    real = Figure.savefig

    def keep(self, *args, **kwargs):
        figures.append(self)
        return real(self, *args, **kwargs)

    monkeypatch.setattr(Figure, "savefig", keep)
    return figures


def test_ospa_bands_stay_between_zero_and_the_cut_off(tmp_path, drawn):
    rng = np.random.default_rng(1)
    runs = np.where(rng.random((5, 30)) < 0.5, 0.0, 200.0)  # wild spread: mean +- half leaves
    runs[:, :3] = [[0.0], [0.0], [0.0], [0.0], [6.0]]        # [0, 200] on most scans
    manifest = {"name": "t", "scenario": "seed000",
                "cells": [{"index": 0, "label": "cell", "values": {}}]}
    assert ospa_time_figure(manifest, {0: {"ospa_k.fused": runs.tolist()}}, tmp_path, 1)
    ax = drawn[-1].axes[0]
    band = ax.collections[0].get_paths()[0].vertices[:, 1]
    assert band.min() >= 0.0 and band.max() <= 200.0  # seed 000's cut-off
    mean = runs.mean(axis=0)
    half = 2.776 * runs.std(axis=0, ddof=1) / np.sqrt(5)
    assert (mean - half).min() < 0 and (mean + half).max() > 200  # unclipped it would leave
    assert "(m" in ax.get_ylabel()


def test_a_sweep_over_tables_is_spaced_by_their_numbers_with_the_local_baseline(tmp_path,
                                                                                 drawn):
    highs = [0, 1, 2, 4]
    cells, manifest_cells = {}, []
    for i, h in enumerate(highs):
        cells[i] = {"fused_ospa": [10.0 + h, 11.0 + h], "local_ospa": [30.0, 31.0]}
        manifest_cells.append({"index": i, "label": f"high={h}", "values": {
            "faults.default.delay": {"kind": "scans", "low": 0, "high": h},
            "network.policy": "nale"}})
    manifest = {"name": "t", "scenario": "seed000", "cells": manifest_cells}
    spec = {"x": "faults.default.delay", "y": "fused_ospa", "lines": "network.policy",
            "baseline": "local_ospa"}
    assert sweep_figure(spec, manifest, cells, tmp_path, 1)
    ax = drawn[-1].axes[0]
    fused = [ln for ln in ax.lines if ln.get_linestyle() != "--" and len(ln.get_xdata()) == 4]
    assert [float(x) for x in fused[0].get_xdata()] == [0.0, 1.0, 2.0, 4.0]
    np.testing.assert_allclose(np.asarray(fused[0].get_ydata(), float), [10.5, 11.5, 12.5, 14.5])
    dashed = [ln for ln in ax.lines if ln.get_linestyle() == "--"]
    assert len(dashed) == 1 and "local_ospa" in dashed[0].get_label()
    np.testing.assert_allclose(np.asarray(dashed[0].get_ydata(), float), [30.5] * 4)
    assert ax.get_ylabel() == "fused_ospa (m)" and "high" in ax.get_xlabel()


def test_every_shipped_sweep_draws_each_peer_alone_beside_the_fused_ospa():
    """README: 'The sweeps' figures draw each peer alone dashed beside the fused OSPA'."""
    sweeps = 0
    for path in sorted((ROOT / "sim" / "campaigns").glob("*.toml")):
        for fig in tomllib.loads(path.read_text()).get("figures", []):
            if fig.get("kind") == "sweep" and "ospa" in fig.get("y", "fused_ospa"):
                sweeps += 1
                assert fig.get("baseline") == "local_ospa", path.name
    assert sweeps >= 3
