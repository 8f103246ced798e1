"""``experiment``, ``sweep``, ``campaign`` and ``report``: studies called with Python values."""

from __future__ import annotations

import argparse
import os
import signal
import sys
from pathlib import Path

from sensornet.cli.budgets import check_budget
from sensornet.cli.common import UserError, _run_folder
from sim.scenario import (
    load_scenario,
    parse_overrides,
)

# --------------------------------------------------------------------------------------------
# Commands
# --------------------------------------------------------------------------------------------


def _warn_fusion(scn) -> None:
    """One line per fusion setting the fusion-quality study measured to hurt."""
    from sim.fusion_advice import fusion_warnings

    for line in fusion_warnings(scn):
        print(f"warning: {line}", file=sys.stderr, flush=True)


def cmd_experiment(args: argparse.Namespace) -> int:
    """``sensornet experiment SCENARIO``: the study that reads the scenario (:mod:`sim.studies`),
    called with the flags' values."""
    from dataclasses import replace

    from sim import studies
    from sim.studies.base import Request, experiment

    overrides = parse_overrides(args.set or [])
    study = studies.for_source(args.scenario, overrides)
    req = Request(args.scenario, overrides, runs=args.runs, jobs=args.jobs,
                  progress=not args.quiet, options={"fusion": args.fusion, "birth": args.birth})
    setups = study.load(req)
    if study.scenario:
        _warn_fusion(setups[0])
        for scn in setups:
            check_budget(scn, args, workers=min(args.jobs, args.runs))
    experiment(study, replace(req, out=_run_folder(args.out, "experiment")), setups)
    return 0


def cmd_sweep(args: argparse.Namespace) -> int:
    from sim.sweep import format_summary, summarise, sweep, write_outputs

    values = list(parse_overrides([f"v={v}" for v in args.values.split(";")]).values()) \
        if ";" in args.values else [parse_overrides([f"v={v}"])["v"]
                                    for v in args.values.split(",")]
    policies = [p for p in args.policies.split(",") if p]
    bad = [p for p in policies if p not in ("nale", "drop-late", "as-is")]
    if bad:
        raise UserError(f"unknown policies {bad}; use nale, drop-late, as-is")
    base = parse_overrides(args.set or [])
    scn = load_scenario(args.scenario, overrides=base)
    if args.real:
        check_budget(scn, args, processes=len(scn.sensors) + 1, wire=True)
    else:
        check_budget(scn, args, workers=args.jobs)
    rows = sweep(args.scenario, args.param, values, policies, args.runs, base=base,
                 real=args.real, jobs=args.jobs, progress=not args.quiet)
    print(format_summary(args.param, summarise(rows)))
    for path in write_outputs(rows, args.param, _run_folder(args.out, "sweep")):
        print(f"wrote {path}")
    return 0


def cmd_campaign(args: argparse.Namespace) -> int:
    from sim.campaign import (
        default_folder,
        format_status,
        load_campaign,
        recorded_runs,
        run_campaign,
        status,
    )

    c = load_campaign(args.file, runs=args.runs)
    folder = Path(args.out) if args.out else default_folder(c)
    if args.status:  # against the plan the folder records (its last run's), not --runs
        planned = recorded_runs(folder)
        if planned is not None and planned != c.runs:
            c = load_campaign(args.file, runs=planned)
        print(format_status(c, folder, status(c, folder)))
        if args.runs is not None and args.runs != c.runs:
            print(f"(--runs {args.runs} not counted: the folder's plan is {c.runs} runs per "
                  f"cell; running with --runs {args.runs} makes it the plan)")
        return 0
    if args.dask and args.scheduler:
        raise UserError("--dask local and --scheduler: give one of them")
    dask = "local" if args.dask else args.scheduler
    jobs = args.jobs or (1 if c.runner == "real" and dask is None else os.cpu_count() or 1)

    def interrupt(signum, frame) -> None:  # SIGTERM as Ctrl-C: cancel, keep what finished
        raise KeyboardInterrupt

    old = signal.signal(signal.SIGTERM, interrupt)
    try:
        summary = run_campaign(c, folder, jobs=jobs, dask=dask, progress=not args.quiet,
                               stop_after=args.stop_after)
    except (ImportError, ConnectionError) as exc:
        raise UserError(str(exc)) from None
    finally:
        signal.signal(signal.SIGTERM, old)
    print(format_status(c, folder, status(c, folder)))
    rate = summary.ran / summary.seconds if summary.seconds > 0 else 0.0
    print(f"ran {summary.ran} runs in {summary.seconds:.1f} s ({rate:.2f} runs/s, "
          f"{summary.cpu_seconds / max(summary.ran, 1):.2f} CPU s per run, "
          f"{summary.cpu_seconds / max(summary.seconds, 1e-9):.2f} cores busy), "
          f"{summary.skipped} already stored")
    if summary.stopped:
        print(f"stopped after {summary.ran} runs: run the same command again to finish")
        return 1
    print(f"report: sensornet report {folder}")
    return 0


def cmd_report(args: argparse.Namespace) -> int:
    from sim.report import write_report

    try:
        written = write_report(args.dir, args.out, html=args.html)
    except ImportError as exc:
        raise UserError(str(exc)) from None
    for path in written:
        print(f"wrote {path}")
    return 0
