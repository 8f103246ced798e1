"""Option groups several subcommands share, each declared once: budgets, Monte Carlo,
Zenoh endpoints and the network flags of a run's processes (a member: ``peer``, ``host``,
``world``) or of the launcher (``run``, ``demo``).

Light like :mod:`sensornet.cli.parser`: flag types and defaults from :mod:`sensornet.cli.common`
only, so ``--help`` loads nothing heavy.
"""

from __future__ import annotations

import argparse

from sensornet.cli.common import (
    DEFAULT_MAX_PEERS,
    DEFAULT_MAX_POINTS,
    DEFAULT_MAX_TARGETS,
    POSITIVE_FLOAT,
    POSITIVE_INT,
    RUNS,
    _default_jobs,
    _endpoint,
    _existing_file,
    _network_name,
    _run_id,
    _viewer,
    default_memory_gb,
)


def add_budget_flags(sp: argparse.ArgumentParser, peers: bool = False) -> None:
    """The budgets group (``--max-*``); ``--max-peers`` only where peers are processes."""
    g = sp.add_argument_group("budgets (a scenario over one refuses to start)")
    g.add_argument("--max-points", type=POSITIVE_INT, default=DEFAULT_MAX_POINTS,
                   metavar="N", help="expected measurements per scan of one sensor "
                   f"(default {DEFAULT_MAX_POINTS})")
    g.add_argument("--max-targets", type=POSITIVE_INT, default=DEFAULT_MAX_TARGETS,
                   metavar="N", help=f"true targets at once (default {DEFAULT_MAX_TARGETS})")
    if peers:
        g.add_argument("--max-peers", type=POSITIVE_INT, default=DEFAULT_MAX_PEERS,
                       metavar="N", help="peer processes started on this machine "
                       f"(default {DEFAULT_MAX_PEERS})")
    g.add_argument("--max-memory-gb", type=POSITIVE_FLOAT, metavar="X",
                   help="estimated memory (default: half of this machine's, "
                   f"{default_memory_gb():g} GB)")


def add_mc_flags(sp: argparse.ArgumentParser, runs: int) -> None:
    """Monte Carlo runs, worker processes, output folder and progress bar."""
    sp.add_argument("--runs", type=RUNS, default=runs,
                    help=f"Monte Carlo runs (default {runs})")
    sp.add_argument("--jobs", type=POSITIVE_INT, default=_default_jobs(),
                    help="worker processes (default: number of cores, at most 4)")
    sp.add_argument("--out", help="output folder (default: runs/<time>-<command>)")
    sp.add_argument("--quiet", action="store_true", help="no progress bar")


def add_zenoh_flags(sp: argparse.ArgumentParser, *, connect: str, config: str,
                    listen: str | None = None, listen_required: bool = False) -> None:
    """``--listen`` (if given its help), ``--connect`` (checked endpoints, repeatable) and
    ``--config`` (an existing Zenoh JSON5 file), each with the help text its command needs."""
    if listen is not None:
        sp.add_argument("--listen", action="append", required=listen_required,
                        metavar="ENDPOINT", type=_endpoint, help=listen)
    sp.add_argument("--connect", action="append", metavar="ENDPOINT", type=_endpoint,
                    help=connect)
    sp.add_argument("--config", type=_existing_file, help=config)


def add_launcher_net_flags(sp: argparse.ArgumentParser) -> None:
    """The network flags of ``run`` and ``demo``, which start the world and every peer."""
    sp.add_argument("--network", type=_network_name,
                    help="network name: the key space of this run (default: a fresh "
                         "random name, run-XXXXXXXX, printed as the run starts)")
    add_zenoh_flags(sp, listen="the world listens here (peers connect to the first), e.g. "
                               "tcp/127.0.0.1:7447, so that more peers can join by hand",
                    connect="every process also connects here, e.g. a zenohd router "
                            "(repeatable)",
                    config="a Zenoh JSON5 config file for every process (flags apply on top)")
    sp.add_argument("--out", help="run folder (default: runs/<time>-run)")
    sp.add_argument("--run-id", type=_run_id,
                    help="Rerun recording id of the run (default: network name + "
                         "random suffix)")
    _add_stream_flags(sp)
    sp.add_argument("--secure", nargs="?", const="", metavar="DIR",
                    help="mutual TLS and access control with the keys in DIR "
                         "(sensornet keys); without DIR, fresh keys in <out>/keys")


def add_member_net_flags(sp: argparse.ArgumentParser) -> None:
    """The network flags of one process of a run (``peer``, ``host``, ``world``)."""
    sp.add_argument("--network", required=True, type=_network_name,
                    help="network name: the key space of this run (runs apart by name)")
    add_zenoh_flags(sp, listen="Zenoh endpoint to listen on, e.g. tcp/127.0.0.1:7447",
                    connect="Zenoh endpoint to connect to (repeatable)",
                    config="a Zenoh JSON5 config file (flags apply on top)")
    sp.add_argument("--out", help="folder for the summary and the .rrd file")
    sp.add_argument("--run-id", type=_run_id,
                    help="Rerun recording id shared by the run's processes")
    sp.add_argument("--recover", action="store_true",
                    help="estimates and scans through Zenoh's advanced publisher/"
                         "subscriber: publishers keep their last messages, a "
                         "subscriber that missed some (a router's outage) asks for "
                         "them; counted in the summary (run --router sets it)")
    _add_stream_flags(sp)
    sp.add_argument("--secure", metavar="DIR",
                    help="mutual TLS and access control with this member's key, "
                         "certificate and the network's CA in DIR (sensornet keys)")


def _add_stream_flags(sp: argparse.ArgumentParser) -> None:
    """Viewer, pace, scenario overrides, recordings and ROS 2: the same for a run's launcher
    and its members."""
    sp.add_argument("--viewer", type=_viewer,
                    help="'spawn' a Rerun viewer, 'none', or a rerun+http://HOST:PORT/proxy "
                         "URL (an unreachable URL is a warning: files only)")
    sp.add_argument("--speed", type=POSITIVE_FLOAT, help="wall-clock speed factor "
                    "(default: the scenario's network.speed)")
    sp.add_argument("--set", action="append", metavar="KEY=VALUE",
                    help="override a scenario value (repeatable)")
    sp.add_argument("--no-rerun", action="store_true",
                    help="do not write .rrd files (benchmarks)")
    sp.add_argument("--ros2", dest="set", action="append_const",
                    const="network.ros2=true",
                    help="also publish the tracks (peers) and detections (world) as ROS 2 "
                         "messages in rmw_zenoh's format (= --set network.ros2=true; "
                         "docs/ros2.md)")
