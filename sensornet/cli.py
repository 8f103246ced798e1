"""The ``sensornet`` command line: experiments, scenarios, peers, the world and whole runs.

Every flag either does what it says or is refused: a bad value, a scenario over a budget or a
file that does not load is one line on stderr and exit code 2 (:class:`UserError`); a run that
ends with nothing scored is one line and exit code 1.
"""

from __future__ import annotations

import argparse
import itertools
import json
import math
import os
import re
import shutil
import signal
import socket
import sys
import threading
import time
from pathlib import Path

from peers.session import PEER_WAIT, SessionError  # noqa: E402
from sim.scenario import (
    MAX_ROUNDS,
    MAX_RUNS,
    ScenarioError,
    builtin_scenarios,
    load_scenario,
    parse_overrides,
    scenario_text,
)


class UserError(Exception):
    """A mistake the user can fix (bad file, bad flag): reported in one line, exit code 2."""


# --------------------------------------------------------------------------------------------
# Run folders: unique, and none left empty when a command fails
# --------------------------------------------------------------------------------------------

_CREATED: list[Path] = []
"""Run folders this command created (removed again on failure if nothing was written)."""


def _run_folder(base: str | None, kind: str) -> Path:
    """``--out`` if given, else a new ``runs/<time>-<kind>[-n]`` (two runs in the same second
    get distinct folders: the folder is claimed with an atomic ``mkdir``)."""
    if base:
        root = Path(base)
        if not root.exists():
            root.mkdir(parents=True)
            _CREATED.append(root)
        elif not root.is_dir():
            raise UserError(f"--out {base}: exists and is not a folder")
        return root
    parent = Path("runs")
    parent.mkdir(exist_ok=True)
    stamp = time.strftime("%Y%m%d-%H%M%S")
    for n in itertools.count(1):
        root = parent / (f"{stamp}-{kind}" if n == 1 else f"{stamp}-{kind}-{n}")
        try:
            root.mkdir()
        except FileExistsError:
            continue
        _CREATED.append(root)
        return root
    raise AssertionError("unreachable")


def _remove_empty_run_folders() -> None:
    """Remove the folders this command created that hold no file with content."""
    while _CREATED:
        root = _CREATED.pop()
        try:
            if root.is_dir() and not any(p.is_file() and p.stat().st_size > 0
                                         for p in root.rglob("*")):
                shutil.rmtree(root, ignore_errors=True)
        except OSError:
            pass


def _default_jobs() -> int:
    return max(1, min(os.cpu_count() or 1, 4))


# --------------------------------------------------------------------------------------------
# Flag values: checked by argparse (one line, exit code 2)
# --------------------------------------------------------------------------------------------


def _number(kind: type, minimum: float, strict: bool, maximum: float | None = None):
    """An argparse ``type=``: a finite ``kind`` above (``strict``) or at least ``minimum``,
    and at most ``maximum`` if given."""
    what = "an integer" if kind is int else "a number"
    bound = f"> {minimum:g}" if strict else f">= {minimum:g}"
    if maximum is not None:
        bound += f" and <= {maximum:,g}"

    def parse(text: str):
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be {what} {bound}, got {text!r}") from None
        if (not math.isfinite(value) or value < minimum or (strict and value == minimum)
                or (maximum is not None and value > maximum)):
            raise argparse.ArgumentTypeError(f"must be {what} {bound}, got {text}")
        return value

    parse.__name__ = what  # argparse names the type in some messages
    return parse


POSITIVE_INT = _number(int, 0, strict=True)
NONNEGATIVE_INT = _number(int, 0, strict=False)
POSITIVE_FLOAT = _number(float, 0.0, strict=True)
RUNS = _number(int, 0, strict=True, maximum=MAX_RUNS)
ROUNDS = _number(int, 0, strict=True, maximum=MAX_ROUNDS)


def _network_name(text: str) -> str:
    from protocol.keys import check_name

    try:
        return check_name(text, "network name")
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _router_name(text: str) -> str:
    from protocol.keys import ROUTER_PREFIX, check_name

    try:
        check_name(text, "router name")
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    if not text.startswith(ROUTER_PREFIX):
        raise argparse.ArgumentTypeError(f"invalid router name {text!r}: a router's name "
                                         f"starts with {ROUTER_PREFIX!r}")
    return text


