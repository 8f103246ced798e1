"""``record`` and ``play``: a live network into one MCAP file, and back onto a network."""

from __future__ import annotations

import argparse
import signal
import sys
import threading
from pathlib import Path

from sensornet.bag import (
    NoNetwork,
    PeersMissing,
    await_peers,
    network_of,
    play,
    read_bag,
    record,
    select,
)
from sensornet.cli.common import UserError
from sensornet.live import default_wait
from sensornet.peers.session import SessionError, open_session
from sensornet.protocol.keys import check_name


def _stop_on_term() -> threading.Event:
    """An event SIGTERM sets (Ctrl-C is a KeyboardInterrupt), so the file is closed whole."""
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    return stop


def cmd_record(args: argparse.Namespace) -> int:
    """``sensornet record NETWORK -o FILE.mcap``: every key of a live network into one MCAP."""
    try:
        check_name(args.network, "network name")
    except ValueError as exc:
        raise UserError(str(exc)) from None
    for flag, v in (("--duration", args.duration), ("--count", args.count),
                    ("--wait", args.wait)):
        if v is not None and not v > 0:
            raise UserError(f"{flag} must be positive")
    out = Path(args.out)
    if out.exists() and not args.force:
        raise UserError(f"{out} exists (pass --force to overwrite it)")
    wait = args.wait if args.wait is not None else default_wait(args.connect or ())
    try:
        bag = record(out, args.network, args.connect or (), args.config, args.duration,
                     args.count, args.until_end, wait, _stop_on_term(),
                     say=lambda s: print(s, file=sys.stderr, flush=True))
    except NoNetwork as exc:
        print(str(exc), file=sys.stderr)
        return 1
    except SessionError as exc:
        raise UserError(str(exc)) from None
    print(f"record: {bag.count} messages on {len(bag.keys)} keys -> {out}"
          + (f" ({bag.dropped} dropped: writing fell behind)" if bag.dropped else ""))
    return 0


def cmd_play(args: argparse.Namespace) -> int:
    """``sensornet play FILE``: put a recording back onto a network at its pace (``--rate``),
    all of it or a part (``--only``, ``--keys``), after ``--peers`` are ready if given."""
    if not args.rate > 0:
        raise UserError("--rate must be positive")
    if not args.wait > 0:
        raise UserError("--wait must be positive")
    if args.network is not None:
        try:
            check_name(args.network, "network name")
        except ValueError as exc:
            raise UserError(str(exc)) from None
    peers = [p for p in (args.peers or "").split(",") if p]
    for p in peers:
        try:
            check_name(p, "peer name in --peers", peer=True)
        except ValueError as exc:
            raise UserError(str(exc)) from None
    try:
        meta, items = read_bag(Path(args.file))
        items = select(items, args.only, args.keys or ())
    except (ValueError, OSError) as exc:
        raise UserError(str(exc)) from None
    if not any(it.alive is None for it in items):
        what = ("no messages to play" if not (args.only or args.keys) else
                "no messages of the selected keys (--only, --keys)")
        raise UserError(f"{args.file}: {what} (a 'sensornet record' bag or a peer's run "
                        f"--record file)")
    try:
        session = open_session(args.listen or (), args.connect or (), args.config)
    except SessionError as exc:
        raise UserError(str(exc)) from None
    stop = _stop_on_term()
    network = args.network or network_of(items)
    try:
        gate = (await_peers(session, network, peers, args.wait, stop) if peers else None)
        if args.delay:
            stop.wait(args.delay)
        span = items[-1].t - items[0].t
        wait = f" once {', '.join(peers)} are ready" if peers else ""
        print(f"play: {sum(it.alive is None for it in items)} messages over {span:.1f} s "
              f"at x{args.rate:g}{wait} (Ctrl-C to stop)", file=sys.stderr, flush=True)
        n = play(items, session, args.rate, args.network, stop, gate=gate)
    except KeyboardInterrupt:
        n = None
    except PeersMissing as exc:
        print(str(exc), file=sys.stderr)
        return 1
    finally:
        session.close()
    print(f"play: {'interrupted' if n is None else f'{n} messages put'}")
    return 0
