"""Seed 004's reproduction as a study: flooding with IDPC / FTC clustering against distributed
GM-PHD filters with GCI and AA consensus, IC, centralised and local (:mod:`sim.seed004`);
``sensornet experiment seed004`` (or a file named ``seed004.toml``)."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from sim import seed004 as s4
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
    return s4.run_once(scn, run, True)


def table(o: Outcome) -> str:
    return "\n".join([s4.table_title(o.setup, o.runs), s4.format_table(o.summary),
                      s4.reference_comparison(o.summary, o.setup.adjacency),
                      f"({o.seconds:.0f} s)"])


def figures(o: Outcome, folder: Path) -> list[Path]:
    return s4.write_outputs(o.summary, folder, s4.table_title(o.setup, o.runs))


STUDY = Study(
    name="seed004",
    about="seed 004: flooding + IDPC/FTC against GCI/AA consensus, IC, centralised, local",
    load=load, run_once=run_once, summarise=lambda scn, per_run: s4.aggregate(per_run),
    table=table, figures=figures, claims=claims)
