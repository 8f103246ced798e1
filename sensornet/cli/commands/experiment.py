"""``experiment``: the study that reads the scenario (:mod:`sim.studies`), called with the
flags' values."""

from __future__ import annotations

import argparse
from dataclasses import replace

from sensornet.cli.budgets import check_budget
from sensornet.cli.common import _run_folder
from sensornet.cli.scenarios import warn_fusion
from sensornet.sim import studies
from sensornet.sim.scenario import parse_overrides
from sensornet.sim.studies.base import Request, experiment


def cmd_experiment(args: argparse.Namespace) -> int:
    """``sensornet experiment SCENARIO``: the study that reads the scenario (:mod:`sim.studies`),
    called with the flags' values."""
    overrides = parse_overrides(args.set or [])
    study = studies.for_source(args.scenario, overrides)
    req = Request(args.scenario, overrides, runs=args.runs, jobs=args.jobs,
                  progress=not args.quiet, options={"fusion": args.fusion, "birth": args.birth})
    setups = study.load(req)
    if study.scenario:
        warn_fusion(setups[0])
        for scn in setups:
            check_budget(scn, args, workers=min(args.jobs, args.runs))
    experiment(study, replace(req, out=_run_folder(args.out, "experiment")), setups)
    return 0
