"""``run``'s checks before anything starts: the process faults and hosts of a run, the flags
``--sim`` or a real run rule out, and an ``--out`` that holds a run already. Each refusal is one
:class:`~sensornet.cli.common.UserError` line."""

from __future__ import annotations

import argparse
from pathlib import Path

from sensornet.cli.budgets import check_budget
from sensornet.cli.common import UserError, _check_listen_free, _resolve_viewer
from sensornet.sim.run import launcher
from sensornet.sim.run.packing import choose, scenario_load
from sensornet.sim.world.build import adjacency

RUN_FILES = ("commands.json", "results.parquet", "logs", "peer-*.json", "*.scans.msgpack")
"""What a run leaves in its folder: an ``--out`` holding any of them holds a run already."""


def refuse_used_out(base: str | None) -> None:
    """A second run into a folder that holds one would mix the two (summaries, per-scan parts,
    logs): refuse in one line, naming what is there."""
    if not base or not Path(base).is_dir():
        return
    found = sorted({q.name for pat in RUN_FILES for q in Path(base).glob(pat)})
    if found:
        raise UserError(f"--out {base} already holds a run ({', '.join(found[:3])}"
                        f"{', ...' if len(found) > 3 else ''}): give a new folder, or leave "
                        f"--out out for a fresh runs/<time>-run")


def _check_hosted_faults(pfaults, hosts: dict[str, list[str]], args) -> None:
    """With hosts (``--per-process N``, N > 1) only ``kill`` (one peer, in its host) and
    ``killhost`` (a whole host, named h1, h2, ...) of the peers' faults (the router's as
    ever); ``killhost`` only with hosts."""
    for f in pfaults:
        if f.action == "killhost" and not hosts:
            raise UserError(f"--fault killhost:{f.peer}@{f.scan} needs hosts: add "
                            f"--per-process N (N > 1)")
        if f.action == "killhost" and f.peer not in hosts:
            raise UserError(f"--fault names unknown host {f.peer!r} (hosts: "
                            f"{', '.join(hosts)})")
        if hosts and f.action not in launcher.HOSTED_ACTIONS and f.peer != "router":
            raise UserError(f"--fault {f.action}:{f.peer}@{f.scan} with --per-process: only "
                            f"{' and '.join(launcher.HOSTED_ACTIONS)} so far")
    if hosts and getattr(args, "sim", False):
        raise UserError("--per-process needs real processes; drop --sim")


def _packing(args: argparse.Namespace, scn, pfaults) -> int:
    """``--per-process``, or the automatic packing (sim.run.packing), saying so in one line."""
    solo = [f"{f.action}:{f.peer}" for f in pfaults
            if f.action not in launcher.HOSTED_ACTIONS and f.peer != "router"]
    asked = getattr(args, "per_process", None)
    if getattr(args, "sim", False):  # the twin: no processes to pack
        return asked or 1
    why_not = ("secure mode" if args.secure is not None or scn.security else
               f"--fault {solo[0]}" if solo else "")
    packing = choose(len(scn.sensors), asked, why_not, load=scenario_load(scn))
    if packing.line:
        print(packing.line, flush=True)
    return packing.per_process


def plan_processes(args: argparse.Namespace, scn) -> tuple[list, int, dict[str, list[str]]]:
    """The process faults (``--fault``), peers per process and hosts of the run, every fault
    checked against them (known peer or host, scheduled before the last scan)."""
    try:
        pfaults = [launcher.ProcessFault.parse(f) for f in args.fault or []]
    except ValueError as exc:
        raise UserError(str(exc)) from None
    if scn.network.router and hasattr(args, "router") and not args.router:
        args.router = "[network] router = true"  # the scenario's routed topology
    routed = {"router"} if getattr(args, "router", False) else set()  # restart:router@K
    per_process = _packing(args, scn, pfaults)
    hosts = launcher.host_groups(scn.sensor_names, per_process, adjacency(scn)[1])
    _check_hosted_faults(pfaults, hosts, args)
    unknown = sorted({f.peer for f in pfaults if f.action != "killhost"}
                     - set(scn.sensor_names) - routed)
    if unknown:
        raise UserError(f"--fault names unknown peers {unknown} "
                        f"(peers: {', '.join(scn.sensor_names)})")
    late = [f for f in pfaults if f.scan >= scn.num_scans]
    if late:  # it would be accepted and never fire (or fire as the run ends)
        f = late[0]
        raise UserError(f"--fault {f.action}:{f.peer}@{f.scan}: scan {f.scan} is at or after "
                        f"the run's last scan ({scn.name} has {scn.num_scans} scans); "
                        f"schedule it before scan {scn.num_scans}")
    return pfaults, per_process, hosts


def refuse_real_only_flags(args: argparse.Namespace) -> None:
    """``--sim`` has no processes: refuse every flag that only processes use."""
    for flag in ("listen", "connect", "config", "run_id", "viewer", "lease_ms", "record"):
        if getattr(args, flag, None):
            raise UserError(f"--{flag.replace('_', '-')} needs real processes; drop --sim")
    if args.secure is not None:
        raise UserError("--secure needs real processes; drop --sim")
    if args.router is True:
        raise UserError("--router needs real processes; drop --sim")


def check_real_run(args: argparse.Namespace, scn, hosts: dict[str, list[str]]) -> None:
    """Budgets, free ``--listen`` ports, the viewer, the scenario's ``[security]`` keys, and
    the flags hosts or a router rule out; before anything starts."""
    check_budget(scn, args, processes=len(hosts or scn.sensors) + 1, wire=True)
    _check_listen_free(args.listen or [])
    _resolve_viewer(args)
    if args.secure is None and scn.security:  # the scenario's [security] keys
        args.secure = scn.security
    if hosts and args.secure is not None:
        raise UserError("--per-process: a host has one Zenoh session, so one TLS identity: "
                        "no --secure (run secure peers one per process)")
    if getattr(args, "router", False):
        clash = [f for f in ("config", "listen", "sparse") if getattr(args, f, None)]
        if clash:
            why = args.router if isinstance(args.router, str) else "--router"
            raise UserError(f"{why} makes every process a client of the run's router: "
                            f"drop --{clash[0]}")
