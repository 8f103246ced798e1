"""The argument parser of every command (options, help, one-line errors) and the table of
which module runs each command.

Light on purpose: it imports no command module and nothing heavy (NumPy, SciPy, Zenoh's
peers); :func:`sensornet.cli.main` imports the one module of the command given, from
:data:`COMMANDS`, after parsing. So ``sensornet --help`` and ``sensornet run --help`` answer
without loading what a run needs.
"""

from __future__ import annotations

import argparse

from sensornet.cli.common import (
    DEFAULT_MAX_PEERS,
    DEFAULT_MAX_POINTS,
    DEFAULT_MAX_TARGETS,
    DEFAULT_SCENARIO,
    NONNEGATIVE_INT,
    POSITIVE_FLOAT,
    POSITIVE_INT,
    ROUNDS,
    RUNS,
    _default_jobs,
    _endpoint,
    _existing_file,
    _network_name,
    _router_name,
    _run_id,
    _viewer,
    default_memory_gb,
)
from sensornet.peers.session import PEER_WAIT
from sensornet.sim.bounds import MAX_ROUNDS
from sensornet.sim.choices import (
    BIRTH_MODELS,
    FUSION_RULES,
    MIXTURE_RULES,
    OMEGA_RULES,
    OOS_POLICIES,
)
from sensornet.sim.kinds import names as kind_names

COMMANDS: dict[str, str] = {
    "experiment": "experiment:cmd_experiment",
    "peer": "peer:cmd_peer",
    "host": "peer:cmd_host",
    "world": "world:cmd_world",
    "run": "run:cmd_run",
    "demo": "run:cmd_demo",
    "replay": "replay:cmd_replay",
    "sweep": "sweep:cmd_sweep",
    "campaign": "campaign:cmd_campaign",
    "report": "report:cmd_report",
    "echo": "live:cmd_live",
    "topics": "live:cmd_live",
    "record": "bag:cmd_record",
    "play": "bag:cmd_play",
    "view": "view:cmd_view",
    "plot": "plot:cmd_plot",
    "scenario": "scenario:cmd_scenario",
    "router": "router:cmd_router",
    "keys": "keys:cmd_keys",
}
"""Command -> ``"module:function"`` under :mod:`sensornet.cli.commands`; the function takes
the parsed arguments and returns the exit code."""

# --------------------------------------------------------------------------------------------
# The parser
# --------------------------------------------------------------------------------------------


