"""Seed 004's reproduction as a study: flooding with IDPC / FTC clustering against distributed
GM-PHD filters with GCI and AA consensus, IC, centralised and local (:mod:`sim.seed004`);
``sensornet experiment seed004`` (or a file named ``seed004.toml``)."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from sim import seed004_output as out
from sim import seed004_scenario as s4
from sim.scenario import ScenarioError
from sim.studies.base import Outcome, Request, Study


def claims(source: str, overrides: Mapping[str, Any]) -> bool:
    return source == "seed004" or Path(source).name == "seed004.toml"


def load(req: Request) -> list[s4.Seed004]:
    path = s4.SCENARIO if req.source == "seed004" else Path(req.source)
    try:
        return [s4.load(path, dict(req.overrides))]
    except OSError as exc:
        raise ScenarioError(f"seed004: {path}: {exc.strerror or exc}") from None
    except s4.ScenarioError as exc:  # seed 004's own format: its errors are one line too
        raise ScenarioError(f"seed004: {exc}") from None


def run_once(scn: s4.Seed004, run: int) -> dict[str, dict[str, float]]:
    # heavy optional dependency: sklearn (sim.seed004 imports it for FTC's DBSCAN, 1-3 s: not
    # for every 'experiment' that asks this study whether it reads a scenario)
    from sim import seed004

    return seed004.run_once(scn, run, True)


def summarise(scn: s4.Seed004, per_run: list) -> dict[str, dict[str, float]]:
    from sim import seed004  # heavy optional dependency: sklearn, as above

    return seed004.aggregate(per_run)


def table(o: Outcome) -> str:
    return out.report_text(o.setup, o.runs, o.summary, o.seconds)


def figures(o: Outcome, folder: Path) -> list[Path]:
    return out.write_outputs(o.summary, folder, out.table_title(o.setup, o.runs))


STUDY = Study(
    name="seed004",
    about="seed 004: flooding + IDPC/FTC against GCI/AA consensus, IC, centralised, local",
    load=load, run_once=run_once, summarise=summarise,
    table=table, figures=figures, claims=claims)
