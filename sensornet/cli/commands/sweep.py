"""``sweep``: a fault parameter x out-of-sequence policy over Monte Carlo runs."""

from __future__ import annotations

import argparse

from sensornet.cli.budgets import check_budget
from sensornet.cli.common import UserError, _run_folder
from sensornet.sim.campaign.sweep import format_summary, summarise, sweep, write_outputs
from sensornet.sim.scenario import load_scenario, parse_overrides


def cmd_sweep(args: argparse.Namespace) -> int:
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
