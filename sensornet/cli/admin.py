"""``router``, ``keys`` and ``scenario``."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from sensornet.cli.common import UserError
from sensornet.cli.peer import _load
from sim.scenario import (
    builtin_scenarios,
    scenario_text,
)


def cmd_router(args: argparse.Namespace) -> int:
    """``sensornet router``: a Zenoh router (see :mod:`sim.router`)."""
    from sim.router import serve

    serve(args.listen, args.connect or [], args.config, args.secure, args.name, args.network)
    return 0


def cmd_keys(args: argparse.Namespace) -> int:
    """``sensornet keys NETWORK --out DIR``: the network's CA and one key + certificate per
    member (every peer and the world), plain PEM files (see :mod:`peers.security`)."""
    from peers.security import WORLD, SecurityError, make_keys

    if args.members:
        members = [m.strip() for m in args.members.split(",") if m.strip()]
    else:
        members = [WORLD, *_load(args, args.scenario).sensor_names]
    hosts = [h.strip() for h in (args.hosts or "localhost,127.0.0.1").split(",") if h.strip()]
    try:
        paths = make_keys(args.network, members, Path(args.out), days=args.days, hosts=hosts,
                          overwrite=args.rotate)
    except (SecurityError, ValueError) as exc:
        raise UserError(str(exc)) from None
    print(f"keys for network {args.network}: CA and {len(members)} members "
          f"({', '.join(members)}) in {args.out}")
    print(f"  {len(paths)} files; give each member only ca.pem, members.json (the roster of "
          "signing keys), <name>.pem, <name>.key and <name>.ed25519; keep ca.key apart")
    return 0


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
