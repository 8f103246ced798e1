"""Start a whole network run as separate OS processes: the world and one peer per sensor.

Every process is ``python -m sensornet world|peer ...`` with explicit loopback endpoints on
free ports, its log in ``<run>/logs/``, its summary in the run folder. The Rerun recording is
built by a view process of its own (``sensornet view``, :mod:`sensornet.view`) that only
subscribes: the world and the peers log nothing to Rerun (issue 38). Whatever
happens (an error, Ctrl-C, SIGTERM, a timeout), every child is stopped before this returns:
:func:`wait_run` takes a ``stop`` event that the caller sets from its signal handler, and then
sends SIGTERM to every child (SIGKILL after a grace period), so the peers still write their
summaries and ``.rrd`` files and the recording can be merged.
"""

from __future__ import annotations

import json
import subprocess
import sys
import threading
import time
import uuid
from pathlib import Path

import numpy as np
from sensornet.peers.security import OBSERVER, tls_endpoint
from sensornet.peers.session import (
    DEFAULT_LEASE_MS,
    MAX_MESSAGE_BYTES,
    endpoint,
    free_port,
)
from sensornet.sim.run.packing import groups_for
from sensornet.sim.run.process_faults import (  # noqa: F401  (the names other modules import from here)
    HOSTED_ACTIONS,
    PROCESS_ACTIONS,
    ProcessFault,
    fault_report,
    inject_process_faults,
)
from sensornet.sim.run.run_handle import (  # noqa: F401
    ROUTER,
    ROUTER_GRACE,
    VIEW_WAIT,
    WORLD_STARTED,
    RunHandle,
)
from sensornet.sim.run.run_summary import (  # noqa: F401  (the names other modules import from here)
    REALTIME_DEADLINE_SHARE,
    format_summary,
    merge_recordings,
    read_summaries,
    realtime_note,
    summary_files,
    trust_note,
)
from sensornet.sim.scenario import Scenario
from sensornet.sim.world.build import adjacency

VIEW_TERM_GRACE = 60.0
"""Seconds a view has after SIGTERM to write its recording before SIGKILL: it draws what it
had heard for up to 10 s (``sensornet.view.END_DRAIN_S``), flushes and closes the file. A view
behind a 300-scan run took 17.8 s at load 16; with 10 s it was killed and its ``.rrd`` had no
footer (``rerun rrd verify`` failed). Only a view behind at the end waits that long."""
VIEW_NICE = 10
"""The view process's nice value where its threads may not be SCHED_IDLE (``--idle``, which
it asks for): on a busy machine it falls behind, not the peers."""


def _cli() -> list[str]:
    return [sys.executable, "-m", "sensornet"]