def _run_id(text: str) -> str:
    from protocol.keys import check_run_id

    try:
        return check_run_id(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


_ENDPOINT = re.compile(r"^[a-z][a-z0-9+\-]*/\S+$")


def _endpoint(text: str) -> str:
    """A Zenoh endpoint ``proto/address``, e.g. ``tcp/127.0.0.1:7447``."""
    if not _ENDPOINT.match(text):
        raise argparse.ArgumentTypeError(
            f"{text!r} is not a Zenoh endpoint; use PROTOCOL/ADDRESS, e.g. tcp/127.0.0.1:7447")
    return text


_VIEWER_URL = re.compile(r"^rerun(\+https?)?://(?P<host>\[[^\]]+\]|[^/:\s]+)(:(?P<port>\d+))?"
                         r"/proxy$")


def _viewer(text: str) -> str | None:
    """``spawn``, ``none``, or a Rerun gRPC URL like ``rerun+http://127.0.0.1:9876/proxy``."""
    if text in ("spawn", "none"):
        return text
    if not _VIEWER_URL.match(text):
        raise argparse.ArgumentTypeError(
            f"{text!r} is not 'spawn', 'none' or a Rerun URL like "
            f"rerun+http://127.0.0.1:9876/proxy")
    return text


def _existing_file(text: str) -> str:
    if not Path(text).is_file():
        raise argparse.ArgumentTypeError(f"file {text!r} not found")
    return text


def viewer_reachable(url: str, timeout: float = 1.0) -> bool:
    """Whether something accepts TCP connections where ``url`` points (a quick probe, so an
    absent viewer costs a warning instead of a ten-second stall at the end of every process)."""
    m = _VIEWER_URL.match(url)
    if m is None:
        return False
    host = m.group("host").strip("[]")
    port = int(m.group("port") or (80 if url.startswith("rerun+http:") else 443))
    try:
        with socket.create_connection((host, port), timeout=timeout):
            return True
    except OSError:
        return False


def _resolve_viewer(args: argparse.Namespace) -> None:
    """``--viewer none`` is no viewer; an unreachable URL is a warning and no viewer."""
    viewer = getattr(args, "viewer", None)
    if viewer == "none":
        args.viewer = None
    elif viewer and viewer != "spawn" and not viewer_reachable(viewer):
        print(f"sensornet: warning: no Rerun viewer answers at {viewer}; recording to files "
              f"only", file=sys.stderr)
        args.viewer = None


def _tcp_port(ep: str) -> tuple[str, int] | None:
    m = re.match(r"^(?:tcp|tls)/(\[[^\]]+\]|[^:/]+):(\d+)", ep)
    return (m.group(1).strip("[]"), int(m.group(2))) if m else None


def _check_listen_free(endpoints: list[str]) -> None:
    """A ``--listen`` TCP port already in use is a user error before anything starts."""
    for ep in endpoints:
        hp = _tcp_port(ep)
        if hp is None or hp[1] == 0:
            continue
        family = socket.AF_INET6 if ":" in hp[0] else socket.AF_INET
        with socket.socket(family, socket.SOCK_STREAM) as s:
            s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            try:
                s.bind(hp)
            except OSError as exc:
                raise UserError(f"--listen {ep}: cannot listen there "
                                f"({exc.strerror or exc})") from None


# --------------------------------------------------------------------------------------------
# Budgets: a scenario over one refuses to start, naming the limit and the flag that lifts it
# --------------------------------------------------------------------------------------------

DEFAULT_MAX_POINTS = 5000
"""Expected measurements per scan of one sensor (clutter + targets)."""
DEFAULT_MAX_TARGETS = 500
"""True targets alive at once."""
DEFAULT_MAX_PEERS = 32
"""Peer processes one ``sensornet run`` starts on this machine."""
PROCESS_MB = 200.0
"""Resident memory of one peer or world process with Rerun recording (measured 95-185 MB)."""


def _machine_memory_gb() -> float:
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 1e9
    except (ValueError, OSError, AttributeError):
        return 8.0


def default_memory_gb() -> float:
    """Half of this machine's memory."""
    return round(_machine_memory_gb() / 2, 1)


def points_per_scan(scn) -> dict[str, float]:
    """Expected measurements per scan of each sensor: clutter rate + targets alive at most."""
    targets = targets_at_once(scn)
    return {s.name: s.clutter_rate + targets * s.detection_probability for s in scn.sensors}


def targets_at_once(scn) -> int:
    """The most true targets alive at one scan."""
    if scn.truth != "straight" or not scn.targets:
        return max(1, len(scn.targets))
    edges = sorted([(t.birth_scan, 1) for t in scn.targets]
                   + [(t.death_scan + 1, -1) for t in scn.targets])
    alive = most = 0
    for _, step in edges:
        alive += step
        most = max(most, alive)
    return most


def memory_estimate_gb(scn, workers: int = 1, processes: int = 0) -> float:
    """A rough upper bound: per worker, every scan of a run held at once (16 bytes a point)
    plus the filter update's (measurement x component) working set (about 14 float64 a pair);
    plus :data:`PROCESS_MB` per process for a run over processes."""
    points = points_per_scan(scn)
    scans = scn.num_scans * sum(points.values()) * 16
    components = scn.filter.max_components + len(scn.birth.paper) + targets_at_once(scn)
    update = components * max(points.values(), default=0) * 14 * 8
    per_worker = 0.15e9 + scans + update
    return (max(1, workers) * per_worker + processes * PROCESS_MB * 1e6) / 1e9


def check_budget(scn, args: argparse.Namespace, workers: int = 1, processes: int = 0,
                 wire: bool = False) -> None:
    """Refuse a scenario over a budget (or, over processes, over what a message carries)."""
    max_points = getattr(args, "max_points", DEFAULT_MAX_POINTS)
    max_targets = getattr(args, "max_targets", DEFAULT_MAX_TARGETS)
    for name, n in points_per_scan(scn).items():
        if n > max_points:
            raise UserError(f"sensor {name} expects {n:,.0f} points per scan, over the budget "
                            f"of {max_points} (--max-points N lifts it)")
    targets = targets_at_once(scn)
    if targets > max_targets:
        raise UserError(f"{targets} true targets at once, over the budget of {max_targets} "
                        f"(--max-targets N lifts it)")
    if wire:
        from protocol.codec import DEFAULT_LIMITS

        for name, n in points_per_scan(scn).items():
            high = n + 6 * math.sqrt(n)
            if high > DEFAULT_LIMITS.max_measurements:
                raise UserError(f"sensor {name} expects {n:,.0f} points per scan: more than one "
                                f"scan message carries ({DEFAULT_LIMITS.max_measurements}); "
                                f"run it offline with 'sensornet experiment'")
        if targets >= DEFAULT_LIMITS.max_components:
            raise UserError(f"{targets} true targets at once: more than one truth message "
                            f"carries ({DEFAULT_LIMITS.max_components - 1}); run it offline "
                            f"with 'sensornet experiment'")
    if processes:
        max_peers = getattr(args, "max_peers", DEFAULT_MAX_PEERS)
        if len(scn.sensors) > max_peers:
            raise UserError(f"{len(scn.sensors)} sensors would start {len(scn.sensors)} peer "
                            f"processes on this machine, over the budget of {max_peers} "
                            f"(--max-peers N lifts it)")
    max_gb = getattr(args, "max_memory_gb", None) or default_memory_gb()
    need = memory_estimate_gb(scn, workers, processes)
    if need > max_gb:
        raise UserError(f"estimated memory {need:.1f} GB is over the budget of {max_gb:g} GB "
                        f"(--max-memory-gb X lifts it)")


# --------------------------------------------------------------------------------------------
# Commands
# --------------------------------------------------------------------------------------------


def _warn_fusion(scn) -> None:
    """One line per fusion setting the fusion-quality study measured to hurt."""
    from sim.fusion_advice import fusion_warnings

    for line in fusion_warnings(scn):
        print(f"warning: {line}", file=sys.stderr, flush=True)


def cmd_experiment(args: argparse.Namespace) -> int:
    from sim.experiment import format_table, run_experiment, write_outputs
    from sim.scenario import with_birth_model

    if args.scenario == "seed004" or Path(args.scenario).name == "seed004.toml":
        # seed 004: flooding + clustering against distributed PHD filters (sim/seed004.py)
        from sim.seed004 import SCENARIO as SEED004
        from sim.seed004 import main as seed004_main

        path = SEED004 if args.scenario == "seed004" else Path(args.scenario)
        sets = [a for item in (args.set or []) for a in ("--set", item)]
        return seed004_main(["--scenario", str(path), "--runs", str(args.runs),
                             "--jobs", str(min(args.jobs, args.runs)),
                             "--out", str(_run_folder(args.out, "experiment")), *sets,
                             *(["--quiet"] if args.quiet else [])])
    if _is_seed003(args.scenario):
        # seed 003: PDAF / IMM-PDAF / fuzzy PDA / fuzzy IMM, one and two sensors (sim/seed003.py)
        from sim.seed003 import main as seed003_main

        sets = [a for item in (args.set or []) for a in ("--set", item)]
        if args.scenario != "seed003":  # a file: its settings
            sets += ["--scenario", str(Path(args.scenario).resolve())]
        return seed003_main(["--runs", str(args.runs), "--jobs", str(min(args.jobs, args.runs)),
                             "--csv", str(_run_folder(args.out, "experiment")), *sets,
                             *(["--quiet"] if args.quiet else [])])
    scn = load_scenario(args.scenario, overrides=parse_overrides(args.set or []))
    if scn.extended is not None:  # seed 002: the partitioner comparison (sim/seed002.py)
        from sim.seed002 import main as seed002_main

        sets = [a for item in (args.set or []) for a in ("--set", item)]
        return seed002_main(["--scenario", args.scenario, "--runs", str(args.runs), *sets,
                             *(["--quiet"] if args.quiet else [])])
    if args.fusion:
        from dataclasses import replace

        scn = replace(scn, fusion=replace(scn.fusion, rule=args.fusion))
    _warn_fusion(scn)
    check_budget(scn, args, workers=min(args.jobs, args.runs))
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


def _is_seed003(source: str) -> bool:
    """Seed 003's offline study is its own (sim/seed003.py); the network scenario reads the
    same file (sim/seed003_net.network_document)."""
    return source == "seed003" or Path(source).name == "seed003.toml"


def _load(args: argparse.Namespace, source: str):
    return load_scenario(source, overrides=parse_overrides(getattr(args, "set", None) or []))


def _prepare_peer(args: argparse.Namespace, scn) -> None:
    """Everything about a peer's flags that can be refused before the peer starts."""
    check_budget(scn, args, wire=True)
    if args.color is None:
        args.color = scn.sensor_names.index(args.name)
    _resolve_viewer(args)
    if args.config:
        _existing_file(args.config)


def _security(args: argparse.Namespace, member: str, scn):
    """``--secure DIR`` (or the scenario's ``[security] keys``) of a peer or the world: its
    TLS files and the network's policy."""
    folder = getattr(args, "secure", None) or scn.security
    if not folder:
        return None
    from peers.security import Security, check_endpoints

    sec = Security.load(folder, member, args.network, scn.sensor_names)
    check_endpoints([*(args.listen or []), *(args.connect or [])])
    return sec


def _run_keys(args: argparse.Namespace, scn, out: Path) -> Path | None:
    """``run/demo --secure [DIR]``: the keys folder (fresh keys in <out>/keys without DIR);
    the network name defaults to the one the keys were made for."""
    if args.secure is None:
        return None
    from peers.security import (
        SIGN_KEY,
        WORLD,
        check_endpoints,
        check_private,
        keys_network,
        make_keys,
    )

    check_endpoints([*(args.listen or []), *(args.connect or [])])
    router = ["router"] if getattr(args, "router", False) else []  # sim.launcher.ROUTER
    if args.secure == "":
        args.network = args.network or f"run-{os.urandom(4).hex()}"
        folder = out / "keys"
        make_keys(args.network, [WORLD, *scn.sensor_names, *router], folder)
        return folder.resolve()
    folder = Path(args.secure)
    made_for = keys_network(folder)
    if args.network and args.network != made_for:
        raise UserError(f"--secure {folder}: keys of network {made_for!r}, not of "
                        f"{args.network!r}")
    args.network = made_for
    missing = [m for m in [WORLD, *scn.sensor_names, *router]
               if not all((folder / f"{m}{x}").is_file() for x in (".key", SIGN_KEY))]
    if missing:
        raise UserError(f"--secure {folder}: no key for {', '.join(missing)} (add them with: "
                        f"sensornet keys {made_for} --out {folder} --members "
                        f"{','.join(missing)})")
    for m in [WORLD, *scn.sensor_names, *router]:  # before any process reads one
        for x in (".key", SIGN_KEY):
            check_private(folder / f"{m}{x}")
    return folder.resolve()


def _peer_scenario(args: argparse.Namespace):
    """The scenario of ``sensornet peer``/``host`` with the command line's network and fusion
    settings on top."""
    from dataclasses import replace

    scn = _load(args, args.scenario)
    net = scn.network
    return replace(scn, network=replace(
        net, rounds=args.rounds or net.rounds, omega=args.omega or net.omega,
        policy=args.policy or net.policy, filter=args.filter or net.filter), fusion=replace(
        scn.fusion, rule=args.fusion or scn.fusion.rule,
        level2_pruning=scn.fusion.level2_pruning if args.level2 is None else args.level2))


def _peer_parts(args: argparse.Namespace, scn, name: str, color: int, security=None):
    """Peer ``name``'s core and runtime options from the command line."""
    from dataclasses import replace

    from peers.runtime import RuntimeOptions
    from sim.build import fault_injector
    from sim.peers import make_peer

    speed = args.speed or scn.network.speed
    core = make_peer(scn, name, args.run, network=args.network, speed=speed)
    if args.world_grace:  # a router's outage takes the world's token away for a while
        core.cfg = replace(core.cfg, world_grace=args.world_grace)
    options = RuntimeOptions(security=security,
        listen=tuple(args.listen or ()), connect=tuple(args.connect or ()),
        config_file=args.config, lease_ms=args.lease_ms, gossip=not args.no_gossip,
        out_dir=Path(args.out) if args.out else None, run_id=args.run_id, viewer=args.viewer,
        color_index=color, idle_timeout=args.idle_timeout, rerun=not args.no_rerun,
        save_tracks=args.save_tracks, scan_period=scn.scan_period,
        faults=fault_injector(scn, args.run), recover=args.recover,
        record=_record_meta(args, speed) if args.record else None)
    return core, options


def cmd_peer(args: argparse.Namespace) -> int:
    from peers.runtime import PeerRuntime
    from peers.transport import DuplicatePeer

    scn = _load(args, args.scenario)
    if args.name not in scn.sensor_names:
        raise UserError(f"no sensor named {args.name!r} in {scn.name} "
                        f"(sensors: {', '.join(scn.sensor_names)})")
    scn = _peer_scenario(args)
    _prepare_peer(args, scn)
    security = _security(args, args.name, scn)
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
    from peers.host import PeerHost
    from peers.transport import DuplicatePeer

    scn = _load(args, args.scenario)
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
                                       args.config, args.lease_ms, not args.no_gossip))
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


