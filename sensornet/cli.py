"""The ``sensornet`` command line: experiments, scenarios, and (later) peers and the world."""

from __future__ import annotations

import argparse
import json
import os
import sys
import threading
import time
from pathlib import Path

from peers.session import SessionError  # noqa: E402
from sim.scenario import (
    ScenarioError,
    builtin_scenarios,
    load_scenario,
    parse_overrides,
    scenario_text,
)


class UserError(Exception):
    """A mistake the user can fix (bad file, bad flag): reported in one line, exit code 2."""


def _run_folder(base: str | None, kind: str) -> Path:
    root = Path(base) if base else Path("runs") / f"{time.strftime('%Y%m%d-%H%M%S')}-{kind}"
    root.mkdir(parents=True, exist_ok=True)
    return root


def _default_jobs() -> int:
    return max(1, min(os.cpu_count() or 1, 4))


def cmd_experiment(args: argparse.Namespace) -> int:
    from sim.experiment import format_table, run_experiment, write_outputs
    from sim.scenario import with_birth_model

    scn = load_scenario(args.scenario, overrides=parse_overrides(args.set or []))
    if args.runs < 1:
        raise UserError(f"--runs must be at least 1, got {args.runs}")
    if args.fusion:
        from dataclasses import replace

        scn = replace(scn, fusion=replace(scn.fusion, rule=args.fusion))
    births = ["paper", "truth"] if args.birth == "both" else [args.birth or scn.birth.model]
    out = _run_folder(args.out, "experiment")
    for model in births:
        s = with_birth_model(scn, model)
        result = run_experiment(s, args.runs, jobs=args.jobs, progress=not args.quiet)
        print(format_table(result))
        print()
        for path in write_outputs(result, out):
            print(f"wrote {path}")
        print()
    return 0


def _load(args: argparse.Namespace, source: str):
    return load_scenario(source, overrides=parse_overrides(getattr(args, "set", None) or []))


def cmd_peer(args: argparse.Namespace) -> int:
    from dataclasses import replace

    from peers.runtime import PeerRuntime
    from sim.build import fault_injector, make_peer

    scn = _load(args, args.scenario)
    if args.name not in scn.sensor_names:
        raise UserError(f"no sensor named {args.name!r} in {scn.name} "
                        f"(sensors: {', '.join(scn.sensor_names)})")
    net = scn.network
    scn = replace(scn, network=replace(
        net, rounds=args.rounds or net.rounds, omega=args.omega or net.omega,
        policy=args.policy or net.policy, filter=args.filter or net.filter), fusion=replace(
        scn.fusion, rule=args.fusion or scn.fusion.rule,
        level2_pruning=scn.fusion.level2_pruning if args.level2 is None else args.level2))
    speed = args.speed or scn.network.speed
    out = Path(args.out) if args.out else None
    runtime = PeerRuntime(
        make_peer(scn, args.name, args.run), args.network, scn.scan_period / speed,
        scn.network.deadline, listen=args.listen or [], connect=args.connect or [],
        config_file=args.config, lease_ms=args.lease_ms, out_dir=out, run_id=args.run_id,
        viewer=args.viewer, color_index=args.color, idle_timeout=args.idle_timeout,
        rerun=not args.no_rerun, faults=fault_injector(scn, args.run),
        save_tracks=args.save_tracks, gossip=not args.no_gossip, scan_period=scn.scan_period)
    print(f"peer {args.name}: network {args.network}, neighbours "
          f"{', '.join(runtime.logic.o.neighbours) or 'none'}", flush=True)
    code = runtime.run()
    s = runtime.summary()
    print(f"peer {args.name}: stopped ({s['stop_reason']}); {s['scans']} scans, mean OSPA "
          f"local {s['mean_ospa_local']:.1f} fused {s['mean_ospa_fused']:.1f}, "
          f"rejected {s['rejected_total']}", flush=True)
    return code


def cmd_world(args: argparse.Namespace) -> int:
    from sim.world_process import WorldError, run_world

    scn = _load(args, args.scenario)
    peers = [p for p in (args.peers or "").split(",") if p]
    unknown = [p for p in peers if p not in scn.sensor_names]
    if unknown:
        raise UserError(f"--peers names unknown sensors {unknown} "
                        f"(sensors: {', '.join(scn.sensor_names)})")
    out = Path(args.out) if args.out else None
    try:
        sent = run_world(scn, args.network, run=args.run, listen=args.listen or [],
                         connect=args.connect or [], config_file=args.config, wait_for=peers,
                         wait_timeout=args.wait, out_dir=out, run_id=args.run_id,
                         viewer=args.viewer, speed=args.speed, rerun=not args.no_rerun)
    except WorldError as exc:
        raise UserError(str(exc)) from None
    print(f"world: published {sent['scans_published']} scans of {len(scn.sensors)} sensors "
          f"({sent['bytes'] / 1e3:.1f} kB)", flush=True)
    return 0


