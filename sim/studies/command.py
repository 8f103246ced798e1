"""``python -m sensornet.sim.studies.seedNNN.montecarlo``: a study's own command line, a thin
wrapper over the Study path.

The flags every study's command line shares are made here; each study module adds its own and
turns them into a :class:`~sim.studies.base.Request` (its extra choices in ``options``), and
:func:`drive` runs it with the same :func:`~sim.studies.base.experiment` that ``sensornet
experiment`` calls: one loader, one pool loop, one table. A mistake is one line on stderr,
prefixed with the study's name, and exit code 2.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from pathlib import Path

from sensornet.sim.scenario import ScenarioError
from sensornet.sim.studies.base import Outcome, Request, Study, experiment
from sensornet.tracking.idpc import MissingBaseline


def parser(name: str, doc: str | None, runs: int, jobs: bool = True,
           set_help: str | None = "override a scenario value (TOML value), e.g. "
                                  "fusion.rule=aa (repeatable)",
           module: str | None = None) -> argparse.ArgumentParser:
    """``--runs``, ``--first-run``, ``--jobs`` (unless the study times its methods in one
    process), ``--set`` (unless ``set_help`` is None: no scenario file) and ``--quiet``; the
    usage names ``module`` (default ``sensornet.sim.studies.NAME.montecarlo``)."""
    module = module or f"sensornet.sim.studies.{name}.montecarlo"
    ap = argparse.ArgumentParser(prog=f"python -m {module}",
                                 description=(doc or "").split("\n")[0])
    ap.add_argument("--runs", type=int, default=runs, help=f"Monte Carlo runs (default {runs})")
    ap.add_argument("--first-run", type=int, default=0, help="index of the first run")
    if jobs:
        ap.add_argument("--jobs", type=int, default=1, help="worker processes (default 1)")
    if set_help is not None:
        ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                        help=set_help)
    ap.add_argument("--quiet", action="store_true", help="no progress bar")
    return ap


def request(a: argparse.Namespace, source: str | Path, overrides: dict,
            out: Path | None = None, **options) -> Request:
    """The request of parsed flags ``a`` (what :func:`parser` made) for ``source``."""
    return Request(str(source), overrides, runs=a.runs, jobs=getattr(a, "jobs", 1),
                   first_run=a.first_run, out=out, progress=not a.quiet, options=options)


def fail(name: str, exc: BaseException) -> int:
    """One line on stderr (``NAME: message``), exit code 2."""
    text = str(exc)
    print(text if text.startswith(f"{name}:") else f"{name}: {text}", file=sys.stderr)
    return 2


def drive(study: Study, req: Request, after: Callable[[list[Outcome]], None] | None = None
          ) -> int:
    """Load, run, print the table (and the files written to ``req.out``), as ``sensornet
    experiment`` does; ``after`` gets the outcomes (a command line's own extra files)."""
    if req.runs < 1 or req.first_run < 0 or req.jobs < 1:
        return fail(study.name, ValueError("--runs and --jobs must be at least 1, "
                                           "--first-run at least 0"))
    try:
        outcomes = experiment(study, req)
    except (ScenarioError, MissingBaseline, ValueError, OSError) as exc:
        return fail(study.name, exc)
    if after is not None:
        after(outcomes)
    return 0