def start_run(scn: Scenario, source: str, out: Path, network: str | None = None,
              overrides: list[str] | None = None, viewer: str | None = None,
              run: int = 0, speed: float | None = None, peer_args: dict | None = None,
              lease_ms: int | None = None, rerun: bool = True,
              sparse: bool = False, listen: list[str] | None = None,
              connect: list[str] | None = None, config: str | None = None,
              run_id: str | None = None, secure: Path | None = None,
              router: bool = False, recover: bool = True,
              world_args: list[str] | None = None, per_process: int = 1) -> RunHandle:
    """Start the world and the peers; returns at once (see :func:`wait_run`).

    ``listen``: the world's endpoints (the peers connect to the first; default a free
    loopback port); ``connect``: endpoints every process connects to as well (a router, say);
    ``config``: a Zenoh JSON5 file for every process; ``run_id``: the Rerun recording id;
    ``secure``: a folder of the network's keys (``sensornet keys``): every process then speaks
    mutual TLS on ``tls/`` endpoints under the network's access control. ``router``: start a
    router first (``sensornet router``, with the folder's ``router`` key in secure mode) and make
    every process its Zenoh client (a config file ``<out>/zenoh-client.json5``; nobody else
    listens): the routed topology of several machines, on loopback; ``recover`` (routed runs):
    estimates and scans through Zenoh's advanced publisher/subscriber (``--recover``);
    ``world_args``: more arguments for the world (``--wait 150``, say), as ``peer_args`` for
    the peers; ``per_process``: peers per process (``sensornet host``, one Zenoh session
    each; hosts ``h1``, ``h2``, ... take the peers in the scenario's order, see
    :func:`host_groups`); 1, the default: every peer a process of its own. Returns at once.
    """
    network = network or f"run-{uuid.uuid4().hex[:8]}"
    run_id = run_id or f"{network}-{uuid.uuid4().hex[:6]}"
    names = scn.sensor_names
    graph = adjacency(scn)[1]
    groups = host_groups(names, per_process, graph)
    if groups and secure:
        raise ValueError("a host has one Zenoh session, so one TLS identity: no --secure "
                         "with more than one peer per process")
    ep = tls_endpoint if secure else endpoint
    eps = {n: ep(free_port()) for n in (groups or names)}
    world_listen = list(listen or []) or [ep(free_port())]
    eps = {"world": world_listen[0], **eps}
    sets = [a for item in (overrides or []) for a in ("--set", item)]
    # the view subscribes, nobody else logs; a secure one joins as the read-only observer
    watch = bool(rerun or viewer) and (secure is None
                                       or (Path(secure) / f"{OBSERVER}.key").is_file())
    common = _common_flags(network, out, run_id, sets, rerun, viewer, secure, config, watch)
    extra_connect = [a for c in (connect or []) for a in ("--connect", c)]
    (out / "logs").mkdir(parents=True, exist_ok=True)
    handle = RunHandle(out=out, endpoints=eps, network=network, secure=secure, hosts=groups)
    handle.views = {}  # the view process: not a member of the run (its end or failure is its own)
    if router:
        if config or listen or sparse:
            raise ValueError("a routed run makes its own client config and endpoints: "
                             "no --config, --listen or --sparse with --router")
        common, eps, extra_connect = _routed(handle, common, ep(free_port()),
                                             list(groups or names), extra_connect, recover)
        world_listen = []
    # the world's first scan waits (bounded) for the view's subscription: a view still
    # importing on a busy machine missed the run's first seconds (a caller's own flag wins)
    world_args = [*(["--view-wait", f"{VIEW_WAIT:g}"] if watch else []), *(world_args or [])]
    world = _world_command(source, common, {} if router and recover else groups, world_listen,
                           extra_connect, names, run, world_args, speed)
    A = graph if sparse else None  # each peer links to the world and its graph neighbours only
    peers = _peer_commands(names, source, common, eps, extra_connect, run=run, speed=speed,
                           lease_ms=lease_ms, peer_args=peer_args or {}, router=router,
                           hosted=bool(groups), A=A)
    cmds = {"world": world, **peers}
    if groups:  # the hosts instead of the peers' processes
        cmds = {"world": world, **_host_commands(
            groups, peers, names, eps, extra_connect, router, sparse, A)}
    if watch:  # started first: it hears the run from its first scan
        cmds = {"view": _view_command(network, eps["world"], extra_connect, source, sets,
                                      run_id, common, out, rerun, viewer), **cmds}
    handle.commands = cmds
    (out / "commands.json").write_text(json.dumps(
        {**({"router": handle.router_command} if router else {}), **cmds}, indent=1))
    _spawn(handle, cmds, groups, router)
    return handle


def _world_command(source: str, common: list[str], bundled: dict[str, list[str]],
                   listen: list[str], extra_connect: list[str], names: list[str], run: int,
                   world_args: list[str] | None, speed: float | None) -> list[str]:
    """The world's command (``sensornet world``): it waits for every peer, and sends each host
    of ``bundled`` its scans in one message per scan (:mod:`protocol.bundle`; a routed run
    that recovers keeps one per sensor, so its caller passes none)."""
    bundles = [a for h, members in bundled.items()
               for a in ("--bundle", f"{h}={','.join(members)}")]
    return [*_cli(), "world", source, *common, *bundles,
            *[a for ep in listen for a in ("--listen", ep)], *extra_connect,
            "--peers", ",".join(names), "--run", str(run), *(world_args or [])] \
        + (["--speed", str(speed)] if speed else [])


