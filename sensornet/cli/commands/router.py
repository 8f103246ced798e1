"""``router``: a Zenoh router for members that cannot all reach each other."""

from __future__ import annotations

import argparse

from sensornet.sim.run.router import serve


def cmd_router(args: argparse.Namespace) -> int:
    """``sensornet router``: a Zenoh router (see :mod:`sim.run.router`)."""
    serve(args.listen, args.connect or [], args.config, args.secure, args.name, args.network)
    return 0