def cmd_replay(args: argparse.Namespace) -> int:
    from sim.replay import replay

    path = Path(args.path)
    files = sorted((path / "record").glob("*.mcap")) if path.is_dir() else [path]
    if not files or not all(f.is_file() for f in files):
        raise UserError(f"no recording at {path} (record with 'sensornet run --record')")
    if args.peer:
        files = [f for f in files if f.stem.split(".")[0] == f"peer-{args.peer}"]
        if not files:
            raise UserError(f"no recording of peer {args.peer!r} in {path}")
    ok = True
    changed = False
    for i, f in enumerate(files):
        try:
            r = replay(f, args.set or [])
        except (ValueError, ScenarioError, OSError) as exc:
            raise UserError(f"{f}: {exc}") from None
        if i == 0:  # after the first replay: a refused --set is one line, no table head
            print("| peer | file | scans | tracks recorded | replayed identical | "
                  "mean OSPA fused |")
            print("|---|---|---:|---:|---|---:|")
        same = r.identical
        ok = ok and (same or bool(args.set))
        changed = changed or not same
        print(f"| {r.peer} | {f.name} | {r.snapshot['scans']} | {len(r.recorded)} | "
              f"{'yes' if same else 'NO'} | {r.snapshot['mean_ospa_fused']:.2f} |", flush=True)
    if args.set and changed:
        print("(with --set the replay is a what-if run: its tracks are expected to differ)")
    elif args.set:
        print("(with --set the replay is a what-if run; these settings changed none of the "
              "tracks)")
    return 0 if ok else 1


