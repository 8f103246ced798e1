"""``peer`` and ``host``: one sensor peer, or several in one process over one Zenoh session."""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import sys
from dataclasses import replace
from pathlib import Path

from sensornet.cli.budgets import check_budget
from sensornet.cli.common import UserError, _existing_file, _resolve_viewer
from sensornet.cli.scenarios import load
from sensornet.cli.security import member_security
from sensornet.peers.host import PeerHost
from sensornet.peers.runtime import PeerRuntime, RuntimeOptions
from sensornet.peers.session import ANNOUNCE
from sensornet.peers.transport import DuplicatePeer
from sensornet.sim.run.peers import make_peer
from sensornet.sim.scenario import scenario_text
from sensornet.sim.world.build import fault_injector


def _prepare_peer(args: argparse.Namespace, scn) -> None:
    """Everything about a peer's flags that can be refused before the peer starts."""
    check_budget(scn, args, wire=True)
    if args.color is None:
        args.color = scn.sensor_names.index(args.name)
    _resolve_viewer(args)
    if args.config:
        _existing_file(args.config)


def _peer_scenario(args: argparse.Namespace):
    """The scenario of ``sensornet peer``/``host`` with the command line's network and fusion
    settings on top."""
    scn = load(args, args.scenario)
    net = scn.network
    return replace(scn, network=replace(
        net, rounds=args.rounds or net.rounds, omega=args.omega or net.omega,
        policy=args.policy or net.policy, filter=args.filter or net.filter), fusion=replace(
        scn.fusion, rule=args.fusion or scn.fusion.rule,
        level2_pruning=scn.fusion.level2_pruning if args.level2 is None else args.level2))


def _gossip(args: argparse.Namespace) -> bool | str:
    """The session's gossip mode from ``--no-gossip`` / ``--no-autoconnect``."""
    if args.no_gossip:
        return False
    return ANNOUNCE if args.no_autoconnect else True


def _peer_parts(args: argparse.Namespace, scn, name: str, color: int, security=None):
    """Peer ``name``'s core and runtime options from the command line."""
    speed = args.speed or scn.network.speed
    core = make_peer(scn, name, args.run, network=args.network, speed=speed)
    if args.world_grace:  # a router's outage takes the world's token away for a while
        core.cfg = replace(core.cfg, world_grace=args.world_grace)
    options = RuntimeOptions(security=security,
        listen=tuple(args.listen or ()), connect=tuple(args.connect or ()),
        config_file=args.config, lease_ms=args.lease_ms, gossip=_gossip(args),
        out_dir=Path(args.out) if args.out else None, run_id=args.run_id, viewer=args.viewer,
        color_index=color, idle_timeout=args.idle_timeout, rerun=not args.no_rerun,
        save_tracks=args.save_tracks, scan_period=scn.scan_period,
        faults=fault_injector(scn, args.run), recover=args.recover,
        record=_record_meta(args, speed) if args.record else None, ros2=ros2_domain(scn))
    return core, options


def ros2_domain(scn) -> int | None:
    """The ROS 2 domain the scenario's ``network.ros2`` publishes on, or None (off); a clear
    error when it is on and ``rosbags`` (the ``[ros2]`` extra) is missing."""
    if not scn.network.ros2:
        return None
    if importlib.util.find_spec("rosbags") is None:
        raise UserError("network.ros2 (--ros2) needs rosbags: pip install 'sensornet[ros2]'")
    return scn.network.ros2_domain


