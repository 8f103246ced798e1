"""``run`` and ``demo``: a whole run (world and peers as processes, or the twin)."""

from __future__ import annotations

import argparse
import json
import math
import os
import signal
import sys
import threading
import time
from pathlib import Path

from sensornet.cli.budgets import check_budget
from sensornet.cli.commands.run_checks import (
    check_real_run,
    plan_processes,
    refuse_real_only_flags,
    refuse_used_out,
)
from sensornet.cli.common import (
    DEFAULT_SCENARIO,
    UserError,
    _run_folder,
)
from sensornet.cli.scenarios import load, warn_fusion
from sensornet.cli.security import run_keys
from sensornet.peers.rerun_sink import spawn_viewer
from sensornet.peers.scan_results import merge_parts, write_part
from sensornet.sim.run import launcher, run_summary
from sensornet.sim.run.twin import run_twin


def report_results(out: Path) -> Path | None:
    """Merge the peers' per-scan parts into ``<out>/results.parquet`` and say where it is."""
    try:
        table = merge_parts(sorted(out.glob("*.scans.msgpack")), out / "results.parquet")
    except ImportError:
        print("per-scan results: not merged (needs pyarrow: pip install pyarrow)")
        return None
    if table is not None:
        print(f"per-scan results: {table}  (plots: sensornet plot {out})")
    return table


def _last_line(path: Path) -> str:
    """The last non-blank line of a process's log (its error, if it failed), or ""."""
    try:
        lines = [ln.strip() for ln in path.read_text(errors="replace").splitlines() if ln.strip()]
    except OSError:
        return ""
    return lines[-1] if lines else ""


def _why_nothing_scored(name: str, s: dict) -> str:
    """Why peer ``name`` (summary ``s``) scored nothing: what it rejected, or why it stopped."""
    rejected = {k: v for k, v in (s.get("rejected") or {}).items() if v}
    if rejected:
        parts = ", ".join(f"{v} {k}" for k, v in sorted(rejected.items()))
        return f"peer {name} scored no scan: it rejected {parts} messages"
    if s.get("stop_reason"):
        return f"peer {name} scored no scan (stopped: {s['stop_reason']})"
    return f"peer {name} scored no scan"


def _scored(s: dict) -> bool:
    """Whether a peer's summary has scans and a finite local or fused mean OSPA."""
    vals = [s.get("mean_ospa_local"), s.get("mean_ospa_fused")]
    return bool(s.get("scans")) and any(v is not None and math.isfinite(v) for v in vals)


def cmd_run(args: argparse.Namespace) -> int:
    """``sensornet run``: check the flags against the scenario, start the world and the peers
    as processes (or the twin, ``--sim``), wait for them, report; the exit code says whether
    every peer that was not killed on purpose scored."""
    scn = load(args, args.scenario)
    warn_fusion(scn)
    pfaults, per_process, hosts = plan_processes(args, scn)
    if getattr(args, "sim", False):
        refuse_real_only_flags(args)
        check_budget(scn, args)
        return _run_twin(scn, args)
    if getattr(args, "twin_workers", 1) != 1:
        raise UserError("--twin-workers is the twin's: add --sim")
    check_real_run(args, scn, hosts)
    refuse_used_out(args.out)
    out = _run_folder(args.out, "run")
    secure = run_keys(args, scn, out)
    speed = args.speed or scn.network.speed
    expected = scn.num_scans * scn.scan_period / speed
    _announce(args, scn, hosts, out, secure, speed, expected)
    handle, codes, caught = _launch_and_wait(args, scn, out, secure, per_process, pfaults,
                                             expected)
    summaries = launcher.read_summaries(out, scn.sensor_names)
    killed = {f.peer for f in pfaults if f.action in ("kill", "term", "restart", "killhost")}
    killed |= {p for f in pfaults if f.action == "killhost" for p in hosts[f.peer]}
    if summaries:
        _print_summaries(scn, out, summaries, pfaults, hosts, killed, caught, speed)
    _print_outputs(args, out, pfaults, summaries)
    return _exit_code(scn, out, handle, codes, summaries, killed, caught)


def _announce(args: argparse.Namespace, scn, hosts: dict[str, list[str]], out: Path,
              secure, speed: float, expected: float) -> None:
    """The run's opening lines: what starts, how long its scans take, where output goes, the
    hosts and the secure mode."""
    how = (f"in {len(hosts)} host process{'es' if len(hosts) != 1 else ''}" if hosts
           else "as processes")
    print(f"run {scn.name}: world + {len(scn.sensors)} peers {how} over Zenoh on "
          f"127.0.0.1, {scn.num_scans} scans at {speed:g}x ({expected:.0f} s of scans, plus a "
          f"few seconds to start {len(hosts or scn.sensors) + 1} processes); output in {out}",
          flush=True)
    if hosts:
        print(launcher.hosts_line(hosts), flush=True)
    if secure is not None:
        made = " (fresh keys made for this run)" if args.secure == "" else ""
        print(f"secure mode: mutual TLS + access control on network {args.network}, keys in "
              f"{secure}{made}", flush=True)


