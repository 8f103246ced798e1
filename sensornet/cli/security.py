"""``--secure``: a member's TLS files and the network's policy, and the keys folder of a run."""

from __future__ import annotations

import argparse
import os
from pathlib import Path

from sensornet.cli.common import UserError
from sensornet.peers.security import (
    OBSERVER,
    SIGN_KEY,
    WORLD,
    Security,
    check_endpoints,
    check_private,
    keys_network,
    make_keys,
)


def member_security(args: argparse.Namespace, member: str, scn):
    """``--secure DIR`` (or the scenario's ``[security] keys``) of a peer or the world: its
    TLS files and the network's policy."""
    folder = getattr(args, "secure", None) or scn.security
    if not folder:
        return None
    sec = Security.load(folder, member, args.network, scn.sensor_names)
    check_endpoints([*(args.listen or []), *(args.connect or [])])
    return sec


def run_keys(args: argparse.Namespace, scn, out: Path) -> Path | None:
    """``run/demo --secure [DIR]``: the keys folder (fresh keys in <out>/keys without DIR,
    the view's read-only observer key among them); the network name defaults to the one the
    keys were made for. A DIR without the observer's key runs without a view (said)."""
    if args.secure is None:
        return None
    check_endpoints([*(args.listen or []), *(args.connect or [])])
    router = ["router"] if getattr(args, "router", False) else []  # sim.run.launcher.ROUTER
    if args.secure == "":
        args.network = args.network or f"run-{os.urandom(4).hex()}"
        folder = out / "keys"
        make_keys(args.network, [WORLD, *scn.sensor_names, *router, OBSERVER], folder)
        return folder.resolve()
    folder = Path(args.secure)
    made_for = keys_network(folder)
    if args.network and args.network != made_for:
        raise UserError(f"--secure {folder}: keys of network {made_for!r}, not of "
                        f"{args.network!r}")
    args.network = made_for
    missing = [m for m in [WORLD, *scn.sensor_names, *router]
               if not all((folder / f"{m}{x}").is_file() for x in (".key", SIGN_KEY))]
    if missing:
        raise UserError(f"--secure {folder}: no key for {', '.join(missing)} (add them with: "
                        f"sensornet keys {made_for} --out {folder} --members "
                        f"{','.join(missing)})")
    for m in [WORLD, *scn.sensor_names, *router]:  # before any process reads one
        for x in (".key", SIGN_KEY):
            check_private(folder / f"{m}{x}")
    if not (folder / f"{OBSERVER}.key").is_file():
        if not getattr(args, "no_rerun", True):
            print(f"secure: no view ({folder} has no key for the read-only observer "
                  f"{OBSERVER!r}; add it with: sensornet keys {made_for} --out {folder} "
                  f"--members {OBSERVER}); the world records alone", flush=True)
    else:
        check_private(folder / f"{OBSERVER}.key")
    return folder.resolve()