class Parser(argparse.ArgumentParser):
    """An argument parser whose errors are one line (no usage block) with exit code 2."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message} (see: {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    p = Parser(
        prog="sensornet",
        description="Peer-to-peer multi-sensor multi-target tracking (GM-PHD, GCI fusion).",
    )
    sub = p.add_subparsers(dest="command", required=True, parser_class=Parser)

    def add_budget_flags(sp: argparse.ArgumentParser, peers: bool = False) -> None:
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
        sp.add_argument("--runs", type=RUNS, default=runs,
                        help=f"Monte Carlo runs (default {runs})")
        sp.add_argument("--jobs", type=POSITIVE_INT, default=_default_jobs(),
                        help="worker processes (default: number of cores, at most 4)")
        sp.add_argument("--out", help="output folder (default: runs/<time>-<command>)")
        sp.add_argument("--quiet", action="store_true", help="no progress bar")

    e = sub.add_parser("experiment", help="offline Monte Carlo: local vs fused vs centralized")
    e.add_argument("scenario", nargs="?", default=DEFAULT_SCENARIO,
                   help=f"scenario file (.toml) or built-in name (default {DEFAULT_SCENARIO})")
    e.add_argument("--birth", choices=[*BIRTH_MODELS, "both"],
                   help="birth model (default: the scenario's)")
    e.add_argument("--fusion", choices=MIXTURE_RULES,
                   help="override the fusion rule")
    e.add_argument("--set", action="append", metavar="KEY=VALUE",
                   help="override a scenario value, e.g. --set fusion.level2_pruning=false "
                        "or --set sensors.s1.clutter_rate=50 (repeatable)")
    add_mc_flags(e, 50)
    add_budget_flags(e)

    def add_net_flags(sp: argparse.ArgumentParser, network_required: bool,
                      launcher: bool = False) -> None:
        if launcher:
            sp.add_argument("--network", type=_network_name,
                            help="network name: the key space of this run (default: a fresh "
                                 "random name, run-XXXXXXXX, printed as the run starts)")
            sp.add_argument("--listen", action="append", metavar="ENDPOINT", type=_endpoint,
                            help="the world listens here (peers connect to the first), e.g. "
                                 "tcp/127.0.0.1:7447, so that more peers can join by hand")
            sp.add_argument("--connect", action="append", metavar="ENDPOINT", type=_endpoint,
                            help="every process also connects here, e.g. a zenohd router "
                                 "(repeatable)")
            sp.add_argument("--config", type=_existing_file,
                            help="a Zenoh JSON5 config file for every process (flags apply "
                                 "on top)")
            sp.add_argument("--out", help="run folder (default: runs/<time>-run)")
            sp.add_argument("--run-id", type=_run_id,
                            help="Rerun recording id of the run (default: network name + "
                                 "random suffix)")
        else:
            sp.add_argument("--network", required=network_required, type=_network_name,
                            help="network name: the key space of this run (runs apart by "
                                 "name)")
            sp.add_argument("--listen", action="append", metavar="ENDPOINT", type=_endpoint,
                            help="Zenoh endpoint to listen on, e.g. tcp/127.0.0.1:7447")
            sp.add_argument("--connect", action="append", metavar="ENDPOINT", type=_endpoint,
                            help="Zenoh endpoint to connect to (repeatable)")
            sp.add_argument("--config", type=_existing_file,
                            help="a Zenoh JSON5 config file (flags apply on top)")
            sp.add_argument("--out", help="folder for the summary and the .rrd file")
            sp.add_argument("--run-id", type=_run_id,
                            help="Rerun recording id shared by the run's processes")
            sp.add_argument("--recover", action="store_true",
                            help="estimates and scans through Zenoh's advanced publisher/"
                                 "subscriber: publishers keep their last messages, a "
                                 "subscriber that missed some (a router's outage) asks for "
                                 "them; counted in the summary (run --router sets it)")
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
        if launcher:
            sp.add_argument("--secure", nargs="?", const="", metavar="DIR",
                            help="mutual TLS and access control with the keys in DIR "
                                 "(sensornet keys); without DIR, fresh keys in <out>/keys")
        else:
            sp.add_argument("--secure", metavar="DIR",
                            help="mutual TLS and access control with this member's key, "
                                 "certificate and the network's CA in DIR (sensornet keys)")


    def add_peer_flags(sp: argparse.ArgumentParser) -> None:
        """The flags ``sensornet peer`` and ``sensornet host`` share (each peer of a host
        gets them all)."""
        add_net_flags(sp, network_required=True)
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
        add_budget_flags(sp)

    pe = sub.add_parser("peer", help="run one sensor peer (a process) over Zenoh")
    pe.add_argument("name", help="the sensor this peer filters (its name in the scenario)")
    pe.add_argument("--scenario", default=DEFAULT_SCENARIO, help="scenario file or built-in name")
    add_peer_flags(pe)

    ho = sub.add_parser("host", help="run several sensor peers in one process over one Zenoh "
                        "session (a peer host)")
    ho.add_argument("scenario", nargs="?", default=DEFAULT_SCENARIO,
                    help="scenario file or built-in name")
    ho.add_argument("--peers", required=True,
                    help="comma-separated sensors this host runs, e.g. s1,s2,s3")
    ho.add_argument("--name", type=_network_name, default="h1",
                    help="the host's name in its log lines (default h1)")
    add_peer_flags(ho)

    w = sub.add_parser("world", help="play a scenario's truth and scans over Zenoh")
    w.add_argument("scenario", nargs="?", default=DEFAULT_SCENARIO)
    add_net_flags(w, network_required=True)
    w.add_argument("--peers", help="comma-separated peers to wait for before starting")
    w.add_argument("--wait", type=POSITIVE_FLOAT, default=PEER_WAIT,
                   help=f"seconds to wait for the peers (default {PEER_WAIT:g}; the run starts "
                        "as soon as they are ready)")
    w.add_argument("--run", type=NONNEGATIVE_INT, default=0,
                   help="Monte Carlo run index (random draws)")
    w.add_argument("--bundle", action="append", metavar="HOST=S1,S2,...",
                   help="send these sensors' scans to peer host HOST in one message per scan "
                        "(repeatable; sensornet run does this for its hosts)")
    w.add_argument("--progress-every", type=POSITIVE_INT, default=10, metavar="N",
                   help="print a progress line every N scans (default 10)")
    add_budget_flags(w)

    def add_run_flags(sp: argparse.ArgumentParser) -> None:
        add_net_flags(sp, network_required=False, launcher=True)
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

    r = sub.add_parser("run", help="run a scenario: world + peers as processes over Zenoh")
    r.add_argument("scenario", nargs="?", default=DEFAULT_SCENARIO)
    add_run_flags(r)
    r.add_argument("--sim", action="store_true",
                   help="run the discrete-event twin instead of processes (fast, no network)")

    d = sub.add_parser("demo", help=f"'run {DEFAULT_SCENARIO}' with a live Rerun viewer: world "
                       "+ 3 peers over Zenoh, summary")
    add_run_flags(d)
    d.set_defaults(viewer="spawn")

    rp = sub.add_parser("replay", help="feed a recorded run through the peers offline: the "
                        "same fused tracks bit for bit, or a what-if with --set")
    rp.add_argument("path", help="a run folder (its record/*.mcap) or one .mcap file")
    rp.add_argument("--peer", help="only this peer's recording")
    rp.add_argument("--set", action="append", metavar="KEY=VALUE",
                    help="change a setting for the replay (what-if), e.g. fusion.cardinality=emd "
                         "(not network.rounds: the recording holds only the rounds it had)")

    sw = sub.add_parser("sweep", help="sweep a fault parameter x out-of-sequence policy "
                        "over Monte Carlo runs (twin by default): CSV and plot")
    sw.add_argument("scenario", nargs="?", default=DEFAULT_SCENARIO)
    sw.add_argument("--param", required=True,
                    help="scenario key to sweep, e.g. faults.default.delay.high")
    sw.add_argument("--values", required=True,
                    help="comma-separated values (TOML literals), or ';'-separated")
    sw.add_argument("--policies", default="nale,drop-late,as-is")
    sw.add_argument("--real", action="store_true",
                    help="real processes over Zenoh instead of the twin (slow)")
    sw.add_argument("--set", action="append", metavar="KEY=VALUE",
                    help="base scenario overrides (repeatable)")
    add_mc_flags(sw, 50)
    add_budget_flags(sw, peers=True)

    ca = sub.add_parser("campaign", help="run an experiment campaign file (cells x Monte "
                        "Carlo runs; resumable; local pool or Dask)")
    ca.add_argument("file", help="campaign .toml (or a shipped one: seed000-figures, "
                    "seed000-twin, policy-sweep, loss-sweep)")
    ca.add_argument("--runs", type=RUNS, help="Monte Carlo runs per cell "
                    "(default: the file's)")
    ca.add_argument("--jobs", type=POSITIVE_INT, help="worker processes, or LocalCluster "
                    "workers with --dask local (default: all cores; 1 for runner 'real')")
    ca.add_argument("--dask", choices=["local"], help="run on a Dask LocalCluster")
    ca.add_argument("--scheduler", metavar="tcp://HOST:8786",
                    help="run on a running Dask scheduler (see README: campaigns)")
    ca.add_argument("--status", action="store_true", help="show progress without running")
    ca.add_argument("--out", help="campaign folder (default: runs/campaign-<name>)")
    ca.add_argument("--quiet", action="store_true", help="no progress bar")
    ca.add_argument("--stop-after", type=POSITIVE_INT, help=argparse.SUPPRESS)  # tests:
    # stop as an interrupt would once this many runs have finished

    rp = sub.add_parser("report", help="markdown + PNG report of a campaign folder")
    rp.add_argument("dir", help="campaign folder (runs/campaign-<name>)")
    rp.add_argument("--out", help="report folder (default: DIR/report)")
    rp.add_argument("--html", action="store_true",
                    help="also report.html beside report.md: one self-contained file (tables, "
                         "every figure embedded)")

    _add_live_and_plot(sub)

    s = sub.add_parser("scenario", help="list or print built-in scenario files")
    s.add_argument("action", choices=["list", "show"])
    s.add_argument("name", nargs="?", default=DEFAULT_SCENARIO)

    ro = sub.add_parser("router", help="a Zenoh router for members that cannot all reach "
                        "each other (clients connect to it)")
    ro.add_argument("--listen", action="append", required=True, metavar="ENDPOINT",
                    type=_endpoint, help="endpoint to listen on, e.g. tls/0.0.0.0:7447")
    ro.add_argument("--connect", action="append", metavar="ENDPOINT", type=_endpoint,
                    help="another router to link to (repeatable)")
    ro.add_argument("--config", type=_existing_file, help="a Zenoh JSON5 config file")
    ro.add_argument("--secure", metavar="DIR", help="mutual TLS and the network's access "
                    "control with the router's key in DIR (sensornet keys ... --members router)")
    ro.add_argument("--name", default="router", type=_router_name,
                    help="the router's member name (default router; must start with 'router')")
    ro.add_argument("--network", type=_network_name,
                    help="check that the keys are this network's")

    k = sub.add_parser("keys", help="make a network's CA and each member's key and "
                       "certificate (for --secure)")
    k.add_argument("network", type=_network_name, help="the network the keys are for")
    k.add_argument("--out", required=True, help="folder for the PEM files")
    k.add_argument("--scenario", default=DEFAULT_SCENARIO,
                   help="members: the world and the scenario's sensors "
                   f"(default {DEFAULT_SCENARIO})")
    k.add_argument("--members", help="comma-separated member names instead, e.g. "
                   "world,s1,s2,s3")
    k.add_argument("--hosts", help="host names and addresses the certificates are valid for "
                   "(default localhost,127.0.0.1)")
    k.add_argument("--days", type=POSITIVE_INT, default=365, help="validity (default 365)")
    k.add_argument("--rotate", action="store_true",
                   help="issue new keys for the named members (same CA)")
    k.set_defaults(set=None)
    return p


def _add_bag(sub) -> None:
    """The ``record`` and ``play`` subcommands (sensornet.bag)."""
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


def _add_live_and_plot(sub) -> None:
    """The ``echo``, ``topics`` and ``plot`` subcommands."""
    for name, helptext in (("echo", "print every message on a running network, decoded, one "
                                     "line each (sender, kind, scan, contents, bytes)"),
                           ("topics", "listen to a running network for a while, then a table "
                                      "of its keys: messages, rate, bytes, kinds, newest scan")):
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
    _add_bag(sub)

    vw = sub.add_parser("view", help="attach a live Rerun view to a running network: it only "
                        "subscribes (peers pay nothing for it); Ctrl-C detaches")
    vw.add_argument("network", type=_network_name, help="the network's name")
    vw.add_argument("--connect", action="append", metavar="ENDPOINT", type=_endpoint,
                    help="a process of the network to join, e.g. the world's --listen "
                         "endpoint (repeatable)")
    vw.add_argument("--config", type=_existing_file, help="a Zenoh JSON5 config file")
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
    vw.add_argument("--from-mcap", nargs="+", metavar="FILE",
                    help="rebuild the view offline from peers' recordings (run --record: "
                         "<run>/record/*.mcap) instead of joining a network")
    vw.add_argument("--estimates", action="store_true",
                    help="hear the peers' estimates too (the local marks of peers that send "
                         "no telemetry; costs every peer a copy of each estimate)")
    vw.add_argument("--nice", type=NONNEGATIVE_INT, default=0,
                    help="lower the view's CPU priority by this much (run: 10), so that on a "
                         "busy machine the view falls behind, not the peers")

    pl = sub.add_parser("plot", help="track map and metrics over time (PNG) of one run from "
                                     "its per-scan results")
    pl.add_argument("dir", help="run folder (what 'sensornet run' printed: runs/<time>-run)")
    pl.add_argument("--out", help="figure folder (default: DIR)")