def cmd_world(args: argparse.Namespace) -> int:
    from sim.world_process import WorldError, run_world

    scn = _load(args, args.scenario)
    peers = [p for p in (args.peers or "").split(",") if p]
    unknown = [p for p in peers if p not in scn.sensor_names]
    if unknown:
        raise UserError(f"--peers names unknown sensors {unknown} "
                        f"(sensors: {', '.join(scn.sensor_names)})")
    check_budget(scn, args, wire=True)
    _resolve_viewer(args)
    out = Path(args.out) if args.out else None
    every = args.progress_every

    def progress(k: int) -> None:
        if k % every == 0 or k == scn.num_scans:
            print(f"world: scan {k}/{scn.num_scans} published", flush=True)

    try:
        sent = run_world(scn, args.network, run=args.run, listen=args.listen or [],
                         connect=args.connect or [], config_file=args.config, wait_for=peers,
                         wait_timeout=args.wait, out_dir=out, run_id=args.run_id,
                         viewer=args.viewer, speed=args.speed, rerun=not args.no_rerun,
                         progress=progress, say=lambda line: print(line, flush=True),
                         security=_security(args, "world", scn), recover=args.recover)
    except WorldError as exc:
        raise UserError(str(exc)) from None
    print(f"world: published {sent['scans_published']} scans of {len(scn.sensors)} sensors "
          f"({sent['bytes'] / 1e3:.1f} kB)", flush=True)
    return 0


