"""The subcommands that watch or feed a running network, or look at one run afterwards:
``echo``, ``topics``, ``record``, ``play``, ``view`` and ``plot``. One function per
subcommand (``echo`` and ``topics`` share one), each taking the subparsers action of
:func:`sensornet.cli.parser.build_parser`."""

from __future__ import annotations

import argparse

from sensornet.cli.common import (
    NONNEGATIVE_INT,
    _network_name,
    _run_id,
    _viewer,
)
from sensornet.cli.parser_flags import add_zenoh_flags

LIVE_TOOLS: tuple[tuple[str, str], ...] = (
    ("echo", "print every message on a running network, decoded, one line each (sender, kind, "
             "scan, contents, bytes)"),
    ("topics", "listen to a running network for a while, then a table of its keys: messages, "
               "rate, bytes, kinds, newest scan"),
)
"""The live tools' names and help lines (both run :func:`sensornet.cli.commands.live`)."""


def add_live(sub, name: str, helptext: str) -> None:
    """``sensornet echo`` (every message) or ``sensornet topics`` (a table of keys)."""
    ec = sub.add_parser(name, help=helptext)
    ec.add_argument("network", help="the network's name (sensornet run prints it as it "
                                    "starts, with the --connect endpoint: its --network, "
                                    "else a fresh random name run-XXXXXXXX)")
    if name == "echo":
        ec.add_argument("key", nargs="?", default="**",
                        help="key expression under sensornet/NETWORK/ (default **: "
                             "everything; e.g. 'estimate/*', 'scan/s1', 'tracks/**')")
        ec.add_argument("--count", type=int, help="stop after this many messages")
        ec.add_argument("--json", action="store_true",
                        help="one JSON object per message: key, time, encoding, bytes "
                             "and every field decoded")
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
    ec.add_argument("--wait", type=float, metavar="S",
                    help="seconds to wait for the network to answer before saying what to "
                         "pass, exit 1 (default 3, 20 with --connect)")
    ec.set_defaults(command_name=name)


def add_record(sub) -> None:
    """``sensornet record``: every key of a running network into one MCAP file."""
    rc = sub.add_parser("record", help="record every key of a running network (and its "
                        "liveliness tokens) into one MCAP file, JSON messages with schemas")
    rc.add_argument("network", help="the network's name (what 'sensornet run' printed)")
    rc.add_argument("-o", "--out", required=True, metavar="FILE.mcap", help="the bag to write")
    rc.add_argument("--connect", action="append", metavar="ENDPOINT",
                    help="a Zenoh endpoint of the network (e.g. the world's --listen)")
    rc.add_argument("--config", help="Zenoh JSON5 config file")
    rc.add_argument("--duration", type=float, help="seconds to record (default: Ctrl-C)")
    rc.add_argument("--count", type=int, help="stop after this many messages")
    rc.add_argument("--until-end", action="store_true",
                    help="stop 2 s after the run's end message")
    rc.add_argument("--wait", type=float, metavar="S",
                    help="seconds to wait for the network to answer (default 3, 20 with "
                         "--connect)")
    rc.add_argument("--force", action="store_true", help="overwrite FILE")
    rc.add_argument("--scenario", help="the run's scenario (file or built-in name), written to "
                    "the bag's metadata (the world publishes none): what peers fed from the "
                    "bag need")
    rc.add_argument("--set", action="append", metavar="KEY=VALUE",
                    help="the run's scenario overrides (repeatable; with --scenario)")


