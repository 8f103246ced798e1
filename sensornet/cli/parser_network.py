"""The subcommands of a run over Zenoh: its processes (``peer``, ``host``, ``world``), the
launcher (``run``, ``demo``) and a ``router``. One function per subcommand, each taking the
subparsers action of :func:`sensornet.cli.parser.build_parser`."""

from __future__ import annotations

import argparse

from sensornet.cli.common import (
    DEFAULT_SCENARIO,
    NONNEGATIVE_INT,
    POSITIVE_FLOAT,
    POSITIVE_INT,
    ROUNDS,
    _network_name,
    _router_name,
)
from sensornet.cli.parser_flags import (
    add_budget_flags,
    add_launcher_net_flags,
    add_member_net_flags,
    add_zenoh_flags,
)
from sensornet.peers.session import PEER_WAIT
from sensornet.sim.bounds import MAX_ROUNDS
from sensornet.sim.choices import FUSION_RULES, OMEGA_RULES, OOS_POLICIES
from sensornet.sim.kinds import names as kind_names
from sensornet.sim.run.run_handle import VIEW_WAIT


def add_peer_flags(sp: argparse.ArgumentParser) -> None:
    """The flags ``sensornet peer`` and ``sensornet host`` share (each peer of a host gets
    them all)."""
    add_member_net_flags(sp)
    sp.add_argument("--world-grace", type=POSITIVE_FLOAT, metavar="SECONDS",
                    help="keep running this long when the world's liveliness goes away, in "
                         "case it comes back (a router restart); counted as an outage "
                         "(default: 8 scan intervals, at least 3 s)")
    sp.add_argument("--filter", choices=kind_names(),
                    help="local filter (default: the scenario's network.filter)")
    sp.add_argument("--fusion", choices=FUSION_RULES,
                    help="fusion rule ('ratio': the particle fusion rule, IMM peers only)")
    sp.add_argument("--rounds", type=ROUNDS,
                    help=f"consensus rounds per scan (1..{MAX_ROUNDS})")
    sp.add_argument("--omega", choices=OMEGA_RULES,
                    help="the peers' fusion weights (network.omega)")
    sp.add_argument("--policy", choices=OOS_POLICIES,
                    help="out-of-sequence policy (network.policy)")
    sp.add_argument("--level2", dest="level2", action="store_true", default=None,
                    help="level-2 pruning before publishing")
    sp.add_argument("--no-level2", dest="level2", action="store_false")
    sp.add_argument("--lease-ms", type=POSITIVE_INT,
                    help="Zenoh lease (how fast a frozen peer is seen)")
    sp.add_argument("--color", type=NONNEGATIVE_INT, help=argparse.SUPPRESS)  # default:
    # the sensor's index in the scenario, the colour the world's legend and plots give it
    _add_peer_link_and_output_flags(sp)
    add_budget_flags(sp)


def _add_peer_link_and_output_flags(sp: argparse.ArgumentParser) -> None:
    """A peer's Zenoh linking (gossip, autoconnect), what it writes, its run index and idle
    timeout."""
    sp.add_argument("--no-gossip", action="store_true",
                    help="link only to the --connect endpoints (no Zenoh gossip discovery)")
    sp.add_argument("--no-autoconnect", action="store_true",
                    help="dial only the --connect endpoints; others still learn of this "
                         "process by gossip and may link to it")
    sp.add_argument("--save-tracks", action="store_true",
                    help="write every scan's fused tracks to <out>/tracks-<peer>.npz")
    sp.add_argument("--record", action="store_true",
                    help="record what the peer's core is given to "
                         "<out>/record/peer-<name>.mcap (sensornet replay re-runs it "
                         "offline, bit for bit)")
    sp.add_argument("--run", type=NONNEGATIVE_INT, default=0,
                    help="Monte Carlo run index (seeds the injected link faults)")
    sp.add_argument("--idle-timeout", type=POSITIVE_FLOAT, default=30.0,
                    help="stop after this many seconds without input (default 30)")


def add_peer(sub) -> None:
    """``sensornet peer NAME``: one sensor peer as a process."""
    pe = sub.add_parser("peer", help="run one sensor peer (a process) over Zenoh")
    pe.add_argument("name", help="the sensor this peer filters (its name in the scenario)")
    pe.add_argument("--scenario", default=DEFAULT_SCENARIO, help="scenario file or built-in name")
    add_peer_flags(pe)


def add_host(sub) -> None:
    """``sensornet host``: several peers in one process over one Zenoh session."""
    ho = sub.add_parser("host", help="run several sensor peers in one process over one Zenoh "
                        "session (a peer host)")
    ho.add_argument("scenario", nargs="?", default=DEFAULT_SCENARIO,
                    help="scenario file or built-in name")
    ho.add_argument("--peers", required=True,
                    help="comma-separated sensors this host runs, e.g. s1,s2,s3")
    ho.add_argument("--name", type=_network_name, default="h1",
                    help="the host's name in its log lines (default h1)")
    add_peer_flags(ho)