def _record_meta(args: argparse.Namespace, speed: float) -> dict[str, str]:
    """What ``sensornet replay`` needs to rebuild this peer: the scenario's text and every
    setting the command line changed, as ``--set`` items."""
    src = Path(args.scenario)
    text = src.read_text() if src.is_file() else scenario_text(args.scenario)
    sets = list(args.set or [])
    for flag, key in (("rounds", "network.rounds"), ("omega", "network.omega"),
                      ("policy", "network.policy"), ("filter", "network.filter"),
                      ("fusion", "fusion.rule")):
        value = getattr(args, flag, None)
        if value is not None:
            sets.append(f"{key}={json.dumps(value)}")
    if getattr(args, "level2", None) is not None:
        sets.append(f"fusion.level2_pruning={'true' if args.level2 else 'false'}")
    return {"scenario_text": text, "scenario_file": src.name if src.is_file() else
            f"{args.scenario}.toml", "overrides": json.dumps(sets), "run": str(args.run),
            "speed": str(speed)}


def cmd_peer(args: argparse.Namespace) -> int:
    scn = load(args, args.scenario)
    if args.name not in scn.sensor_names:
        raise UserError(f"no sensor named {args.name!r} in {scn.name} "
                        f"(sensors: {', '.join(scn.sensor_names)})")
    scn = _peer_scenario(args)
    _prepare_peer(args, scn)
    security = member_security(args, args.name, scn)
    core, options = _peer_parts(args, scn, args.name, args.color, security)
    runtime = PeerRuntime(core, options)
    print(f"peer {args.name}: network {args.network}, neighbours "
          f"{', '.join(core.consensus.o.neighbours) or 'none'}", flush=True)
    try:
        code = runtime.run()
    except DuplicatePeer as exc:
        raise UserError(str(exc)) from None
    s = runtime.summary()
    if getattr(core, "world", None) == "unseen" and not s["scans"]:
        if s["stop_reason"].startswith("no input"):  # the idle timeout: say so, no "OSPA nan"
            print(f"peer {args.name}: no world on network {args.network} within "
                  f"{args.idle_timeout:g} s: nothing was tracked", flush=True)
            return 1
        print(f"peer {args.name}: stopped ({s['stop_reason']}) before a world appeared on "
              f"network {args.network}: nothing was tracked", flush=True)
        return code
    print(f"peer {args.name}: stopped ({s['stop_reason']}); {s['scans']} scans, mean OSPA "
          f"local {s['mean_ospa_local']:.1f} fused {s['mean_ospa_fused']:.1f}, "
          f"rejected {s['rejected_total']}", flush=True)
    return code


def cmd_host(args: argparse.Namespace) -> int:
    """``sensornet host --peers s1,s2 SCENARIO``: several peers in one process, one session."""
    scn = load(args, args.scenario)
    names = [n for n in (args.peers or "").split(",") if n]
    unknown = [n for n in names if n not in scn.sensor_names]
    if not names or unknown:
        raise UserError(f"--peers needs sensors of {scn.name}"
                        + (f" ({', '.join(unknown)} unknown)" if unknown else "")
                        + f" (sensors: {', '.join(scn.sensor_names)})")
    if len(set(names)) != len(names):
        raise UserError(f"--peers names a peer twice: {args.peers}")
    if args.secure or scn.security:
        raise UserError("a host has one Zenoh session, so one TLS identity: run secure peers "
                        "one per process (sensornet peer)")
    scn = _peer_scenario(args)
    check_budget(scn, args, wire=True)
    _resolve_viewer(args)
    if args.config:
        _existing_file(args.config)
    parts = [_peer_parts(args, scn, n, scn.sensor_names.index(n)) for n in names]
    host = PeerHost(args.name, parts, (list(args.listen or ()), list(args.connect or ()),
                                       args.config, args.lease_ms, _gossip(args)))
    print(f"host {args.name}: network {args.network}, peers {', '.join(names)} (pid "
          f"{os.getpid()})", flush=True)
    for core, _ in parts:
        print(f"peer {core.name}: network {args.network}, neighbours "
              f"{', '.join(core.consensus.o.neighbours) or 'none'}", flush=True)
    host.read_commands(sys.stdin)
    try:
        code = host.run()
    except DuplicatePeer as exc:
        raise UserError(str(exc)) from None
    print(f"host {args.name}: stopped; {len(names)} peers", flush=True)
    return code
