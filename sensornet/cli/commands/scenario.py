"""``scenario list|show``: the built-in scenario files."""

from __future__ import annotations

import argparse
import sys

from sensornet.cli.common import UserError
from sensornet.sim.scenario import builtin_scenarios, scenario_text


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
