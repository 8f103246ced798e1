"""The ``sensornet`` command line: experiments, scenarios, peers, the world and whole runs.

``main`` here; the parser in :mod:`sensornet.cli.parser`, each command group in its module.

Every flag either does what it says or is refused: a bad value, a scenario over a budget or a
file that does not load is one line on stderr and exit code 2 (:class:`UserError`); a run that
ends with nothing scored is one line and exit code 1.
"""

from __future__ import annotations

import os
import sys

from peers.session import SessionError
from sensornet.cli.budgets import memory_estimate_gb, points_per_scan, targets_at_once
from sensornet.cli.common import (
    _CREATED,
    UserError,
    _remove_empty_run_folders,
    _run_folder,
    viewer_reachable,
)
from sensornet.cli.parser import build_parser
from sensornet.cli.peer import _prepare_peer
from sim.scenario import ScenarioError
from tracking.idpc import MissingBaseline

__all__ = ["UserError", "_CREATED", "_prepare_peer", "_run_folder", "build_parser", "main",
           "memory_estimate_gb", "points_per_scan", "targets_at_once", "viewer_reachable"]
"""Also what tests and callers import from ``sensornet.cli`` (the commands live in its
modules: common, budgets, studies, peer, run, admin, parser)."""


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    code = 1
    try:
        code = int(args.func(args) or 0)
        return code
    except (ScenarioError, UserError, SessionError, MissingBaseline) as exc:
        code = 2
        print(f"sensornet: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        code = 130
        print("sensornet: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # e.g. `sensornet experiment | head`: the reader left; be quiet
        code = 141
        try:
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, sys.stdout.fileno())
        except OSError:
            pass
        return 141
    finally:
        if code != 0:
            _remove_empty_run_folders()
        _CREATED.clear()


if __name__ == "__main__":
    sys.exit(main())
