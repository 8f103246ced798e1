"""The argument parser of every command (options, help, one-line errors) and the table of
which module runs each command.

Light on purpose: it imports no command module and nothing heavy (NumPy, SciPy, Zenoh's
peers); :func:`sensornet.cli.main` imports the one module of the command given, from
:data:`COMMANDS`, after parsing. So ``sensornet --help`` and ``sensornet run --help`` answer
without loading what a run needs.
"""

from __future__ import annotations

import argparse

from sensornet.cli.parser_network import (
    add_demo,
    add_host,
    add_peer,
    add_router,
    add_run,
    add_world,
)
from sensornet.cli.parser_offline import (
    add_campaign,
    add_experiment,
    add_keys,
    add_replay,
    add_report,
    add_scenario,
    add_sweep,
)
from sensornet.cli.parser_tools import (
    LIVE_TOOLS,
    add_live,
    add_play,
    add_plot,
    add_record,
    add_view,
)

COMMANDS: dict[str, str] = {
    "experiment": "experiment:cmd_experiment",
    "peer": "peer:cmd_peer",
    "host": "peer:cmd_host",
    "world": "world:cmd_world",
    "run": "run:cmd_run",
    "demo": "run:cmd_demo",
    "replay": "replay:cmd_replay",
    "sweep": "sweep:cmd_sweep",
    "campaign": "campaign:cmd_campaign",
    "report": "report:cmd_report",
    "echo": "live:cmd_live",
    "topics": "live:cmd_live",
    "record": "bag:cmd_record",
    "play": "bag:cmd_play",
    "view": "view:cmd_view",
    "plot": "plot:cmd_plot",
    "scenario": "scenario:cmd_scenario",
    "router": "router:cmd_router",
    "keys": "keys:cmd_keys",
}
"""Command -> ``"module:function"`` under :mod:`sensornet.cli.commands`; the function takes
the parsed arguments and returns the exit code."""

# --------------------------------------------------------------------------------------------
# The parser
# --------------------------------------------------------------------------------------------


class Parser(argparse.ArgumentParser):
    """An argument parser whose errors are one line (no usage block) with exit code 2."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message} (see: {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    """The ``sensornet`` parser: each subcommand declared by its function in
    :mod:`~sensornet.cli.parser_offline`, :mod:`~sensornet.cli.parser_network` or
    :mod:`~sensornet.cli.parser_tools` (shared flags in :mod:`~sensornet.cli.parser_flags`),
    in the order ``--help`` lists them."""
    p = Parser(
        prog="sensornet",
        description="Peer-to-peer multi-sensor multi-target tracking (GM-PHD, GCI fusion).",
    )
    sub = p.add_subparsers(dest="command", required=True, parser_class=Parser)
    add_experiment(sub)
    add_peer(sub)
    add_host(sub)
    add_world(sub)
    add_run(sub)
    add_demo(sub)
    add_replay(sub)
    add_sweep(sub)
    add_campaign(sub)
    add_report(sub)
    for name, helptext in LIVE_TOOLS:
        add_live(sub, name, helptext)
    add_record(sub)
    add_play(sub)
    add_view(sub)
    add_plot(sub)
    add_scenario(sub)
    add_router(sub)
    add_keys(sub)
    return p
