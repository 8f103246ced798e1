"""``echo`` and ``topics``: a running network heard, its messages decoded."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from sensornet.cli.common import UserError
from sensornet.live import Tap, default_wait, main_echo, topics
from sensornet.peers.security import OBSERVER_PREFIX, Security, SecurityError, load_roster
from sensornet.peers.session import SessionError
from sensornet.protocol.keys import check_name


def cmd_live(args: argparse.Namespace) -> int:
    """``sensornet echo`` / ``sensornet topics``: a running network's messages, decoded."""
    try:
        check_name(args.network, "network name")
    except ValueError as exc:
        raise UserError(str(exc)) from None
    if args.count is not None and args.count < 1:
        raise UserError("--count must be at least 1")
    if args.duration is not None and not args.duration > 0:
        raise UserError("--duration must be positive")
    if getattr(args, "wait", None) is not None and not args.wait > 0:
        raise UserError("--wait must be positive")
    if any(c in args.key for c in "?#$") or args.key.startswith("/"):
        raise UserError(f"key {args.key!r}: a key expression under sensornet/{args.network}/, "
                        "e.g. 'estimate/*'")
    security = None
    if args.secure:
        if not args.member:
            raise UserError("--secure needs --as MEMBER (whose certificate the tool uses)")
        try:
            peers = [n for n in load_roster(Path(args.secure))
                     if n != "world" and not n.startswith(OBSERVER_PREFIX)]
            security = Security.load(args.secure, args.member, args.network, peers)
        except (SecurityError, OSError, ValueError) as exc:
            raise UserError(str(exc)) from None
    elif args.member:
        raise UserError("--as needs --secure DIR")
    tap = Tap(args.network, args.key, args.connect or (), args.config, security,
              json_lines=bool(getattr(args, "json", False)))
    try:
        wait = args.wait if getattr(args, "wait", None) is not None else default_wait(tap.connect)
        if args.command_name == "echo":
            return main_echo(tap, args.count, args.duration, wait)
        tap.open()
        try:
            wait = min(wait, args.duration)
            if not tap.answers(wait):
                print(tap.hint("topics", wait), file=sys.stderr, flush=True)
                return 1
            print(topics(tap, args.duration, count=args.count), flush=True)
        finally:
            tap.close()
        return 0
    except SessionError as exc:
        raise UserError(str(exc)) from None
