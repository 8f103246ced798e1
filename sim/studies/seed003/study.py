"""Seed 003's reproduction as a study: PDAF, IMM-PDAF, fuzzy PDA and fuzzy IMM, one and two
sensors, on the manoeuvring target (:mod:`sim.studies.seed003.montecarlo`); ``sensornet experiment
seed003`` (or a
file named ``seed003.toml``: its settings), and ``python -m
sensornet.sim.studies.seed003.montecarlo`` (:func:`main`:
the
same path, with the choice of methods, a trained ``[fuzzy]`` table and the training)."""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from sensornet.sim.scenario import ScenarioError, parse_overrides
from sensornet.sim.studies import command
from sensornet.sim.studies.base import Outcome, Request, Study
from sensornet.sim.studies.seed003 import montecarlo as s3


@dataclass(frozen=True)
class Setup:
    """The resolved settings and the methods a run computes."""

    cfg: dict
    methods: tuple[str, ...] = s3.METHODS


def claims(source: str, overrides: Mapping[str, Any]) -> bool:
    """The shipped ``seed003`` or a file of that name (the network scenario reads the same
    file: :mod:`sim.studies.seed003.network`)."""
    return source == "seed003" or Path(source).name == "seed003.toml"


def load(req: Request) -> list[Setup]:
    """The file's settings with the overrides; options ``methods`` (a subset of
    :data:`sim.studies.seed003.montecarlo.METHODS`) and ``fuzzy`` (a ``[fuzzy]`` table as JSON,
    e.g. a
    ``--train-fuzzy`` result, its ``mode`` kept unless overridden)."""
    path = s3.SCENARIO if req.source == "seed003" else Path(req.source).resolve()
    try:
        cfg = s3.load(path, dict(req.overrides))
        if req.options.get("fuzzy"):
            mode = cfg["fuzzy"].get("mode")
            cfg["fuzzy"] = json.loads(Path(req.options["fuzzy"]).read_text(encoding="utf-8"))
            cfg["fuzzy"]["mode"] = req.overrides.get("fuzzy.mode", mode)
    except (ValueError, OSError) as exc:
        raise ScenarioError(str(exc)) from None
    methods = tuple(req.options.get("methods") or s3.METHODS)
    if unknown := [m for m in methods if m not in s3.METHODS]:
        raise ScenarioError(f"methods: unknown {unknown}; expected some of "
                            f"{', '.join(s3.METHODS)}")
    return [Setup(cfg, methods)]


def run_once(s: Setup, run: int) -> s3.RunResult:
    return s3.run_once(s.cfg, run, s.methods)


def summarise(s: Setup, results: list[s3.RunResult]) -> list[dict]:
    return s3.summarise(s.cfg, results)


def table(o: Outcome) -> str:
    return s3.format_table(o.summary) + "\n" + s3.footer(o.setup.cfg, o.runs, o.seconds)


def figures(o: Outcome, folder: Path) -> list[Path]:
    over_time = s3.rmse_over_time(o.results)
    return [*s3.write_csv(o.summary, over_time, folder),
            s3.plot_rmse(over_time, o.setup.cfg, folder / "seed003_rmse.png")]


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m sensornet.sim.studies.seed003.montecarlo``: the study's table (``--csv DIR``:
    its CSVs and figure),
    or
    ``--train-fuzzy N``: the fitted ``[fuzzy]`` table as JSON."""
    p = command.parser("seed003", s3.__doc__, runs=200,
                       set_help="override a scenario setting (TOML value), e.g. "
                                "clutter.in_gate=1")
    p.add_argument("--methods", default=",".join(s3.METHODS),
                   help=f"comma-separated subset of {', '.join(s3.METHODS)}")
    p.add_argument("--csv", type=Path,
                   help="write the table and RMSE-over-time CSVs and the RMSE PNG here")
    p.add_argument("--scenario", type=Path, default=s3.SCENARIO,
                   help="scenario file (default sim/scenarios/seed003.toml)")
    p.add_argument("--train-fuzzy", type=int, metavar="N", default=0,
                   help="fit the fuzzy system on training runs 10000..10000+N-1, print the "
                        "fitted [fuzzy] table as JSON and exit")
    p.add_argument("--fuzzy", type=Path, metavar="JSON",
                   help="use this [fuzzy] table (e.g. a --train-fuzzy result) instead of the "
                        "scenario's")
    a = p.parse_args(argv)
    try:
        req = command.request(a, a.scenario, parse_overrides(a.set), a.csv, fuzzy=a.fuzzy,
                              methods=[m.strip() for m in a.methods.split(",")])
        if a.train_fuzzy:
            print(json.dumps(s3.train_fuzzy(load(req)[0].cfg, a.train_fuzzy), indent=1))
            return 0
    except ScenarioError as exc:
        return command.fail("seed003", exc)
    return command.drive(STUDY, req)


STUDY = Study(
    name="seed003",
    about="seed 003: PDAF / IMM-PDAF / fuzzy PDA / fuzzy IMM, one and two sensors",
    load=load, run_once=run_once, summarise=summarise, table=table, figures=figures,
    claims=claims, command=main)