def cmd_run(args: argparse.Namespace) -> int:
    from sim.launcher import (
        ProcessFault,
        format_summary,
        inject_process_faults,
        merge_recordings,
        read_summaries,
        start_run,
        wait_run,
    )

    scn = _load(args, args.scenario)
    try:
        pfaults = [ProcessFault.parse(f) for f in args.fault or []]
    except ValueError as exc:
        raise UserError(str(exc)) from None
    unknown = sorted({f.peer for f in pfaults} - set(scn.sensor_names))
    if unknown:
        raise UserError(f"--fault names unknown peers {unknown} "
                        f"(peers: {', '.join(scn.sensor_names)})")
    if args.sim:
        return _run_twin(scn, args)
    out = _run_folder(args.out, "run")
    speed = args.speed or scn.network.speed
    expected = scn.num_scans * scn.scan_period / speed
    print(f"run {scn.name}: world + {len(scn.sensors)} peers as processes over Zenoh on "
          f"127.0.0.1, {scn.num_scans} scans at {speed:g}x (about {expected:.0f} s); "
          f"output in {out}", flush=True)
    viewer = args.viewer
    if viewer == "spawn":  # one viewer for the whole run; every process streams to it
        from peers.rerun_sink import spawn_viewer

        viewer = "rerun+http://127.0.0.1:9876/proxy" if spawn_viewer() else None
    handle = start_run(scn, args.scenario, out, network=args.network, overrides=args.set,
                       viewer=viewer, run=args.run, speed=args.speed,
                       rerun=not args.no_rerun, lease_ms=args.lease_ms, sparse=args.sparse)
    stop = threading.Event()
    injector = None
    if pfaults:
        injector = threading.Thread(target=inject_process_faults, daemon=True,
                                    args=(handle, pfaults, scn.sensor_names[0], stop))
        injector.start()
    try:
        codes = wait_run(handle, timeout=expected + args.timeout)
    except KeyboardInterrupt:
        handle.stop_all()
        raise
    finally:
        stop.set()
        if injector is not None:
            injector.join(timeout=5)
    summaries = read_summaries(out, scn.sensor_names)
    print(format_summary(summaries))
    faults_file = out / "process-faults.json"
    if pfaults and faults_file.is_file():
        from sim.launcher import fault_report

        print(fault_report(json.loads(faults_file.read_text()), summaries))
    rec = merge_recordings(out)
    shown = rec or out / "rerun" / "*.rrd"
    print(f"recording: {shown}  (view it with: rerun {shown})")
    killed = {f.peer for f in pfaults if f.action in ("kill", "term", "restart")}
    bad = {n: c for n, c in codes.items() if c != 0 and n not in killed}
    if bad or len(summaries) != len(scn.sensors):
        for n, c in bad.items():
            print(f"{n} exited with code {c}; see {handle.logs[n]}", file=sys.stderr)
        missing = sorted(set(scn.sensor_names) - set(summaries))
        if missing:
            print(f"no summary from {missing}", file=sys.stderr)
        return 1
    return 0


def _run_twin(scn, args: argparse.Namespace) -> int:
    """``sensornet run --sim``: the same peers on the discrete-event twin (no processes)."""
    from sim.launcher import format_summary
    from sim.twin import run_twin

    if args.fault:
        raise UserError("--fault (process faults) needs real processes; drop --sim")
    t0 = time.perf_counter()
    result = run_twin(scn, args.run)
    summaries = {}
    for name, peer in result.peers.items():
        ages = [a for r in peer.records if r["kind"] == "fusion" for a in r["ages"].values()]
        summaries[name] = {
            "scans": peer.stats.scans, "mean_ospa_local": peer.mean_ospa("local"),
            "mean_ospa_fused": peer.mean_ospa("fused"),
            "messages_sent": peer.stats.estimates_out + peer.stats.tracks_out,
            "messages_received": peer.stats.estimates_in,
            "bytes_sent": 8 * peer.stats.tuples_out, "bytes_received": 0, "rejected_total": 0,
            "mean_estimate_age": sum(ages) / len(ages) if ages else None,
            "latency_ms_median": None, "latency_ms_p99": None}
    print(f"twin run {scn.name} (run {args.run}): {len(summaries)} peers, {scn.num_scans} "
          f"scans in {time.perf_counter() - t0:.1f} s (kB sent: raw tuples x 8 bytes)")
    print(format_summary(summaries))
    if result.faults is not None:
        print(f"injected link faults: {result.faults.counts()}")
        if args.out:
            out = _run_folder(args.out, "run")
            result.faults.write_log(out / "faults.csv")
            print(f"fault log: {out / 'faults.csv'}")
    return 0


