"""The notebook API (issue 26): a scenario, a twin run, tracks and metrics as arrays; the
example notebook's code cells run in order and agree with the twin's summaries."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from sensornet.sim.scenario import ScenarioError
from sensornet.tracking.metrics import ospa

from sensornet.api import scenario, simulate

ROOT = Path(__file__).resolve().parents[1]


def test_run_gives_the_summary_numbers_and_arrays():
    scn = scenario("seed000", {"scenario.num_scans": 12})
    run = simulate(scn, run=3)
    assert run.peers == ["s1", "s2", "s3"]
    for p in run.peers:
        for which in ("local", "fused"):
            k, v = run.metric(p, "ospa", which)
            assert list(k) == list(range(1, 13))
            assert v.mean() == pytest.approx(run.mean_ospa(p, which), rel=1e-12)
            g = run.metric(p, "gospa", which)[1]
            assert g.mean() == pytest.approx(run.summary(p)[f"mean_gospa_{which}"], rel=1e-12)
    pos = run.meta["position_index"]
    tracks, truth = run.tracks("s2"), run.truth()
    for k in (1, 6, 12):
        X, Y = tracks[k], truth[k]
        assert X.ndim == 2 and Y.shape[1] == 4
        expected = run.metric("s2", "ospa")[1][k - 1]
        assert ospa(X[:, pos], Y[:, pos], run.meta["cutoff"], run.meta["order"]) == \
            pytest.approx(expected)
    again = simulate(scn, run=3)
    np.testing.assert_array_equal(again.columns["ospa"], run.columns["ospa"])


def test_a_bad_key_is_the_loader_error():
    with pytest.raises(ScenarioError, match="unknown key"):
        scenario("seed000", {"scenario.nmu_scans": 3})


def test_the_example_notebook_runs(monkeypatch):
    """Execute the notebook's code cells in one namespace, in order, as a kernel would."""
    import matplotlib

    matplotlib.use("Agg")
    nb = json.loads((ROOT / "docs" / "notebooks" / "quickstart.ipynb").read_text())
    cells = ["".join(c["source"]) for c in nb["cells"] if c["cell_type"] == "code"]
    assert len(cells) >= 4
    ns: dict = {}
    for src in cells:
        exec(compile(src, "quickstart.ipynb", "exec"), ns)
    run = ns["run"]
    for p, (local, fused) in ns["summary_table"].items():
        assert local == run.mean_ospa(p, "local") and fused == run.mean_ospa(p, "fused")
    parts = ns["gospa_parts"]
    assert list(parts.index) == run.peers
    s1 = run.metric("s1", "gospa")[1].mean()
    assert parts.loc["s1", "gospa"] == pytest.approx(s1)
