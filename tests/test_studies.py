"""The Study contract: a small study registered from here runs through ``sensornet experiment``
and a campaign (and its report) by the same hooks the seed studies use, over the one pool loop
with one progress line; the registry finds each seed's study by the scenario it reads."""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from sensornet.sim import studies
from sensornet.sim.campaign import load_campaign, results_table, run_campaign
from sensornet.sim.campaign.report import write_report
from sensornet.sim.run.pool import iter_pool, map_runs
from sensornet.sim.studies.base import Cell, Outcome, Request, Study, run_study

from sensornet.cli import main

NAME = "toy-study"


@dataclass(frozen=True)
class Toy:
    scale: float


def toy_once(setup: Toy, run: int) -> float:
    """One seeded run (module level: it is sent to the pool's workers)."""
    return float(setup.scale * np.random.default_rng([7, run]).standard_normal())


def toy_load(req: Request) -> list[Toy]:
    return [Toy(float(req.overrides.get("scale", 1.0)))]


def toy_figures(o: Outcome, folder: Path) -> list[Path]:
    path = folder / "toy.csv"
    path.write_text("\n".join(f"{r:.6f}" for r in o.results) + "\n")
    return [path]


def toy_row(setup: Toy, cell: Cell) -> dict:
    return {"value": toy_once(setup, cell.run)}


def toy_report(cell: dict, data: dict, out: Path) -> tuple[list[str], list[Path]]:
    return [f"toy cell {cell['index']}: {len(data['value'])} values", ""], []


TOY = Study(
    name=NAME, about="a seeded normal draw per run, scaled",
    load=toy_load, run_once=toy_once,
    summarise=lambda setup, results: float(np.mean(results)),
    table=lambda o: f"toy mean {o.summary:.6f} over {len(o.runs)} runs",
    figures=toy_figures, claims=lambda source, overrides: source == NAME,
    label=lambda setup: "toy runs",
    row=toy_row, cell_setup=lambda source, overrides: Toy(float(overrides.get("scale", 1.0))),
    setup_hash=lambda s: hashlib.sha256(repr(s).encode()).hexdigest()[:16],
    fixed_scenario="toy", report=toy_report)


@pytest.fixture
def toy():
    studies.register(TOY)
    try:
        yield TOY
    finally:
        studies.unregister(NAME)


def expected(scale: float, runs: range) -> list[float]:
    return [toy_once(Toy(scale), r) for r in runs]


def _progress_lines(err: str) -> list[str]:
    return [ln for ln in err.splitlines() if ln.startswith("[")]


@pytest.mark.network  # starts worker processes
def test_pool_gives_results_in_call_order_whatever_the_workers():
    calls = [(Toy(2.0), r) for r in range(9)]
    serial = map_runs(toy_once, calls, jobs=1, progress=False)
    assert serial == expected(2.0, range(9))
    assert map_runs(toy_once, calls, jobs=2, progress=False) == serial
    got = dict(iter_pool(toy_once, calls, jobs=2))
    assert [got[i] for i in range(9)] == serial
    rows = iter_pool(toy_once, calls, jobs=2)  # closing early cancels the rest, no hang
    next(rows)
    rows.close()


def test_registry_finds_each_seeds_study_by_what_it_reads():
    assert studies.for_source("seed004").name == "seed004"
    assert studies.for_source("some/dir/seed003.toml").name == "seed003"
    assert studies.for_source("seed002").name == "seed002"  # an [extended] table
    assert studies.for_source("seed000").name == "experiment"
    assert studies.for_source("seed001").name == "experiment"  # the one model's experiment
    assert {"experiment", "twin", "real", "seed001"} <= set(studies.runners())
    assert {"seed000", "seed001"} <= set(studies.report_kinds())
    with pytest.raises(KeyError, match="unknown study 'nope'"):
        studies.get("nope")


@pytest.mark.network  # starts worker processes
def test_a_registered_study_runs_through_experiment(toy, tmp_path, capsys):
    rc = main(["experiment", NAME, "--runs", "5", "--jobs", "2", "--set", "scale=3",
               "--out", str(tmp_path / "out")])
    assert rc == 0
    cap = capsys.readouterr()
    want = expected(3.0, range(5))
    assert f"toy mean {np.mean(want):.6f} over 5 runs" in cap.out
    assert f"wrote {tmp_path / 'out' / 'toy.csv'}" in cap.out
    values = [float(x) for x in (tmp_path / "out" / "toy.csv").read_text().split()]
    assert values == pytest.approx(want, abs=1e-6)
    bars = _progress_lines(cap.err)
    assert bars and all("toy runs" in b for b in bars)  # one progress line, the study's label
    assert bars[-1].split()[1] == "5/5"
    outcome = run_study(TOY, Toy(3.0), range(5), jobs=1, progress=False)
    assert outcome.results == want and outcome.runs == range(5)


@pytest.mark.network  # starts worker processes
def test_a_registered_study_runs_as_a_campaign_and_reports(toy, tmp_path, capsys):
    pytest.importorskip("pyarrow", reason="campaign results need pyarrow")
    path = tmp_path / "toy.toml"
    path.write_text(f"""
[campaign]
name = "toy"
scenario = "toy"
runner = "{NAME}"
runs = 3

[grid]
scale = [1.0, 2.0]

[[figures]]
kind = "{NAME}"
""")
    c = load_campaign(path)
    folder = tmp_path / "campaign"
    summary = run_campaign(c, folder, jobs=2, progress=True)
    assert summary.ran == 6
    err = capsys.readouterr().err
    bars = _progress_lines(err)
    assert bars and bars[-1].split()[1] == "6/6"
    table = results_table(folder)
    rows = sorted(zip(table.column("cell").to_pylist(), table.column("run").to_pylist(),
                      table.column("value").to_pylist(), strict=True))
    assert [v for _, _, v in rows] == expected(1.0, range(3)) + expected(2.0, range(3))
    assert run_campaign(c, folder, jobs=2, progress=False).skipped == 6  # stored: not rerun
    written = write_report(folder)
    report = next(p for p in written if p.name == "report.md").read_text()
    assert "toy cell 0: 3 values" in report and "toy cell 1: 3 values" in report


def test_an_unknown_runner_or_figure_kind_names_the_studies(toy, tmp_path):
    from sensornet.sim.campaign import CampaignError

    path = tmp_path / "bad.toml"
    path.write_text('[campaign]\nrunner = "nope"\n')
    with pytest.raises(CampaignError, match=f"campaign.runner must be one of .*{NAME}"):
        load_campaign(path)
    path.write_text(f'[campaign]\nrunner = "{NAME}"\nscenario = "toy"\n'
                    '[[figures]]\nkind = "nope"\n')
    with pytest.raises(CampaignError, match=f"kind = one of .*{NAME}"):
        load_campaign(path)


def test_a_plugin_study_is_found_through_the_environment(monkeypatch):
    """Campaign workers find a plug-in study by ``SENSORNET_STUDIES=name=module:attribute``."""
    assert NAME not in studies.names()
    monkeypatch.setenv(studies.PLUGINS_ENV, f"{NAME}={__name__}:TOY")
    try:
        assert NAME in studies.names() and studies.get(NAME) is TOY
        assert studies.for_source(NAME).name == NAME
    finally:
        studies.unregister(NAME)
    monkeypatch.setenv(studies.PLUGINS_ENV, "broken")
    with pytest.raises(ValueError, match="is not 'name=module:attribute'"):
        studies.names()
