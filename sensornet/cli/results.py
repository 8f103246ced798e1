"""``plot``, ``echo`` and ``topics``: a run's per-scan results drawn, a running network heard."""

from __future__ import annotations

import argparse
from pathlib import Path

from sensornet.cli.common import UserError


def report_results(out: Path) -> Path | None:
    """Merge the peers' per-scan parts into ``<out>/results.parquet`` and say where it is."""
    from peers.scan_results import merge_parts

    try:
        table = merge_parts(sorted(out.glob("*.scans.msgpack")), out / "results.parquet")
    except ImportError:
        print("per-scan results: not merged (needs pyarrow: pip install pyarrow)")
        return None
    if table is not None:
        print(f"per-scan results: {table}  (plots: sensornet plot {out})")
    return table


def cmd_plot(args: argparse.Namespace) -> int:
    """``sensornet plot RUN``: tracks.png and metrics.png from the run's per-scan results."""
    from sim.run_plots import PlotError, plot_run

    try:
        paths = plot_run(Path(args.dir), Path(args.out) if args.out else None)
    except (PlotError, ValueError, OSError) as exc:
        raise UserError(str(exc)) from None
    for p in paths:
        print(p)
    return 0


def cmd_live(args: argparse.Namespace) -> int:
    """``sensornet echo`` / ``sensornet topics``: a running network's messages, decoded."""
    from peers.session import SessionError
    from protocol.keys import check_name
    from sensornet.live import Tap, main_echo, topics

    try:
        check_name(args.network, "network name")
    except ValueError as exc:
        raise UserError(str(exc)) from None
    if args.count is not None and args.count < 1:
        raise UserError("--count must be at least 1")
    if args.duration is not None and not args.duration > 0:
        raise UserError("--duration must be positive")
    if any(c in args.key for c in "?#$") or args.key.startswith("/"):
        raise UserError(f"key {args.key!r}: a key expression under sensornet/{args.network}/, "
                        "e.g. 'estimate/*'")
    security = None
    if args.secure:
        from peers.security import Security, SecurityError, load_roster

        if not args.member:
            raise UserError("--secure needs --as MEMBER (whose certificate the tool uses)")
        try:
            peers = [n for n in load_roster(Path(args.secure)) if n != "world"]
            security = Security.load(args.secure, args.member, args.network, peers)
        except (SecurityError, OSError, ValueError) as exc:
            raise UserError(str(exc)) from None
    elif args.member:
        raise UserError("--as needs --secure DIR")
    tap = Tap(args.network, args.key, args.connect or (), args.config, security)
    try:
        if args.command_name == "echo":
            return main_echo(tap, args.count, args.duration)
        tap.open()
        try:
            print(topics(tap, args.duration, count=args.count), flush=True)
        finally:
            tap.close()
        return 0
    except SessionError as exc:
        raise UserError(str(exc)) from None


def add_parsers(sub) -> None:
    """The ``echo``, ``topics`` and ``plot`` subcommands."""
    for name, helptext in (("echo", "print every message on a running network, decoded, one "
                                     "line each (sender, kind, scan, contents, bytes)"),
                           ("topics", "listen to a running network for a while, then a table "
                                      "of its keys: messages, rate, bytes, kinds, newest scan")):
        ec = sub.add_parser(name, help=helptext)
        ec.add_argument("network", help="the network's name (sensornet run --network; default "
                                        "of run: the scenario's name)")
        if name == "echo":
            ec.add_argument("key", nargs="?", default="**",
                            help="key expression under sensornet/NETWORK/ (default **: "
                                 "everything; e.g. 'estimate/*', 'scan/s1', 'tracks/**')")
            ec.add_argument("--count", type=int, help="stop after this many messages")
        else:
            ec.add_argument("--count", type=int,
                            help="table as soon as this many messages were heard")
            ec.set_defaults(key="**")
        ec.add_argument("--duration", type=float, default=None if name == "echo" else 3.0,
                        help="seconds to listen (echo: until Ctrl-C or --count)")
        ec.add_argument("--connect", action="append",
                        help="a Zenoh endpoint of the network (e.g. the world's --listen)")
        ec.add_argument("--config", help="Zenoh JSON5 config file")
        ec.add_argument("--secure", metavar="DIR",
                        help="a keys folder: speak as --as MEMBER over mutual TLS and verify "
                             "every signature")
        ec.add_argument("--as", dest="member", help="the member the tool speaks as (--secure)")
        ec.set_defaults(func=cmd_live, command_name=name)

    pl = sub.add_parser("plot", help="track map and metrics over time (PNG) of one run from "
                                     "its per-scan results")
    pl.add_argument("dir", help="run folder (what 'sensornet run' printed: runs/<time>-run)")
    pl.add_argument("--out", help="figure folder (default: DIR)")
    pl.set_defaults(func=cmd_plot)