def _common_flags(network: str, out: Path, run_id: str, sets: list[str], rerun: bool,
                  viewer: str | None, secure: Path | None, config: str | None,
                  watch: bool) -> list[str]:
    """The flags every member of the run gets: network, output folder, recording id,
    overrides, Rerun logging (only the world's, and only in secure mode with a keys folder
    that has no observer key, where there is no view process: ``watch`` False), the Zenoh
    config and the keys folder."""
    common = ["--network", network, "--out", str(out), "--run-id", run_id, *sets]
    if secure and (rerun or viewer) and not watch:  # no view: the world logs as before
        common += ["--viewer", viewer] if viewer else []
    else:
        common += ["--no-rerun"]
    if config:
        common += ["--config", str(config)]
    if secure:
        common += ["--secure", str(secure)]
    return common


def _peer_commands(names: list[str], source: str, common: list[str], eps: dict[str, str],
                   extra_connect: list[str], *, run: int, speed: float | None,
                   lease_ms: int | None, peer_args: dict, router: bool, hosted: bool,
                   A: np.ndarray | None) -> dict[str, list[str]]:
    """Each peer's ``sensornet peer`` command. Its links: none of its own in a routed or
    hosted run (the router; its host's, :func:`_host_commands`), the world and its earlier
    graph neighbours given the adjacency ``A`` (``--sparse``: gossip off), else the world and
    every earlier peer (autoconnect off: the links are explicit)."""
    cmds = {}
    for i, n in enumerate(names):
        if router or hosted:  # a host's links: _host_commands
            links = []  # the router, in extra_connect like every process
        elif A is not None:
            links = [eps["world"], *(eps[names[j]] for j in range(i) if A[i, j])]
        else:
            links = [eps["world"], *(eps[m] for m in names[:i])]
        cmds[n] = [*_cli(), "peer", n, "--scenario", source, *common,
                   *(["--listen", eps.get(n, "")] if not router else
                     ["--world-grace", str(ROUTER_GRACE)]),
                   "--color", str(i), "--run", str(run),
                   *[a for c in links for a in ("--connect", c)], *extra_connect,
                   *(["--lease-ms", str(lease_ms)] if lease_ms else []),
                   *(["--no-gossip"] if A is not None else [] if router else
                     ["--no-autoconnect"]),
                   *peer_args.get(n, [])] \
            + (["--speed", str(speed)] if speed else [])
    return cmds


def _view_command(network: str, world: str, extra_connect: list[str], source: str,
                  sets: list[str], run_id: str, common: list[str], out: Path, rerun: bool,
                  viewer: str | None) -> list[str]:
    """The view process's command (``sensornet view``): it connects to the world's endpoint,
    records ``<out>/rerun/view.rrd`` and ends a little after the run's end message; in secure
    mode as the keys folder's read-only observer."""
    cfg = common[common.index("--config") + 1] if "--config" in common else None
    keys = common[common.index("--secure") + 1] if "--secure" in common else None
    eps = [world, *(extra_connect[i + 1] for i, a in enumerate(extra_connect)
                    if a == "--connect")]  # not a routed run's --recover: not a view's flag
    links = [a for e in dict.fromkeys(eps) for a in ("--connect", e)]
    return [*_cli(), "view", network, *links,
            "--scenario", source, *sets, "--run-id", run_id, "--until-end",
            "--idle", "--nice", str(VIEW_NICE),
            *(["--config", cfg] if cfg else []),
            *(["--secure", keys] if keys else []),
            *(["--out", str(out / "rerun" / "view.rrd")] if rerun else []),
            *(["--viewer", viewer] if viewer else [])]