def _launch_and_wait(args: argparse.Namespace, scn, out: Path, secure, per_process: int,
                     pfaults: list, expected: float) -> tuple[object, dict, list[str]]:
    """Start the run's processes, inject the process faults, wait for the end (or the
    timeout, or SIGINT/SIGTERM: stop the children, then report as usual). Returns the run's
    handle, the exit codes by process and the signals caught."""
    viewer = args.viewer
    if viewer == "spawn":  # one viewer for the whole run; every process streams to it
        viewer = "rerun+http://127.0.0.1:9876/proxy" if spawn_viewer() else None
    stop = threading.Event()
    caught: list[str] = []

    def on_signal(signum, frame) -> None:
        caught.append(signal.Signals(signum).name)
        stop.set()

    previous = {s: signal.signal(s, on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
    injector = None
    try:
        handle = launcher.start_run(
            scn, args.scenario, out, network=args.network, overrides=args.set, viewer=viewer,
            run=args.run, speed=args.speed, rerun=not args.no_rerun, lease_ms=args.lease_ms,
            sparse=args.sparse, listen=args.listen, connect=args.connect, config=args.config,
            run_id=args.run_id, secure=secure, router=bool(getattr(args, "router", False)),
            peer_args={n: ["--record"] for n in scn.sensor_names} if args.record else None,
            per_process=per_process)
        watch = _watch_line(handle)
        if watch:
            print(watch, flush=True)
        if getattr(args, "router", False):
            why = f" ({args.router})" if isinstance(args.router, str) else ""
            print(f"routed{why}: the world and every peer are clients of the run's router "
                  f"(sensornet router) at {handle.endpoints['router']}", flush=True)
        if pfaults:
            injector = threading.Thread(target=launcher.inject_process_faults, daemon=True,
                                        args=(handle, pfaults, scn.sensor_names[0], stop))
            injector.start()
        codes = launcher.wait_run(handle, timeout=expected + args.timeout, stop=stop)
    finally:
        stop.set()
        if injector is not None:
            injector.join(timeout=5)
        for s, h in previous.items():
            signal.signal(s, h)
    return handle, codes, caught


def _print_summaries(scn, out: Path, summaries: dict, pfaults: list,
                     hosts: dict[str, list[str]], killed: set[str], caught: list[str],
                     speed: float) -> None:
    """The peers' summary table (a peer killed on purpose marked so), the trust note and, on
    an undisturbed run, whether the peers kept up with real time."""
    tables, meta = run_summary.read_tables(out)
    run_summary.add_track_summary(summaries, tables, meta, out)
    scan_of = {f.peer: f.scan for f in pfaults}
    scan_of |= {p: f.scan for f in pfaults if f.action == "killhost" for p in hosts[f.peer]}
    missing = {n: (f"killed at scan {scan_of[n]}" if n in killed else "no summary")
               for n in scn.sensor_names if n not in summaries}
    print(launcher.format_summary(summaries, missing, scn.metrics.ospa_cutoff))
    if launcher.trust_note(summaries):
        print(launcher.trust_note(summaries))
    if not caught and not pfaults and scn.faults is None:  # faults: deadlines on purpose
        note = launcher.realtime_note(summaries, scn.scan_period / speed, speed, os.cpu_count())
        if note:
            print(note)


def _print_outputs(args: argparse.Namespace, out: Path, pfaults: list, summaries: dict) -> None:
    """What the run left: the process-fault report, the per-scan results and the merged
    Rerun recording (or why there is none)."""
    faults_file = out / "process-faults.json"
    if pfaults and faults_file.is_file():
        print(launcher.fault_report(json.loads(faults_file.read_text()), summaries))
    report_results(out)
    rec = launcher.merge_recordings(out)
    parts = sorted((out / "rerun").glob("*.rrd")) if (out / "rerun").is_dir() else []
    if rec is not None:
        print(f"recording: {rec}  (view it with: rerun {rec})")
    elif parts:
        print(f"recording: {out / 'rerun'} (the .rrd files could not be merged)")
    elif not args.no_rerun:
        print("recording: none (no process got as far as opening its recording)")


def _exit_code(scn, out: Path, handle, codes: dict, summaries: dict, killed: set[str],
               caught: list[str]) -> int:
    """0 for a run stopped by a signal or one where every peer not killed on purpose scored;
    else the first failure in one line on stderr (the world's, a process's exit code, a
    missing summary, a peer that scored nothing) and 1 (2 for a user error)."""
    if caught:
        if not summaries:  # stopped while the processes were still starting
            print(f"sensornet: stopped by {caught[0]} during start-up, before any peer began "
                  f"its run: nothing was tracked; every process stopped, logs in {out / 'logs'}",
                  file=sys.stderr)
            return 0
        print(f"sensornet: stopped by {caught[0]}; every process stopped, output in {out}",
              file=sys.stderr)
        return 0
    if handle.timed_out:  # stopped by wait_run, not by the run's own end: say so
        print(f"sensornet: error: the run outlived its length plus --timeout and was stopped "
              f"(the table above is what it did until then; allow more with --timeout), "
              f"output in {out}", file=sys.stderr)
        return 1
    world = codes.get("world")
    if world not in (0, None):
        why = _last_line(handle.logs["world"]).removeprefix("sensornet: error: ")
        print(f"sensornet: error: the world failed (exit {world}): {why} "
              f"(log: {handle.logs['world']})", file=sys.stderr)
        return 2 if world == 2 else 1
    bad = {n: c for n, c in codes.items() if c != 0 and n not in killed}
    if bad:
        n, c = next(iter(bad.items()))
        why = _last_line(handle.logs[n]).removeprefix("sensornet: error: ")
        more = f" (and {len(bad) - 1} more)" if len(bad) > 1 else ""
        print(f"sensornet: error: {n} exited with code {c}{more}: {why} "
              f"(log: {handle.logs[n]})", file=sys.stderr)
        return 2 if c == 2 else 1
    missing = sorted(set(scn.sensor_names) - set(summaries) - killed)
    if missing:
        print(f"sensornet: error: no summary from {', '.join(missing)} (logs in {out / 'logs'})",
              file=sys.stderr)
        return 1
    unscored = [n for n, s in summaries.items() if not _scored(s) and n not in killed]
    if unscored:
        n = unscored[0]
        print(f"sensornet: error: {_why_nothing_scored(n, summaries[n])}"
              + (f" (and {len(unscored) - 1} more peers)" if len(unscored) > 1 else ""),
              file=sys.stderr)
        return 1
    return 0


def _watch_line(handle) -> str | None:
    """The run's network name and the endpoint to join it at, with the command that watches
    it (``sensornet echo``; in secure mode with the keys folder); None if the handle has
    neither."""
    eps = getattr(handle, "endpoints", None) or {}
    router, network = eps.get("router"), getattr(handle, "network", None)
    ep = router or eps.get("world")
    if not network or not ep:
        return None
    where = f"routed through {router}" if router else f"world at {ep}"
    secure = getattr(handle, "secure", None)
    keys = f" --secure {secure} --as MEMBER" if secure is not None else ""
    return (f"network {network}, {where} (watch it: sensornet echo {network} --connect "
            f"{ep}{keys})")


def _run_twin(scn, args: argparse.Namespace) -> int:
    """``sensornet run --sim``: the same peers on the discrete-event twin (no processes)."""
    if args.fault:
        raise UserError("--fault (process faults) needs real processes; drop --sim")
    refuse_used_out(args.out)
    t0 = time.perf_counter()
    result = run_twin(scn, args.run, workers=args.twin_workers)
    summaries = {name: result.summary(name) for name in result.peers}
    run_summary.add_track_summary(
        summaries, {n: core.scorer.results.table(n) for n, core in result.peers.items()},
        next(iter(result.peers.values())).scorer.results.meta() if result.peers else {})
    print(f"twin run {scn.name} (run {args.run}): {len(summaries)} peers, {scn.num_scans} "
          f"scans in {time.perf_counter() - t0:.1f} s (bytes: the encoded messages)")
    print(launcher.format_summary(summaries, cutoff=scn.metrics.ospa_cutoff))
    if launcher.trust_note(summaries):
        print(launcher.trust_note(summaries))
    out = _run_folder(args.out, "sim")
    for name, core in result.peers.items():
        write_part(core.scorer.results, name, out / f"peer-{name}.scans.msgpack")
    report_results(out)
    if result.faults is not None:
        print(f"injected link faults: {result.faults.counts()}")
        result.faults.write_log(out / "faults.csv")
        print(f"fault log: {out / 'faults.csv'}")
    unscored = [n for n, s in summaries.items() if not _scored(s)]
    if unscored:
        print(f"sensornet: error: peer {unscored[0]} scored no scan", file=sys.stderr)
        return 1
    return 0


def cmd_demo(args: argparse.Namespace) -> int:
    """``sensornet run`` of the default scenario with a viewer (``--viewer spawn`` unless told
    otherwise)."""
    args.scenario = DEFAULT_SCENARIO
    args.sim = False
    return cmd_run(args)