def _last_line(path: Path) -> str:
    try:
        lines = [ln.strip() for ln in path.read_text(errors="replace").splitlines() if ln.strip()]
    except OSError:
        return ""
    return lines[-1] if lines else ""


def _why_nothing_scored(name: str, s: dict) -> str:
    rejected = {k: v for k, v in (s.get("rejected") or {}).items() if v}
    if rejected:
        parts = ", ".join(f"{v} {k}" for k, v in sorted(rejected.items()))
        return f"peer {name} scored no scan: it rejected {parts} messages"
    if s.get("stop_reason"):
        return f"peer {name} scored no scan (stopped: {s['stop_reason']})"
    return f"peer {name} scored no scan"


def _scored(s: dict) -> bool:
    vals = [s.get("mean_ospa_local"), s.get("mean_ospa_fused")]
    return bool(s.get("scans")) and any(v is not None and math.isfinite(v) for v in vals)


def _check_hosted_faults(pfaults, hosts: dict[str, list[str]], args) -> None:
    """With hosts (``--per-process N``, N > 1) only ``kill`` (one peer, in its host) and
    ``killhost`` (a whole host, named h1, h2, ...) of the peers' faults (the router's as
    ever); ``killhost`` only with hosts."""
    from sim.launcher import HOSTED_ACTIONS

    for f in pfaults:
        if f.action == "killhost" and not hosts:
            raise UserError(f"--fault killhost:{f.peer}@{f.scan} needs hosts: add "
                            f"--per-process N (N > 1)")
        if f.action == "killhost" and f.peer not in hosts:
            raise UserError(f"--fault names unknown host {f.peer!r} (hosts: "
                            f"{', '.join(hosts)})")
        if hosts and f.action not in HOSTED_ACTIONS and f.peer != "router":
            raise UserError(f"--fault {f.action}:{f.peer}@{f.scan} with --per-process: only "
                            f"{' and '.join(HOSTED_ACTIONS)} so far")
    if hosts and getattr(args, "sim", False):
        raise UserError("--per-process needs real processes; drop --sim")


