"""``record`` and ``play``: a live network into one MCAP file, and back onto a network."""

from __future__ import annotations

import argparse
import json
import shlex
import signal
import sys
import threading
import time
from pathlib import Path

from sensornet.bag import (
    NoNetwork,
    PeersMissing,
    await_peers,
    network_of,
    play,
    read_bag,
    record,
    restamp,
    select,
)
from sensornet.cli.common import UserError
from sensornet.cli.scenarios import load
from sensornet.live import default_wait
from sensornet.peers.session import SessionError, open_session
from sensornet.protocol.keys import check_name
from sensornet.sim.scenario import scenario_text


def _stop_on_term() -> threading.Event:
    """An event SIGTERM sets (Ctrl-C is a KeyboardInterrupt), so the file is closed whole."""
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    return stop


def _scenario_meta(args: argparse.Namespace) -> dict[str, str] | None:
    """The run's scenario for the bag's metadata (``--scenario``, ``--set``), checked by
    loading it (a bad one: the loader's one line, exit 2); None without ``--scenario``."""
    if not args.scenario:
        if args.set:
            raise UserError("--set changes the --scenario: give it too")
        return None
    load(args, args.scenario)
    src = Path(args.scenario)
    key = args.scenario.removesuffix(".toml")
    return {"scenario_text": src.read_text() if src.is_file() else scenario_text(key),
            "scenario_file": src.name if src.is_file() else f"{key}.toml",
            "overrides": json.dumps(list(args.set or []))}


def _scenario_line(meta: dict[str, str]) -> str | None:
    """One line naming the recorded run's scenario, what peers fed from the bag need."""
    if not meta.get("scenario_file"):
        return None
    sets = "".join(f" --set {shlex.quote(s)}" for s in json.loads(meta.get("overrides")
                                                                   or "[]"))
    return (f"play: recorded with scenario {meta['scenario_file']}{sets} (start the peers "
            f"with it; the bag's metadata has its text)")


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
    scenario = _scenario_meta(args)
    wait = args.wait if args.wait is not None else default_wait(args.connect or ())
    try:
        bag = record(out, args.network, args.connect or (), args.config, args.duration,
                     args.count, args.until_end, wait, _stop_on_term(),
                     say=lambda s: print(s, file=sys.stderr, flush=True), scenario=scenario)
    except NoNetwork as exc:
        print(str(exc), file=sys.stderr)
        return 1
    except SessionError as exc:
        raise UserError(str(exc)) from None
    print(f"record: {bag.count} messages on {len(bag.keys)} keys -> {out}"
          + (f" ({bag.dropped} dropped: writing fell behind)" if bag.dropped else ""))
    return 0


def _stamps_line(items, keep: bool) -> str:
    """What the played messages' send times are, so what the peers' latency means."""
    if keep:
        return ("send times as recorded (--keep-stamps): the peers' latency figures count "
                "from the recording, not measured")
    first = {}
    for it in items:
        if it.alive is None:
            first.setdefault(it.key, it)  # a key's messages are all signed or none
    kept = sorted(k for k, it in first.items() if restamp(k, it.payload, 0.0) is None)
    return ("send times set as each message is put (the peers' latency counts from play)"
            + (f"; {len(kept)} keys' messages as recorded (signed or not sensornet's: "
               f"latency from them not measured)" if kept else ""))


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
        line = _scenario_line(meta)
        if line:
            print(line, file=sys.stderr, flush=True)
        span = items[-1].t - items[0].t
        wait = f" once {', '.join(peers)} are ready" if peers else ""
        print(f"play: {sum(it.alive is None for it in items)} messages over {span:.1f} s "
              f"at x{args.rate:g}{wait}; {_stamps_line(items, args.keep_stamps)} (Ctrl-C to "
              f"stop)", file=sys.stderr, flush=True)
        n = play(items, session, args.rate, args.network, stop, gate=gate,
                 stamp=None if args.keep_stamps else time.time)
    except KeyboardInterrupt:
        n = None
    except PeersMissing as exc:
        print(str(exc), file=sys.stderr)
        return 1
    finally:
        session.close()
    print(f"play: {'interrupted' if n is None else f'{n} messages put'}")
    return 0
