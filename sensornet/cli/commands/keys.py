"""``keys``: a network's CA and each member's key and certificate (for ``--secure``)."""

from __future__ import annotations

import argparse
from pathlib import Path

from sensornet.cli.common import UserError
from sensornet.cli.scenarios import load
from sensornet.peers.security import OBSERVER, WORLD, SecurityError, make_keys


def cmd_keys(args: argparse.Namespace) -> int:
    """``sensornet keys NETWORK --out DIR``: the network's CA and one key + certificate per
    member (every peer, the world and the read-only observer a view joins as), plain PEM
    files (see :mod:`peers.security`)."""
    if args.members:
        members = [m.strip() for m in args.members.split(",") if m.strip()]
    else:
        members = [WORLD, *load(args, args.scenario).sensor_names, OBSERVER]
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