def _spawn(handle: RunHandle, cmds: dict[str, list[str]], groups: dict[str, list[str]],
           router: bool) -> None:
    """Start the router (routed runs) and every command, each logging to
    ``<out>/logs/<name>.log``; on any failure stop what was started and re-raise."""
    try:
        if router:
            handle.start_router()
        for name, cmd in cmds.items():
            log = handle.out / "logs" / f"{name}.log"
            handle.logs[name] = log
            with log.open("w") as fh:  # a host reads its commands (kill PEER) on stdin
                procs = handle.views if name == "view" else handle.procs
                procs[name] = subprocess.Popen(
                    cmd, stdout=fh, stderr=subprocess.STDOUT,
                    stdin=subprocess.PIPE if name in groups else subprocess.DEVNULL)
    except BaseException:
        handle.stop_all(grace=1.0)
        stop_views(handle, 0.0)
        raise


def host_groups(names: list[str], per_process: int,
                adjacency: np.ndarray | None = None) -> dict[str, list[str]]:
    """``h1``, ``h2``, ...: at most ``per_process`` peers each, in the scenario's order (the
    last host may hold fewer), or, given the peer graph's ``adjacency``, grouped so that fewer
    graph edges run between hosts when a spectral partition finds such a grouping
    (:func:`sim.run.packing.groups_for`); empty for ``per_process`` 1 (a process per peer)."""
    if per_process < 1:
        raise ValueError(f"per_process must be >= 1, not {per_process}")
    if per_process == 1:
        return {}
    groups = groups_for(adjacency, len(names), per_process)
    return {f"h{j + 1}": [names[i] for i in g] for j, g in enumerate(groups)}


def hosts_line(hosts: dict[str, list[str]]) -> str:
    """One line: which peers each host holds."""
    return "hosts: " + "; ".join(f"{h} = {','.join(p)}" for h, p in hosts.items())


def _host_commands(groups: dict[str, list[str]], peer_cmds: dict[str, list[str]],
                   names: list[str], eps: dict[str, str], extra_connect: list[str],
                   router: bool, sparse: bool, A) -> dict[str, list[str]]:
    """Each host's ``sensornet host`` command, made from its peers' commands: their shared
    flags, the host's own endpoint, links to the world and the earlier hosts (with
    ``sparse`` only those that hold a neighbour of one of its peers)."""
    index = {n: i for i, n in enumerate(names)}
    order = list(groups)
    cmds = {}
    for j, (h, members) in enumerate(groups.items()):
        first = peer_cmds[members[0]]
        for m in members[1:]:
            if _without_own(peer_cmds[m]) != _without_own(first):
                raise ValueError(f"the peers of host {h} need the same peer flags "
                                 f"({members[0]}: {first[len(_cli()) + 2:]}; {m}: "
                                 f"{peer_cmds[m][len(_cli()) + 2:]})")
        rest = _without_own(first)
        if router:
            links = []
        else:
            earlier = order[:j]
            if sparse:
                earlier = [g for g in earlier if any(A[index[a], index[b]] for a in members
                                                     for b in groups[g])]
            links = [eps["world"], *(eps[g] for g in earlier)]
        source = rest[rest.index("--scenario") + 1]
        rest = _drop(rest, "--scenario", 1)
        cmds[h] = [*_cli(), "host", source, "--peers", ",".join(members), "--name", h,
                   *(["--listen", eps[h]] if not router else []),
                   *[a for c in links for a in ("--connect", c)], *extra_connect, *rest]
    return cmds


def _drop(cmd: list[str], flag: str, values: int) -> list[str]:
    """``cmd`` without every ``flag`` and the ``values`` arguments after it."""
    out, i = [], 0
    while i < len(cmd):
        if cmd[i] == flag:
            i += 1 + values
            continue
        out.append(cmd[i])
        i += 1
    return out


def _without_own(cmd: list[str]) -> list[str]:
    """A peer's command without what is its own (name, endpoint, links, colour)."""
    rest = cmd[len(_cli()) + 2:]  # after "peer NAME"
    for flag in ("--listen", "--connect", "--color"):
        rest = _drop(rest, flag, 1)
    return rest


