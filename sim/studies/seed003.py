"""Seed 003's reproduction as a study: PDAF, IMM-PDAF, fuzzy PDA and fuzzy IMM, one and two
sensors, on the manoeuvring target (:mod:`sim.seed003`); ``sensornet experiment seed003`` (or a
file named ``seed003.toml``: its settings)."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from sim import seed003 as s3
from sim.scenario import ScenarioError
from sim.studies.base import Outcome, Request, Study


def claims(source: str, overrides: Mapping[str, Any]) -> bool:
    """The shipped ``seed003`` or a file of that name (the network scenario reads the same
    file: :mod:`sim.seed003_net`)."""
    return source == "seed003" or Path(source).name == "seed003.toml"


def load(req: Request) -> list[dict]:
    path = s3.SCENARIO if req.source == "seed003" else Path(req.source).resolve()
    try:
        return [s3.load(path, dict(req.overrides))]
    except (ValueError, OSError) as exc:
        raise ScenarioError(str(exc)) from None


def run_once(cfg: dict, run: int) -> s3.RunResult:
    return s3.run_once(cfg, run)


def table(o: Outcome) -> str:
    m = o.setup["metrics"]
    return (s3.format_table(o.summary) + "\n"
            f"({len(o.runs)} runs from {o.runs.start}, {o.seconds:.0f} s; lost: error > "
            f"{m['loss_bound']:g} m for {m['loss_scans']} scans; RMSE over kept tracks; "
            "detector rates per scan)")


def figures(o: Outcome, folder: Path) -> list[Path]:
    over_time = s3.rmse_over_time(o.results)
    return [*s3.write_csv(o.summary, over_time, folder),
            s3.plot_rmse(over_time, o.setup, folder / "seed003_rmse.png")]


STUDY = Study(
    name="seed003",
    about="seed 003: PDAF / IMM-PDAF / fuzzy PDA / fuzzy IMM, one and two sensors",
    load=load, run_once=run_once, summarise=s3.summarise, table=table, figures=figures,
    claims=claims)