def cmd_demo(args: argparse.Namespace) -> int:
    args.scenario = "seed000"
    args.set = list(args.set or []) + ["birth.model=truth"]
    args.fault = []
    args.lease_ms = None
    args.sim = False
    args.sparse = False
    return cmd_run(args)


def cmd_sweep(args: argparse.Namespace) -> int:
    from sim.sweep import format_summary, summarise, sweep, write_outputs

    values = list(parse_overrides([f"v={v}" for v in args.values.split(";")]).values()) \
        if ";" in args.values else [parse_overrides([f"v={v}"])["v"]
                                    for v in args.values.split(",")]
    policies = [p for p in args.policies.split(",") if p]
    bad = [p for p in policies if p not in ("nale", "drop-late", "as-is")]
    if bad:
        raise UserError(f"unknown policies {bad}; use nale, drop-late, as-is")
    if args.runs < 1:
        raise UserError(f"--runs must be at least 1, got {args.runs}")
    rows = sweep(args.scenario, args.param, values, policies, args.runs,
                 base=parse_overrides(args.set or []), real=args.real, jobs=args.jobs,
                 progress=not args.quiet)
    print(format_summary(args.param, summarise(rows)))
    for path in write_outputs(rows, args.param, _run_folder(args.out, "sweep")):
        print(f"wrote {path}")
    return 0


