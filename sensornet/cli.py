"""The ``sensornet`` command line: experiments, scenarios, and (later) peers and the world."""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

from sim.scenario import (
    ScenarioError,
    builtin_scenarios,
    load_scenario,
    parse_overrides,
    scenario_text,
)


class UserError(Exception):
    """A mistake the user can fix (bad file, bad flag): reported in one line, exit code 2."""


def _run_folder(base: str | None, kind: str) -> Path:
    root = Path(base) if base else Path("runs") / f"{time.strftime('%Y%m%d-%H%M%S')}-{kind}"
    root.mkdir(parents=True, exist_ok=True)
    return root


def _default_jobs() -> int:
    return max(1, min(os.cpu_count() or 1, 4))


def cmd_experiment(args: argparse.Namespace) -> int:
    from sim.experiment import format_table, run_experiment, write_outputs
    from sim.scenario import with_birth_model

    scn = load_scenario(args.scenario, overrides=parse_overrides(args.set or []))
    if args.runs < 1:
        raise UserError(f"--runs must be at least 1, got {args.runs}")
    if args.fusion:
        from dataclasses import replace

        scn = replace(scn, fusion=replace(scn.fusion, rule=args.fusion))
    births = ["paper", "truth"] if args.birth == "both" else [args.birth or scn.birth.model]
    out = _run_folder(args.out, "experiment")
    for model in births:
        s = with_birth_model(scn, model)
        result = run_experiment(s, args.runs, jobs=args.jobs, progress=not args.quiet)
        print(format_table(result))
        print()
        for path in write_outputs(result, out):
            print(f"wrote {path}")
        print()
    return 0


def cmd_demo(args: argparse.Namespace) -> int:
    args.scenario = "seed000"
    args.birth = "both"
    args.fusion = None
    args.set = []
    return cmd_experiment(args)


def cmd_scenario(args: argparse.Namespace) -> int:
    if args.action == "list":
        for name in builtin_scenarios():
            print(name)
        return 0
    if args.name not in builtin_scenarios():
        raise UserError(f"unknown built-in scenario {args.name!r}; "
                        f"known: {', '.join(builtin_scenarios())}")
    sys.stdout.write(scenario_text(args.name))
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="sensornet",
        description="Peer-to-peer multi-sensor multi-target tracking (GM-PHD, GCI fusion).",
    )
    sub = p.add_subparsers(dest="command", required=True)

    def add_mc_flags(sp: argparse.ArgumentParser, runs: int) -> None:
        sp.add_argument("--runs", type=int, default=runs, help=f"Monte Carlo runs (default {runs})")
        sp.add_argument("--jobs", type=int, default=_default_jobs(),
                        help="worker processes (default: number of cores, at most 4)")
        sp.add_argument("--out", help="output folder (default: runs/<time>-experiment)")
        sp.add_argument("--quiet", action="store_true", help="no progress bar")

    e = sub.add_parser("experiment", help="offline Monte Carlo: local vs fused vs centralized")
    e.add_argument("scenario", nargs="?", default="seed000",
                   help="scenario file (.toml) or built-in name (default seed000)")
    e.add_argument("--birth", choices=["paper", "truth", "both"],
                   help="birth model (default: the scenario's)")
    e.add_argument("--fusion", choices=["gci", "aa", "none"], help="override the fusion rule")
    e.add_argument("--set", action="append", metavar="KEY=VALUE",
                   help="override a scenario value, e.g. --set fusion.level2_pruning=false "
                        "or --set sensors.s1.clutter_rate=50 (repeatable)")
    add_mc_flags(e, 50)
    e.set_defaults(func=cmd_experiment)

    d = sub.add_parser("demo", help="the seed-000 experiment with both birth models")
    add_mc_flags(d, 20)
    d.set_defaults(func=cmd_demo)

    s = sub.add_parser("scenario", help="list or print built-in scenario files")
    s.add_argument("action", choices=["list", "show"])
    s.add_argument("name", nargs="?", default="seed000")
    s.set_defaults(func=cmd_scenario)
    return p


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except (ScenarioError, UserError) as exc:
        print(f"sensornet: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("sensornet: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
