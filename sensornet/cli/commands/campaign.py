"""``campaign``: cells x Monte Carlo runs of a campaign file (resumable; a local pool or Dask)."""

from __future__ import annotations

import argparse
import os
import signal
from pathlib import Path

from sensornet.cli.common import UserError
from sensornet.sim.campaign import (
    default_folder,
    format_status,
    load_campaign,
    recorded_runs,
    run_campaign,
    status,
)


def cmd_campaign(args: argparse.Namespace) -> int:
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