def cmd_scenario(args: argparse.Namespace) -> int:
    if args.action == "list":
        for name in builtin_scenarios():
            print(name)
        return 0
    if args.name not in builtin_scenarios():
        raise UserError(f"unknown built-in scenario {args.name!r}; "
                        f"known: {', '.join(builtin_scenarios())}")
    sys.stdout.write(scenario_text(args.name))
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="sensornet",
        description="Peer-to-peer multi-sensor multi-target tracking (GM-PHD, GCI fusion).",
    )
    sub = p.add_subparsers(dest="command", required=True)

    def add_mc_flags(sp: argparse.ArgumentParser, runs: int) -> None:
        sp.add_argument("--runs", type=int, default=runs, help=f"Monte Carlo runs (default {runs})")
        sp.add_argument("--jobs", type=int, default=_default_jobs(),
                        help="worker processes (default: number of cores, at most 4)")
        sp.add_argument("--out", help="output folder (default: runs/<time>-experiment)")
        sp.add_argument("--quiet", action="store_true", help="no progress bar")

    e = sub.add_parser("experiment", help="offline Monte Carlo: local vs fused vs centralized")
    e.add_argument("scenario", nargs="?", default="seed000",
                   help="scenario file (.toml) or built-in name (default seed000)")
    e.add_argument("--birth", choices=["paper", "truth", "both"],
                   help="birth model (default: the scenario's)")
    e.add_argument("--fusion", choices=["gci", "aa", "none"], help="override the fusion rule")
    e.add_argument("--set", action="append", metavar="KEY=VALUE",
                   help="override a scenario value, e.g. --set fusion.level2_pruning=false "
                        "or --set sensors.s1.clutter_rate=50 (repeatable)")
    add_mc_flags(e, 50)
    e.set_defaults(func=cmd_experiment)

    def add_net_flags(sp: argparse.ArgumentParser, network_required: bool) -> None:
        sp.add_argument("--network", required=network_required,
                        help="network name: the key-space of this run (runs apart by name)")
        sp.add_argument("--listen", action="append", metavar="ENDPOINT",
                        help="Zenoh endpoint to listen on, e.g. tcp/127.0.0.1:7447")
        sp.add_argument("--connect", action="append", metavar="ENDPOINT",
                        help="Zenoh endpoint to connect to (repeatable)")
        sp.add_argument("--config", help="a Zenoh JSON5 config file (flags apply on top)")
        sp.add_argument("--out", help="folder for the summary and the .rrd file")
        sp.add_argument("--run-id", help="Rerun recording id shared by the run's processes")
        sp.add_argument("--viewer", help="'spawn' a Rerun viewer or a rerun+http:// URL")
        sp.add_argument("--speed", type=float, help="wall-clock speed factor (default: "
                        "the scenario's network.speed)")
        sp.add_argument("--set", action="append", metavar="KEY=VALUE",
                        help="override a scenario value (repeatable)")
        sp.add_argument("--no-rerun", action="store_true",
                        help="do not write .rrd files (benchmarks)")

    pe = sub.add_parser("peer", help="run one sensor peer (a process) over Zenoh")
    pe.add_argument("name", help="the sensor this peer filters (its name in the scenario)")
    pe.add_argument("--scenario", default="seed000", help="scenario file or built-in name")
    add_net_flags(pe, network_required=True)
    pe.add_argument("--filter", choices=["gmphd", "imm-pf", "imm-ekf"],
                    help="local filter (default: the scenario's network.filter)")
    pe.add_argument("--fusion", choices=["gci", "aa", "ratio", "none"],
                    help="fusion rule ('ratio': the particle fusion rule, IMM peers only)")
    pe.add_argument("--rounds", type=int, help="consensus rounds per scan")
    pe.add_argument("--omega", choices=["metropolis", "uniform", "det", "chernoff"])
    pe.add_argument("--policy", choices=["nale", "drop-late", "as-is"])
    pe.add_argument("--level2", dest="level2", action="store_true", default=None,
                    help="level-2 pruning before publishing")
    pe.add_argument("--no-level2", dest="level2", action="store_false")
    pe.add_argument("--lease-ms", type=int, help="Zenoh lease (how fast a frozen peer is seen)")
    pe.add_argument("--color", type=int, default=0, help=argparse.SUPPRESS)
    pe.add_argument("--no-gossip", action="store_true",
                    help="link only to the --connect endpoints (no Zenoh gossip discovery)")
    pe.add_argument("--save-tracks", action="store_true",
                    help="write every scan's fused tracks to <out>/tracks-<peer>.npz")
    pe.add_argument("--run", type=int, default=0,
                    help="Monte Carlo run index (seeds the injected link faults)")
    pe.add_argument("--idle-timeout", type=float, default=30.0,
                    help="stop after this many seconds without input (default 30)")
    pe.set_defaults(func=cmd_peer)

    w = sub.add_parser("world", help="play a scenario's truth and scans over Zenoh")
    w.add_argument("scenario", nargs="?", default="seed000")
    add_net_flags(w, network_required=True)
    w.add_argument("--peers", help="comma-separated peers to wait for before starting")
    w.add_argument("--wait", type=float, default=30.0, help="seconds to wait for the peers")
    w.add_argument("--run", type=int, default=0, help="Monte Carlo run index (random draws)")
    w.set_defaults(func=cmd_world)

    r = sub.add_parser("run", help="run a scenario: world + peers as processes over Zenoh")
    r.add_argument("scenario", nargs="?", default="seed000")
    add_net_flags(r, network_required=False)
    r.add_argument("--run", type=int, default=0, help="Monte Carlo run index")
    r.add_argument("--fault", action="append", metavar="ACTION:PEER@SCAN",
                   help="process fault: kill|stop|cont|restart|term, e.g. kill:s2@30 "
                        "(repeatable)")
    r.add_argument("--sparse", action="store_true",
                   help="Zenoh links only along the peer graph (gossip off): less overhead "
                        "in large networks; peers then see only their neighbours come and go")
    r.add_argument("--sim", action="store_true",
                   help="run the discrete-event twin instead of processes (fast, no network)")
    r.add_argument("--lease-ms", type=int,
                   help="Zenoh lease of every process: a frozen peer is noticed after about "
                        "this long (Zenoh's default is 10000)")
    r.add_argument("--timeout", type=float, default=60.0,
                   help="extra seconds allowed beyond the run's own length")
    r.set_defaults(func=cmd_run)

    d = sub.add_parser("demo", help="seed-000: world + 3 peers over Zenoh, live Rerun, summary")
    add_net_flags(d, network_required=False)
    d.add_argument("--run", type=int, default=0, help="Monte Carlo run index")
    d.add_argument("--timeout", type=float, default=60.0, help=argparse.SUPPRESS)
    d.set_defaults(func=cmd_demo)

    sw = sub.add_parser("sweep", help="sweep a fault parameter x out-of-sequence policy "
                        "over Monte Carlo runs (twin by default): CSV and plot")
    sw.add_argument("scenario", nargs="?", default="seed000")
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
    sw.set_defaults(func=cmd_sweep)

    s = sub.add_parser("scenario", help="list or print built-in scenario files")
    s.add_argument("action", choices=["list", "show"])
    s.add_argument("name", nargs="?", default="seed000")
    s.set_defaults(func=cmd_scenario)
    return p


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except (ScenarioError, UserError, SessionError) as exc:
        print(f"sensornet: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("sensornet: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