def _routed(handle: RunHandle, common: list[str], router_ep: str, names: list[str],
            extra_connect: list[str],
            recover: bool) -> tuple[list[str], dict[str, str], list[str]]:
    """A routed run: the router's command, the clients' config file, every endpoint the
    router's, every process connecting to it (``recover``: what a router's outage held back
    comes from the publishers' caches); returns the common flags, endpoints and connects."""
    config = handle.out / "zenoh-client.json5"
    config.write_text(json.dumps({
        "mode": "client", "scouting": {"multicast": {"enabled": False}},
        "transport": {"link": {"tx": {"lease": DEFAULT_LEASE_MS},
                               "rx": {"max_message_size": MAX_MESSAGE_BYTES}}}}, indent=1))
    handle.router_command = [sys.executable, "-m", "sensornet.sim.run.router", "--listen",
                             router_ep,
                             "--network", handle.network]  # sensornet router, started faster
    if handle.secure:
        handle.router_command += ["--secure", str(handle.secure), "--name", ROUTER]
    handle.endpoints = {"router": router_ep}
    connect = ["--connect", router_ep, *extra_connect, *(["--recover"] if recover else [])]
    return [*common, "--config", str(config)], {"router": router_ep, "world": router_ep,
                                               **{n: router_ep for n in names}}, connect


def world_started(handle: RunHandle) -> bool:
    """Whether the run's world has logged :data:`WORLD_STARTED` (False without a log)."""
    path = handle.logs.get("world")
    try:
        with open(path, errors="replace") as f:
            return any(line.startswith(WORLD_STARTED) for line in f)
    except (OSError, TypeError):
        return False


def wait_run(handle: RunHandle, timeout: float,
             stop: threading.Event | None = None) -> dict[str, int]:
    """Wait for the world to finish and the peers to exit; returns every exit code.

    Everything is stopped (SIGTERM, then SIGKILL after a grace period) when the run outlives
    ``timeout`` (``handle.timed_out``), when ``stop`` is set (``handle.stopped``: the caller's
    SIGINT/SIGTERM handler), when the world fails, or when a peer exits with an error code (a
    crash or a bad flag; peers stopped by a signal, as process faults do, exit with a negative
    code and do not count). Peers get 15 s after the world to finish. ``timeout`` counts
    from the world's first scan (:data:`WORLD_STARTED` in its log), or from now until then:
    a slow start-up (processes importing on a busy machine) does not eat a long run's slack.
    """
    end = time.monotonic() + timeout
    world = handle.procs["world"]
    peers_end = None
    started, look = False, 0.0
    try:
        while True:
            if stop is not None and stop.is_set():
                handle.stopped = True
                break
            now = time.monotonic()
            if not started and now >= look:
                look = now + 0.5
                started = world_started(handle)
                if started:
                    end = max(end, now + timeout)
            if now >= end or (peers_end is not None and now >= peers_end):
                handle.timed_out = now >= end
                break
            if all(p.poll() is not None for p in handle.procs.values()):
                break
            code = world.poll()
            if code is not None:
                if code != 0:
                    break
                if peers_end is None:
                    peers_end = min(end, now + 15.0)
            if any((p.poll() or 0) > 0 for n, p in handle.procs.items() if n != "world"):
                break
            if stop is not None:
                stop.wait(0.05)
            else:
                time.sleep(0.05)
    finally:
        handle.stop_all()
        stop_views(handle, 0.0 if handle.stopped or handle.timed_out else 15.0)
    return {name: p.returncode for name, p in handle.procs.items()}


def stop_views(handle: RunHandle, wait: float = 15.0) -> None:
    """The view ends by itself a few seconds after the run's end message; given ``wait``
    seconds for that, then SIGTERM (it writes its recording: :data:`VIEW_TERM_GRACE`), then
    SIGKILL."""
    for proc in getattr(handle, "views", {}).values():
        for action, grace in ((None, wait), ("terminate", VIEW_TERM_GRACE), ("kill", 5.0)):
            if action is not None:
                getattr(proc, action)()
            try:
                proc.wait(timeout=grace)
                break
            except subprocess.TimeoutExpired:
                continue

