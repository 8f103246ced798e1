"""A small slice of the fusion-quality study, end to end: the study file expands into cells on
several networks, runs resumably through the campaign machinery, and its table and figures
carry the numbers the twin and the offline experiment compute for the same cells."""

from __future__ import annotations

import json

import numpy as np
import pytest
from sensornet.sim.campaign import CampaignError, load_campaign, run_campaign, status
from sensornet.sim.run.twin import run_twin
from sensornet.sim.scenario import load_scenario
from sensornet.sim.studies.base import Cell
from sensornet.sim.studies.fusion.quality import format_markdown, interval, plot, summarise
from sensornet.sim.studies.seed000.study import row as experiment_row
from sensornet.sim.world.graphs import network_scenario

STUDY = """
[campaign]
name = "slice"
runs = 2

[study]
kind = "fusion-quality"
rounds = [1, 2]
graphs = [
    { name = "full-3", scenario = "seed000", set = { "scenario.num_scans" = 8 } },
    { name = "ring-6", scenario = "circulant:6:2", set = { "scenario.num_scans" = 8 }, runs = 1 },
]
rules = [
    { name = "hybrid", set = { "fusion.rule" = "hybrid" } },
    { name = "gci", set = { "fusion.rule" = "gci" }, rounds = [1] },
    { name = "aa", set = { "fusion.rule" = "aa" }, max_peers = 3 },
]
conditions = [
    { pd = 0.99, clutter = 10 },
    { pd = 0.9, clutter = 10, graphs = ["ring-6"], rules = ["hybrid"] },
]
"""


@pytest.fixture
def study(tmp_path):
    path = tmp_path / "slice.toml"
    path.write_text(STUDY)
    return path


def test_the_study_expands_into_cells_per_graph_rule_and_round(study):
    c = load_campaign(study)
    labels = [cell.values for cell in c.cells]
    # full-3: hybrid L=1,2, gci L=1, aa L=1,2, none, centralised; ring-6: no aa, and at Pd
    # 0.9 the hybrid only (and the references)
    assert len(c.cells) == 7 + 5 + 4
    assert {(v["graph"], v["rule"]) for v in labels if v["rule"] == "aa"} == {("full-3", "aa")}
    assert [v["rounds"] for v in labels if v["graph"] == "full-3" and v["rule"] == "hybrid"] \
        == [1, 2]
    central = [cell for cell in c.cells if cell.values["rule"] == "centralised"]
    assert all(cell.runner == "experiment" for cell in central)
    assert [len(cell.keys) for cell in c.cells if cell.values["graph"] == "ring-6"] == [1] * 9
    pd9 = [cell for cell in c.cells if cell.values["pd"] == 0.9]
    assert {cell.values["rule"] for cell in pd9} == {"hybrid", "none", "centralised"}
    assert pd9 and all(cell.overrides["sensors.*.detection_probability"] == 0.9 for cell in pd9)
    keys = [k for cell in c.cells for k in cell.keys]
    assert len(set(keys)) == len(keys)  # no-fusion and centralised share a scenario, not keys


def test_study_rows_are_the_twin_and_experiment_numbers(study, tmp_path):
    c = load_campaign(study)
    folder = tmp_path / "out"
    first = run_campaign(c, folder, jobs=1, progress=False, stop_after=4)
    assert first.stopped and first.ran == 4
    rest = run_campaign(load_campaign(study), folder, jobs=1, progress=False)
    assert rest.skipped == 4 and not rest.stopped
    st = status(c, folder)
    assert st.done == st.total == sum(len(cell.keys) for cell in c.cells)
    rows = summarise(folder)
    assert len(rows) == len(c.cells)
    # one cell recomputed by hand: full-3, hybrid, L=2, runs 0 and 1
    row = next(r for r in rows if r["graph"] == "full-3" and r["rule"] == "hybrid"
               and r["rounds"] == 2)
    scn = load_scenario("seed000", overrides={"scenario.num_scans": 8, "network.rounds": 2,
                                              "fusion.rule": "hybrid",
                                              "sensors.*.detection_probability": 0.99,
                                              "sensors.*.clutter_rate": 10.0})
    per_run = [np.mean([p.mean_ospa("fused") for p in run_twin(scn, r).peers.values()])
               for r in (0, 1)]
    mean, half = interval(np.array(per_run))
    assert row["runs"] == 2 and row["fused_ospa"] == pytest.approx(mean)
    assert row["fused_ospa_ci"] == pytest.approx(half) and half > 0
    # the centralised reference is the experiment's iterated corrector
    cen = next(r for r in rows if r["graph"] == "full-3" and r["rule"] == "centralised")
    central = load_scenario("seed000", overrides=scn_overrides(c, "full-3", "centralised"))
    ref = [experiment_row(central, Cell(r, "", None, {}))["mean_ospa.centralized"]
           for r in (0, 1)]
    assert cen["fused_ospa"] == pytest.approx(np.mean(ref))
    table = format_markdown(rows)
    assert table.count("\n") == 2 + len({(r["pd"], r["graph"], r["rule"]) for r in rows})
    assert f"{mean:.1f} ± {half:.1f}" in table
    figures = plot(rows, tmp_path / "img")
    assert [p.name for p in figures] == ["fusion-study-rounds.png", "fusion-study-cost.png"]
    assert all(p.stat().st_size > 10_000 for p in figures)
    manifest = json.loads((folder / "manifest.json").read_text())
    assert {cell.get("runner") for cell in manifest["cells"]} == {"twin", "experiment"}


def scn_overrides(c, graph: str, rule: str) -> dict:
    return next(cell.overrides for cell in c.cells
                if cell.values["graph"] == graph and cell.values["rule"] == rule)


def test_interval_is_the_student_t_half_width():
    from scipy.stats import t

    x = np.array([10.0, 12.0, 11.0, 15.0])
    mean, half = interval(x)
    assert mean == pytest.approx(12.0)
    assert half == pytest.approx(t.ppf(0.975, 3) * x.std(ddof=1) / 2.0)
    assert np.isnan(interval(np.array([3.0]))[1])


@pytest.mark.parametrize("edit, problem", [
    (('kind = "fusion-quality"', 'kind = "other"'), "study.kind must be"),
    (('rounds = [1, 2]\n', 'rounds = [0]\n'), "study.rounds must be"),
    (('"circulant:6:2"', '"circulant:6"'), "expected circulant:N:D"),
    (('graphs = ["ring-6"]', 'graphs = ["ring-7"]'), "unknown graph 'ring-7'"),
    (('rules = ["hybrid"] }', 'rules = ["nope"] }'), "unknown rule"),
    (('"fusion.rule" = "aa"', '"fusion.rule" = "bogus"'), "rule 'aa'"),
])
def test_a_bad_study_file_is_one_line(tmp_path, edit, problem):
    path = tmp_path / "bad.toml"
    path.write_text(STUDY.replace(*edit))
    with pytest.raises(CampaignError, match=problem) as err:
        load_campaign(path)
    assert "\n" not in str(err.value)


def test_generated_graph_scenarios_load(tmp_path):
    (tmp_path / "g.toml").write_text(network_scenario(12, 3))
    scn = load_scenario(str(tmp_path / "g.toml"))
    assert len(scn.sensors) == 12 and scn.fusion.rule == "hybrid"
    assert len(scn.network.edges) == 12 * 3 // 2