def add_world(sub) -> None:
    """``sensornet world``: the scenario's truth and scans played over Zenoh."""
    w = sub.add_parser("world", help="play a scenario's truth and scans over Zenoh")
    w.add_argument("scenario", nargs="?", default=DEFAULT_SCENARIO)
    add_member_net_flags(w)
    w.add_argument("--peers", help="comma-separated peers to wait for before starting")
    w.add_argument("--wait", type=POSITIVE_FLOAT, default=PEER_WAIT,
                   help=f"seconds to wait for the peers (default {PEER_WAIT:g}; the run starts "
                        "as soon as they are ready)")
    w.add_argument("--view-wait", type=POSITIVE_FLOAT, metavar="SECONDS",
                   help="before the first scan, wait up to SECONDS from the start for a "
                        "subscriber on the truth (the run's view; sensornet run passes "
                        f"{VIEW_WAIT:g} when it starts one); default: no wait")
    w.add_argument("--run", type=NONNEGATIVE_INT, default=0,
                   help="Monte Carlo run index (random draws)")
    w.add_argument("--bundle", action="append", metavar="HOST=S1,S2,...",
                   help="send these sensors' scans to peer host HOST in one message per scan "
                        "(repeatable; sensornet run does this for its hosts)")
    w.add_argument("--progress-every", type=POSITIVE_INT, default=10, metavar="N",
                   help="print a progress line every N scans (default 10)")
    add_budget_flags(w)


def add_run_flags(sp: argparse.ArgumentParser) -> None:
    """The flags ``sensornet run`` and ``sensornet demo`` share (the launcher's)."""
    add_launcher_net_flags(sp)
    sp.add_argument("--run", type=NONNEGATIVE_INT, default=0, help="Monte Carlo run index")
    sp.add_argument("--fault", action="append", metavar="ACTION:PEER@SCAN",
                    help="process fault: kill|stop|cont|restart|term, e.g. kill:s2@30 "
                         "(repeatable; SCAN before the run's last); with --router also "
                         "restart:router@K")
    sp.add_argument("--record", action="store_true",
                    help="every peer records its inputs to <out>/record/*.mcap "
                         "(see: sensornet replay)")
    sp.add_argument("--router", action="store_true",
                    help="start a Zenoh router and make every process its client (the "
                         "topology of several machines, on loopback; with --secure DIR, "
                         "DIR needs a 'router' member)")
    sp.add_argument("--sparse", action="store_true",
                    help="Zenoh links only along the peer graph (gossip off): less "
                         "overhead in large networks; peers then see only their "
                         "neighbours come and go")
    sp.add_argument("--lease-ms", type=POSITIVE_INT,
                    help="Zenoh lease of every process: a frozen peer is noticed after "
                         "about this long (Zenoh's default is 10000)")
    sp.add_argument("--timeout", type=POSITIVE_FLOAT, default=60.0,
                    help="extra seconds allowed beyond the run's own length (default 60)")
    sp.add_argument("--per-process", type=POSITIVE_INT, metavar="N",
                    help="peers per process: hosts h1, h2, ... of N peers each, one Zenoh "
                         "session per host (sensornet host); default a process per peer "
                         "up to 16 peers, a host per core above (said in one line)")
    add_budget_flags(sp, peers=True)


def add_run(sub) -> None:
    """``sensornet run``: world and peers as processes (or the twin with ``--sim``)."""
    r = sub.add_parser("run", help="run a scenario: world + peers as processes over Zenoh")
    r.add_argument("scenario", nargs="?", default=DEFAULT_SCENARIO)
    add_run_flags(r)
    r.add_argument("--sim", action="store_true",
                   help="run the discrete-event twin instead of processes (fast, no network)")
    r.add_argument("--twin-workers", type=POSITIVE_INT, default=1, metavar="N",
                   help="with --sim: the twin's peers split over N worker processes "
                        "(the same results; 2 uses both cores of a 2-core machine)")


def add_demo(sub) -> None:
    """``sensornet demo``: ``run`` of the default scenario with a viewer spawned."""
    d = sub.add_parser("demo", help=f"'run {DEFAULT_SCENARIO}' with a live Rerun viewer: world "
                       "+ 3 peers over Zenoh, summary")
    add_run_flags(d)
    d.set_defaults(viewer="spawn")


def add_router(sub) -> None:
    """``sensornet router``: a Zenoh router for members that cannot reach each other."""
    ro = sub.add_parser("router", help="a Zenoh router for members that cannot all reach "
                        "each other (clients connect to it)")
    add_zenoh_flags(ro, listen="endpoint to listen on, e.g. tls/0.0.0.0:7447",
                    listen_required=True, connect="another router to link to (repeatable)",
                    config="a Zenoh JSON5 config file")
    ro.add_argument("--secure", metavar="DIR", help="mutual TLS and the network's access "
                    "control with the router's key in DIR (sensornet keys ... --members router)")
    ro.add_argument("--name", default="router", type=_router_name,
                    help="the router's member name (default router; must start with 'router')")
    ro.add_argument("--network", type=_network_name,
                    help="check that the keys are this network's")
