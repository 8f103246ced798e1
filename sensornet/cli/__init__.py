"""The ``sensornet`` command line: experiments, scenarios, peers, the world and whole runs.

``main`` here; the parser and the table of commands in :mod:`sensornet.cli.parser`, each
command in its module under :mod:`sensornet.cli.commands`, imported only when it runs (so the
help and a mistyped flag answer quickly, and every import in a command module is at its top).

Every flag either does what it says or is refused: a bad value, a scenario over a budget or a
file that does not load is one line on stderr and exit code 2 (:class:`UserError`); a run that
ends with nothing scored is one line and exit code 1.
"""

from __future__ import annotations

import importlib
import os
import sys

from sensornet.cli.common import _CREATED, UserError, _remove_empty_run_folders
from sensornet.cli.parser import COMMANDS, build_parser
from sensornet.peers.errors import SessionError

__all__ = ["COMMANDS", "UserError", "build_parser", "command", "main"]

USER_ERRORS: tuple[tuple[str, str], ...] = (
    ("sensornet.sim.scenario.model", "ScenarioError"),
    ("sensornet.tracking.idpc", "MissingBaseline"),
)
"""Errors of modules a command may load that are the user's to fix (one line, exit code 2),
besides :class:`UserError` and :class:`SessionError`. Named, not imported: an error of a
module the command never loaded cannot have been raised."""


def command(name: str):
    """The function that runs command ``name`` (its module imported now)."""
    module, _, func = COMMANDS[name].partition(":")
    return getattr(importlib.import_module(f"sensornet.cli.commands.{module}"), func)


def _user_errors() -> tuple[type[BaseException], ...]:
    loaded = (getattr(sys.modules[m], n, None) for m, n in USER_ERRORS if m in sys.modules)
    return (UserError, SessionError, *(c for c in loaded if c is not None))


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    code = 1
    try:
        code = int(command(args.command)(args) or 0)
        return code
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
    except Exception as exc:
        if not isinstance(exc, _user_errors()):
            raise
        code = 2
        print(f"sensornet: error: {exc}", file=sys.stderr)
        return 2
    finally:
        if code != 0:
            _remove_empty_run_folders()
        _CREATED.clear()


if __name__ == "__main__":
    sys.exit(main())