def cmd_run(args: argparse.Namespace) -> int:
    from sim.launcher import (
        ProcessFault,
        format_summary,
        host_groups,
        hosts_line,
        inject_process_faults,
        merge_recordings,
        read_summaries,
        start_run,
        wait_run,
    )

    scn = _load(args, args.scenario)
    _warn_fusion(scn)
    try:
        pfaults = [ProcessFault.parse(f) for f in args.fault or []]
    except ValueError as exc:
        raise UserError(str(exc)) from None
    if scn.network.router and hasattr(args, "router") and not args.router:
        args.router = "[network] router = true"  # the scenario's routed topology
    routed = {"router"} if getattr(args, "router", False) else set()  # restart:router@K
    per_process = getattr(args, "per_process", 1) or 1
    hosts = host_groups(scn.sensor_names, per_process)
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
    if getattr(args, "sim", False):
        for flag in ("listen", "connect", "config", "run_id", "viewer", "lease_ms", "record"):
            if getattr(args, flag, None):
                raise UserError(f"--{flag.replace('_', '-')} needs real processes; drop --sim")
        if args.secure is not None:
            raise UserError("--secure needs real processes; drop --sim")
        if args.router is True:
            raise UserError("--router needs real processes; drop --sim")
        check_budget(scn, args)
        return _run_twin(scn, args)
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
    out = _run_folder(args.out, "run")
    secure = _run_keys(args, scn, out)
    speed = args.speed or scn.network.speed
    expected = scn.num_scans * scn.scan_period / speed
    how = f"in {len(hosts)} host processes" if hosts else "as processes"
    print(f"run {scn.name}: world + {len(scn.sensors)} peers {how} over Zenoh on "
          f"127.0.0.1, {scn.num_scans} scans at {speed:g}x ({expected:.0f} s of scans, plus a "
          f"few seconds to start {len(hosts or scn.sensors) + 1} processes); output in {out}",
          flush=True)
    if hosts:
        print(hosts_line(hosts), flush=True)
    if secure is not None:
        made = " (fresh keys made for this run)" if args.secure == "" else ""
        print(f"secure mode: mutual TLS + access control on network {args.network}, keys in "
              f"{secure}{made}", flush=True)
    viewer = args.viewer
    if viewer == "spawn":  # one viewer for the whole run; every process streams to it
        from peers.rerun_sink import spawn_viewer

        viewer = "rerun+http://127.0.0.1:9876/proxy" if spawn_viewer() else None
    stop = threading.Event()  # SIGINT / SIGTERM: stop the children, then report as usual
    caught: list[str] = []

    def on_signal(signum, frame) -> None:
        caught.append(signal.Signals(signum).name)
        stop.set()

    previous = {s: signal.signal(s, on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
    injector = None
    try:
        handle = start_run(scn, args.scenario, out, network=args.network, overrides=args.set,
                           viewer=viewer, run=args.run, speed=args.speed,
                           rerun=not args.no_rerun, lease_ms=args.lease_ms,
                           sparse=args.sparse, listen=args.listen, connect=args.connect,
                           config=args.config, run_id=args.run_id, secure=secure,
                           router=bool(getattr(args, "router", False)),
                           peer_args={n: ["--record"] for n in scn.sensor_names}
                           if args.record else None, per_process=per_process)
        if getattr(args, "router", False):
            why = f" ({args.router})" if isinstance(args.router, str) else ""
            print(f"routed{why}: the world and every peer are clients of the run's router "
                  f"(sensornet router) at {handle.endpoints['router']}", flush=True)
        if pfaults:
            injector = threading.Thread(target=inject_process_faults, daemon=True,
                                        args=(handle, pfaults, scn.sensor_names[0], stop))
            injector.start()
        codes = wait_run(handle, timeout=expected + args.timeout, stop=stop)
    finally:
        stop.set()
        if injector is not None:
            injector.join(timeout=5)
        for s, h in previous.items():
            signal.signal(s, h)
    summaries = read_summaries(out, scn.sensor_names)
    if summaries:
        from sim.launcher import trust_note

        print(format_summary(summaries))
        if trust_note(summaries):
            print(trust_note(summaries))
        if not caught and not pfaults and scn.faults is None:  # faults: deadlines on purpose
            from sim.launcher import realtime_note

            note = realtime_note(summaries, scn.scan_period / speed, speed, os.cpu_count())
            if note:
                print(note)
    faults_file = out / "process-faults.json"
    if pfaults and faults_file.is_file():
        from sim.launcher import fault_report

        print(fault_report(json.loads(faults_file.read_text()), summaries))
    _report_results(out)
    rec = merge_recordings(out)
    if rec is not None:
        print(f"recording: {rec}  (view it with: rerun {rec})")
    elif not args.no_rerun:
        print(f"recording: {out / 'rerun'} (the .rrd files could not be merged)")
    if caught:
        print(f"sensornet: stopped by {caught[0]}; every process stopped, output in {out}",
              file=sys.stderr)
        return 0
    world = codes.get("world")
    if world not in (0, None):
        why = _last_line(handle.logs["world"]).removeprefix("sensornet: error: ")
        print(f"sensornet: error: the world failed (exit {world}): {why} "
              f"(log: {handle.logs['world']})", file=sys.stderr)
        return 2 if world == 2 else 1
    killed = {f.peer for f in pfaults if f.action in ("kill", "term", "restart", "killhost")}
    killed |= {p for f in pfaults if f.action == "killhost" for p in hosts[f.peer]}
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


def _report_results(out: Path) -> Path | None:
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


def _run_twin(scn, args: argparse.Namespace) -> int:
    """``sensornet run --sim``: the same peers on the discrete-event twin (no processes)."""
    from peers.scan_results import write_part
    from sim.launcher import format_summary
    from sim.twin import run_twin

    if args.fault:
        raise UserError("--fault (process faults) needs real processes; drop --sim")
    t0 = time.perf_counter()
    result = run_twin(scn, args.run)
    summaries = {name: result.summary(name) for name in result.peers}
    print(f"twin run {scn.name} (run {args.run}): {len(summaries)} peers, {scn.num_scans} "
          f"scans in {time.perf_counter() - t0:.1f} s (bytes: the encoded messages)")
    print(format_summary(summaries))
    from sim.launcher import trust_note

    if trust_note(summaries):
        print(trust_note(summaries))
    out = _run_folder(args.out, "sim")
    for name, core in result.peers.items():
        write_part(core.scorer.results, name, out / f"peer-{name}.scans.msgpack")
    _report_results(out)
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
    """``sensornet run seed000`` with a viewer (``--viewer spawn`` unless told otherwise)."""
    args.scenario = "seed000"
    args.sim = False
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
    base = parse_overrides(args.set or [])
    scn = load_scenario(args.scenario, overrides=base)
    if args.real:
        check_budget(scn, args, processes=len(scn.sensors) + 1, wire=True)
    else:
        check_budget(scn, args, workers=args.jobs)
    rows = sweep(args.scenario, args.param, values, policies, args.runs, base=base,
                 real=args.real, jobs=args.jobs, progress=not args.quiet)
    print(format_summary(args.param, summarise(rows)))
    for path in write_outputs(rows, args.param, _run_folder(args.out, "sweep")):
        print(f"wrote {path}")
    return 0


def cmd_campaign(args: argparse.Namespace) -> int:
    from sim.campaign import (
        default_folder,
        format_status,
        load_campaign,
        recorded_runs,
        run_campaign,
        status,
    )

    c = load_campaign(args.file, runs=args.runs)
    folder = Path(args.out) if args.out else default_folder(c)
    if args.status:  # against the plan the folder records (its last run's), not --runs
        planned = recorded_runs(folder)
        if planned is not None and planned != c.runs:
            c = load_campaign(args.file, runs=planned)
        print(format_status(c, folder, status(c, folder)))
        if args.runs is not None and args.runs != c.runs:
            print(f"(--runs {args.runs} not counted: the folder's plan is {c.runs} runs per "
                  f"cell; running with --runs {args.runs} makes it the plan)")
        return 0
    if args.dask and args.scheduler:
        raise UserError("--dask local and --scheduler: give one of them")
    dask = "local" if args.dask else args.scheduler
    jobs = args.jobs or (1 if c.runner == "real" and dask is None else os.cpu_count() or 1)

    def interrupt(signum, frame) -> None:  # SIGTERM as Ctrl-C: cancel, keep what finished
        raise KeyboardInterrupt

    old = signal.signal(signal.SIGTERM, interrupt)
    try:
        summary = run_campaign(c, folder, jobs=jobs, dask=dask, progress=not args.quiet,
                               stop_after=args.stop_after)
    except (ImportError, ConnectionError) as exc:
        raise UserError(str(exc)) from None
    finally:
        signal.signal(signal.SIGTERM, old)
    print(format_status(c, folder, status(c, folder)))
    rate = summary.ran / summary.seconds if summary.seconds > 0 else 0.0
    print(f"ran {summary.ran} runs in {summary.seconds:.1f} s ({rate:.2f} runs/s, "
          f"{summary.cpu_seconds / max(summary.ran, 1):.2f} CPU s per run, "
          f"{summary.cpu_seconds / max(summary.seconds, 1e-9):.2f} cores busy), "
          f"{summary.skipped} already stored")
    if summary.stopped:
        print(f"stopped after {summary.ran} runs: run the same command again to finish")
        return 1
    print(f"report: sensornet report {folder}")
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
            print(topics(tap, args.duration), flush=True)
        finally:
            tap.close()
        return 0
    except SessionError as exc:
        raise UserError(str(exc)) from None


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


def cmd_report(args: argparse.Namespace) -> int:
    from sim.report import write_report

    try:
        written = write_report(args.dir, args.out, html=args.html)
    except ImportError as exc:
        raise UserError(str(exc)) from None
    for path in written:
        print(f"wrote {path}")
    return 0


def cmd_router(args: argparse.Namespace) -> int:
    """``sensornet router``: a Zenoh router (see :mod:`sim.router`)."""
    from sim.router import serve

    serve(args.listen, args.connect or [], args.config, args.secure, args.name, args.network)
    return 0


def cmd_keys(args: argparse.Namespace) -> int:
    """``sensornet keys NETWORK --out DIR``: the network's CA and one key + certificate per
    member (every peer and the world), plain PEM files (see :mod:`peers.security`)."""
    from peers.security import WORLD, SecurityError, make_keys

    if args.members:
        members = [m.strip() for m in args.members.split(",") if m.strip()]
    else:
        members = [WORLD, *_load(args, args.scenario).sensor_names]
    hosts = [h.strip() for h in (args.hosts or "localhost,127.0.0.1").split(",") if h.strip()]
    try:
        paths = make_keys(args.network, members, Path(args.out), days=args.days, hosts=hosts,
                          overwrite=args.rotate)
    except (SecurityError, ValueError) as exc:
        raise UserError(str(exc)) from None
    print(f"keys for network {args.network}: CA and {len(members)} members "
          f"({', '.join(members)}) in {args.out}")
    print(f"  {len(paths)} files; give each member only ca.pem, members.json (the roster of "
          "signing keys), <name>.pem, <name>.key and <name>.ed25519; keep ca.key apart")
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
    e.add_argument("scenario", nargs="?", default="seed000",
                   help="scenario file (.toml) or built-in name (default seed000)")
    e.add_argument("--birth", choices=["paper", "truth", "both"],
                   help="birth model (default: the scenario's)")
    e.add_argument("--fusion", choices=["gci", "aa", "hybrid", "none"],
                   help="override the fusion rule")
    e.add_argument("--set", action="append", metavar="KEY=VALUE",
                   help="override a scenario value, e.g. --set fusion.level2_pruning=false "
                        "or --set sensors.s1.clutter_rate=50 (repeatable)")
    add_mc_flags(e, 50)
    add_budget_flags(e)
    e.set_defaults(func=cmd_experiment)

    def add_net_flags(sp: argparse.ArgumentParser, network_required: bool,
                      launcher: bool = False) -> None:
        if launcher:
            sp.add_argument("--network", type=_network_name,
                            help="network name: the key space of this run (default: a fresh "
                                 "random name)")
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
                             "(default: stop at once)")
        sp.add_argument("--filter", choices=["gmphd", "imm-pf", "imm-ekf"],
                        help="local filter (default: the scenario's network.filter)")
        sp.add_argument("--fusion", choices=["gci", "aa", "hybrid", "ratio", "none"],
                        help="fusion rule ('ratio': the particle fusion rule, IMM peers only)")
        sp.add_argument("--rounds", type=ROUNDS,
                        help=f"consensus rounds per scan (1..{MAX_ROUNDS})")
        sp.add_argument("--omega", choices=["metropolis", "uniform", "det", "chernoff"])
        sp.add_argument("--policy", choices=["nale", "drop-late", "as-is"])
        sp.add_argument("--level2", dest="level2", action="store_true", default=None,
                        help="level-2 pruning before publishing")
        sp.add_argument("--no-level2", dest="level2", action="store_false")
        sp.add_argument("--lease-ms", type=POSITIVE_INT,
                        help="Zenoh lease (how fast a frozen peer is seen)")
        sp.add_argument("--color", type=NONNEGATIVE_INT, help=argparse.SUPPRESS)  # default:
        # the sensor's index in the scenario, the colour the world's legend and plots give it
        sp.add_argument("--no-gossip", action="store_true",
                        help="link only to the --connect endpoints (no Zenoh gossip discovery)")
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
    pe.add_argument("--scenario", default="seed000", help="scenario file or built-in name")
    add_peer_flags(pe)
    pe.set_defaults(func=cmd_peer)

    ho = sub.add_parser("host", help="run several sensor peers in one process over one Zenoh "
                        "session (a peer host)")
    ho.add_argument("scenario", nargs="?", default="seed000",
                    help="scenario file or built-in name")
    ho.add_argument("--peers", required=True,
                    help="comma-separated sensors this host runs, e.g. s1,s2,s3")
    ho.add_argument("--name", type=_network_name, default="h1",
                    help="the host's name in its log lines (default h1)")
    add_peer_flags(ho)
    ho.set_defaults(func=cmd_host)

    w = sub.add_parser("world", help="play a scenario's truth and scans over Zenoh")
    w.add_argument("scenario", nargs="?", default="seed000")
    add_net_flags(w, network_required=True)
    w.add_argument("--peers", help="comma-separated peers to wait for before starting")
    w.add_argument("--wait", type=POSITIVE_FLOAT, default=PEER_WAIT,
                   help=f"seconds to wait for the peers (default {PEER_WAIT:g}; the run starts "
                        "as soon as they are ready)")
    w.add_argument("--run", type=NONNEGATIVE_INT, default=0,
                   help="Monte Carlo run index (random draws)")
    w.add_argument("--progress-every", type=POSITIVE_INT, default=10, metavar="N",
                   help="print a progress line every N scans (default 10)")
    add_budget_flags(w)
    w.set_defaults(func=cmd_world)

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
        sp.add_argument("--per-process", type=POSITIVE_INT, default=1, metavar="N",
                        help="peers per process: hosts h1, h2, ... of N peers each, one Zenoh "
                             "session per host (sensornet host); default 1, a process per "
                             "peer")
        add_budget_flags(sp, peers=True)

    r = sub.add_parser("run", help="run a scenario: world + peers as processes over Zenoh")
    r.add_argument("scenario", nargs="?", default="seed000")
    add_run_flags(r)
    r.add_argument("--sim", action="store_true",
                   help="run the discrete-event twin instead of processes (fast, no network)")
    r.set_defaults(func=cmd_run)

    d = sub.add_parser("demo", help="'run seed000' with a live Rerun viewer: world + 3 peers "
                       "over Zenoh, summary")
    add_run_flags(d)
    d.set_defaults(func=cmd_demo, viewer="spawn")

    rp = sub.add_parser("replay", help="feed a recorded run through the peers offline: the "
                        "same fused tracks bit for bit, or a what-if with --set")
    rp.add_argument("path", help="a run folder (its record/*.mcap) or one .mcap file")
    rp.add_argument("--peer", help="only this peer's recording")
    rp.add_argument("--set", action="append", metavar="KEY=VALUE",
                    help="change a setting for the replay (what-if), e.g. fusion.cardinality=emd "
                         "(not network.rounds: the recording holds only the rounds it had)")
    rp.set_defaults(func=cmd_replay)

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
    add_budget_flags(sw, peers=True)
    sw.set_defaults(func=cmd_sweep)

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
    ca.set_defaults(func=cmd_campaign)

    rp = sub.add_parser("report", help="markdown + PNG report of a campaign folder")
    rp.add_argument("dir", help="campaign folder (runs/campaign-<name>)")
    rp.add_argument("--out", help="report folder (default: DIR/report)")
    rp.add_argument("--html", action="store_true",
                    help="also report.html beside report.md: one self-contained file (tables, "
                         "every figure embedded)")
    rp.set_defaults(func=cmd_report)

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
            ec.set_defaults(key="**", count=None)
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

    s = sub.add_parser("scenario", help="list or print built-in scenario files")
    s.add_argument("action", choices=["list", "show"])
    s.add_argument("name", nargs="?", default="seed000")
    s.set_defaults(func=cmd_scenario)

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
    ro.set_defaults(func=cmd_router)

    k = sub.add_parser("keys", help="make a network's CA and each member's key and "
                       "certificate (for --secure)")
    k.add_argument("network", type=_network_name, help="the network the keys are for")
    k.add_argument("--out", required=True, help="folder for the PEM files")
    k.add_argument("--scenario", default="seed000",
                   help="members: the world and the scenario's sensors (default seed000)")
    k.add_argument("--members", help="comma-separated member names instead, e.g. "
                   "world,s1,s2,s3")
    k.add_argument("--hosts", help="host names and addresses the certificates are valid for "
                   "(default localhost,127.0.0.1)")
    k.add_argument("--days", type=POSITIVE_INT, default=365, help="validity (default 365)")
    k.add_argument("--rotate", action="store_true",
                   help="issue new keys for the named members (same CA)")
    k.set_defaults(func=cmd_keys, set=None)
    return p


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    code = 1
    try:
        code = int(args.func(args) or 0)
        return code
    except (ScenarioError, UserError, SessionError) as exc:
        code = 2
        print(f"sensornet: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        code = 130
        print("sensornet: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # e.g. `sensornet experiment | head`: the reader left; be quiet
        code = 141
        try:
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, sys.stdout.fileno())
        except OSError:
            pass
        return 141
    finally:
        if code != 0:
            _remove_empty_run_folders()
        _CREATED.clear()


if __name__ == "__main__":
    sys.exit(main())