def add_play(sub) -> None:
    """``sensornet play``: a recording put back onto a network."""
    pl = sub.add_parser("play", help="put a recording (sensornet record, or a peer's run "
                        "--record file) back onto a network at its pace or --rate faster")
    pl.add_argument("file", help="an MCAP file")
    pl.add_argument("--connect", action="append", metavar="ENDPOINT",
                    help="a Zenoh endpoint to put onto (repeatable)")
    pl.add_argument("--listen", action="append", metavar="ENDPOINT",
                    help="listen here, so peers started by hand can --connect to it")
    pl.add_argument("--config", help="Zenoh JSON5 config file")
    pl.add_argument("--rate", type=float, default=1.0,
                    help="play this many times faster than recorded (default 1)")
    pl.add_argument("--network", help="put the keys under this network's name instead")
    pl.add_argument("--delay", type=float, default=0.0, metavar="S",
                    help="seconds to wait after opening (for subscribers to link)")
    pl.add_argument("--only", choices=("world", "peers"),
                    help="play only the world's part (scans, truth, control, its alive token: "
                         "fresh peers compute their own tracks) or only the peers' (default: "
                         "everything)")
    pl.add_argument("--keys", action="append", metavar="EXPR",
                    help="play only keys a Zenoh key expression includes, e.g. "
                         "'sensornet/*/scan/**' (repeatable)")
    pl.add_argument("--peers", metavar="NAMES",
                    help="as the world: wait until these peers (comma-separated) are ready "
                         "before the first message, and count the pace from it")
    pl.add_argument("--wait", type=float, default=60.0, metavar="S",
                    help="seconds to wait for the --peers (default 60)")
    pl.add_argument("--keep-stamps", action="store_true",
                    help="put the recorded bytes exactly, send times as recorded (default: "
                         "each message's send time set as it is put, as a live sender does, "
                         "so the peers' latency counts from play)")


def add_view(sub) -> None:
    """``sensornet view``: a live Rerun view of a running network (it only subscribes)."""
    vw = sub.add_parser("view", help="attach a live Rerun view to a running network: it only "
                        "subscribes (peers pay nothing for it); Ctrl-C detaches")
    vw.add_argument("network", type=_network_name, help="the network's name")
    add_zenoh_flags(vw, connect="a process of the network to join, e.g. the world's --listen "
                                "endpoint (repeatable)",
                    config="a Zenoh JSON5 config file")
    vw.add_argument("--scenario", help="the scenario the network plays (peer order and "
                    "colours, region, sensors, layout); without it peers are coloured as heard")
    vw.add_argument("--set", action="append", metavar="KEY=VALUE",
                    help="the scenario overrides of the run (repeatable)")
    vw.add_argument("--out", help="write the recording here (an .rrd file)")
    vw.add_argument("--viewer", type=_viewer,
                    help="'spawn' a Rerun viewer, 'none', or a rerun+http://HOST:PORT/proxy URL")
    vw.add_argument("--run-id", type=_run_id, help="Rerun recording id")
    vw.add_argument("--duration", type=float, help="seconds to watch (default: until Ctrl-C)")
    vw.add_argument("--until-end", action="store_true",
                    help="stop a few seconds after the run's end message")
    vw.add_argument("--count", type=int, metavar="N",
                    help="stop after drawing this many messages (detach once it has seen "
                         "enough, however long the network takes to send them)")
    vw.add_argument("--from-mcap", nargs="+", metavar="FILE",
                    help="rebuild the view offline from peers' recordings (run --record: "
                         "<run>/record/*.mcap) instead of joining a network")
    vw.add_argument("--estimates", action="store_true",
                    help="hear the peers' estimates too (the local marks of peers that send "
                         "no telemetry; costs every peer a copy of each estimate)")
    vw.add_argument("--nice", type=NONNEGATIVE_INT, default=0,
                    help="lower the view's CPU priority by this much (run: 10), so that on a "
                         "busy machine the view falls behind, not the peers")
    vw.add_argument("--idle", action="store_true",
                    help="run every thread of the view in Linux's SCHED_IDLE class (run does): "
                         "it takes only CPU time no peer wants, and a peer that wakes preempts "
                         "it at once; where not permitted, --nice (10 if 0) instead")
    vw.add_argument("--discard", action="store_true", help=argparse.SUPPRESS)
    # --discard, a diagnostic: subscribe and drop every message (what the subscription alone
    # costs the peers; benchmarks/bench_fifty.py --view-arg=--discard)
    vw.add_argument("--secure", metavar="DIR",
                    help="join a secure network with the read-only observer key of this keys "
                         "folder (sensornet keys makes 'view': it may subscribe, not put)")
    vw.add_argument("--as", dest="member", help="the observer member to join as, a name "
                    "starting with 'view' (default: view)")


def add_plot(sub) -> None:
    """``sensornet plot``: one run's track map and metrics over time."""
    pl = sub.add_parser("plot", help="track map and metrics over time (PNG) of one run from "
                                     "its per-scan results")
    pl.add_argument("dir", help="run folder (what 'sensornet run' printed: runs/<time>-run)")
    pl.add_argument("--out", help="figure folder (default: DIR)")
