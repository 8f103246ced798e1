"""Start a whole network run as separate OS processes: the world and one peer per sensor.

Every process is ``python -m sensornet world|peer ...`` with explicit loopback endpoints on
free ports, its log in ``<run>/logs/``, its summary and ``.rrd`` in the run folder. Whatever
happens (an error, Ctrl-C, SIGTERM, a timeout), every child is stopped before this returns:
:func:`wait_run` takes a ``stop`` event that the caller sets from its signal handler, and then
sends SIGTERM to every child (SIGKILL after a grace period), so the peers still write their
summaries and ``.rrd`` files and the recording can be merged.
"""

from __future__ import annotations

import json
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
import uuid
from dataclasses import dataclass, field
from pathlib import Path

from peers.security import WORLD, Security, tls_endpoint
from peers.session import (
    DEFAULT_LEASE_MS,
    MAX_MESSAGE_BYTES,
    SessionError,
    endpoint,
    free_port,
    open_session,
)
from peers.telemetry import percentile
from protocol.codec import Rejected, decode
from protocol.envelope import inner
from protocol.keys import Keys
from sim.build import adjacency
from sim.scenario import Scenario


@dataclass
class RunHandle:
    """The processes of one run and where they write."""

    out: Path
    procs: dict[str, subprocess.Popen] = field(default_factory=dict)
    logs: dict[str, Path] = field(default_factory=dict)
    endpoints: dict[str, str] = field(default_factory=dict)
    network: str = ""
    commands: dict[str, list[str]] = field(default_factory=dict)
    restarts: dict[str, int] = field(default_factory=dict)
    timed_out: bool = False
    """Set by :func:`wait_run` when the run outlived its timeout (and was stopped)."""
    stopped: bool = False
    """Set by :func:`wait_run` when the caller's ``stop`` event ended the run."""
    secure: Path | None = None
    """The network's keys folder in secure mode (tools of the launcher use the world's key)."""
    router: subprocess.Popen | None = None
    """The run's router (``start_run(router=True)``): every other process is its client."""
    router_command: list[str] = field(default_factory=list)
    hosts: dict[str, list[str]] = field(default_factory=dict)
    """``start_run(per_process=N)``, N > 1: each host process (``h1``, ``h2``, ...; its key in
    :attr:`procs`) and the peers it runs; empty when every peer is a process of its own."""

    def host_of(self, peer: str) -> str | None:
        """The host that runs ``peer`` (None: the peer is a process of its own)."""
        return next((h for h, names in self.hosts.items() if peer in names), None)

    def kill_hosted(self, peer: str, at_scan: int) -> subprocess.Popen:
        """Stop hosted peer ``peer`` as if killed (its host's ``kill`` command, on the
        host's standard input): the host's other peers keep running."""
        proc = self.procs[self.host_of(peer)]
        if proc.poll() is None and proc.stdin is not None:
            try:
                proc.stdin.write(f"kill {peer} {at_scan}\n".encode())
                proc.stdin.flush()
            except OSError:  # the host is gone already
                pass
        return proc

    def restart(self, name: str) -> subprocess.Popen:
        """Start peer ``name`` again (same command, a fresh listening port), or the router
        (``name`` ``router``: killed, started again on the same endpoint)."""
        if name == ROUTER and self.router is not None:
            return self.start_router()
        old = self.procs[name]
        if old.poll() is None:
            old.kill()
            old.wait()
        cmd = list(self.commands[name])
        if "--listen" in cmd:  # a router's client listens nowhere
            i = cmd.index("--listen")
            cmd[i + 1] = f"{cmd[i + 1].split('/', 1)[0]}/127.0.0.1:{free_port()}"  # tcp/, tls/
        self.restarts[name] = self.restarts.get(name, 0) + 1
        log = self.out / "logs" / f"{name}.restart{self.restarts[name]}.log"
        with log.open("w") as fh:
            self.procs[name] = subprocess.Popen(cmd, stdout=fh, stderr=subprocess.STDOUT,
                                                stdin=subprocess.DEVNULL)
        return self.procs[name]

    def wait_listening(self, name: str = "world", timeout: float = 60.0) -> None:
        """Return once process ``name`` accepts connections on its endpoint (it may still be
        importing when :func:`start_run` returns: a session that connects earlier waits for
        Zenoh's reconnection back-off, and a refused connection means nothing)."""
        host, _, port = self.endpoints[name].split("/", 1)[1].rpartition(":")
        end = time.monotonic() + timeout
        while True:
            try:
                socket.create_connection((host.strip("[]"), int(port)), timeout=1.0).close()
                return
            except OSError:
                if self.procs[name].poll() is not None or time.monotonic() > end:
                    raise SessionError(f"{name} is not listening on "
                                       f"{self.endpoints[name]}") from None
                time.sleep(0.05)

    def start_router(self, timeout: float = 30.0) -> subprocess.Popen:
        """Start (or start again) the run's router; returns once it listens."""
        if self.router is not None and self.router.poll() is None:
            self.router.kill()
            self.router.wait()
        n = self.restarts["router"] = self.restarts.get("router", -1) + 1
        log = self.out / "logs" / ("router.log" if n == 0 else f"router.restart{n}.log")
        self.logs["router" if n == 0 else f"router.restart{n}"] = log
        with log.open("w") as fh:
            self.router = subprocess.Popen(self.router_command, stdout=fh,
                                           stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL)
        end = time.monotonic() + timeout
        while "router: listening" not in log.read_text(errors="replace"):
            if self.router.poll() is not None or time.monotonic() > end:
                tail = log.read_text(errors="replace").strip().splitlines()[-1:]
                raise SessionError(f"the router did not start: {' '.join(tail) or 'no output'} "
                                   f"(log: {log})")
            time.sleep(0.02)  # the router prints one line once it listens
        return self.router

    def stop_all(self, grace: float = 5.0) -> None:
        """SIGTERM every child still running, then SIGKILL after ``grace`` seconds; the
        router last (the others may still be sending their last messages through it)."""
        self._stop(list(self.procs.values()), grace)
        if self.router is not None:
            self._stop([self.router], grace)

    @staticmethod
    def _stop(procs: list[subprocess.Popen], grace: float) -> None:
        for p in procs:
            if p.poll() is None:
                p.send_signal(signal.SIGCONT)  # a stopped process cannot handle SIGTERM
                p.send_signal(signal.SIGTERM)
        end = time.monotonic() + grace
        for p in procs:
            try:
                p.wait(timeout=max(0.0, end - time.monotonic()))
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()


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
    groups = host_groups(names, per_process)
    if groups and secure:
        raise ValueError("a host has one Zenoh session, so one TLS identity: no --secure "
                         "with more than one peer per process")
    ep = tls_endpoint if secure else endpoint
    eps = {n: ep(free_port()) for n in (groups or names)}
    world_listen = list(listen or []) or [ep(free_port())]
    eps = {"world": world_listen[0], **eps}
    sets = [a for item in (overrides or []) for a in ("--set", item)]
    common = ["--network", network, "--out", str(out), "--run-id", run_id, *sets]
    if viewer:
        common += ["--viewer", viewer]
    if not rerun:
        common += ["--no-rerun"]
    if config:
        common += ["--config", str(config)]
    if secure:
        common += ["--secure", str(secure)]
    extra_connect = [a for c in (connect or []) for a in ("--connect", c)]
    (out / "logs").mkdir(parents=True, exist_ok=True)
    handle = RunHandle(out=out, endpoints=eps, network=network, secure=secure, hosts=groups)
    if router:
        if config or listen or sparse:
            raise ValueError("a routed run makes its own client config and endpoints: "
                             "no --config, --listen or --sparse with --router")
        common, eps = _routed(handle, common, ep(free_port()), list(groups or names))
        world_listen = []
    if router:  # recover: what a router's outage held back comes from the publishers' caches
        extra_connect = ["--connect", eps["router"], *extra_connect,
                         *(["--recover"] if recover else [])]
    cmds = {"world": [*_cli(), "world", source, *common,
                      *[a for ep in world_listen for a in ("--listen", ep)], *extra_connect,
                      "--peers", ",".join(names), "--run", str(run), *(world_args or [])]
            + (["--speed", str(speed)] if speed else [])}
    if sparse:  # each peer links to the world and its graph neighbours only, gossip off
        _, A = adjacency(scn)
    for i, n in enumerate(names):
        if router or groups:  # a host's links: _host_commands
            links = []  # the router, in extra_connect like every process
        elif sparse:
            links = [eps["world"], *(eps[names[j]] for j in range(i) if A[i, j])]
        else:
            links = [eps["world"], *(eps[m] for m in names[:i])]
        extra = (peer_args or {}).get(n, [])
        cmds[n] = [*_cli(), "peer", n, "--scenario", source, *common,
                   *(["--listen", eps.get(n, "")] if not router else
                     ["--world-grace", str(ROUTER_GRACE)]),
                   "--color", str(i), "--run", str(run),
                   *[a for c in links for a in ("--connect", c)], *extra_connect,
                   *(["--lease-ms", str(lease_ms)] if lease_ms else []),
                   *(["--no-gossip"] if sparse else []), *extra] \
            + (["--speed", str(speed)] if speed else [])
    if groups:  # the hosts instead of the peers' processes
        cmds = {"world": cmds["world"], **_host_commands(
            groups, cmds, names, eps, extra_connect, router, sparse, A if sparse else None)}
    handle.commands = cmds
    (out / "commands.json").write_text(json.dumps(
        {**({"router": handle.router_command} if router else {}), **cmds}, indent=1))
    try:
        if router:
            handle.start_router()
        for name, cmd in cmds.items():
            log = out / "logs" / f"{name}.log"
            handle.logs[name] = log
            with log.open("w") as fh:  # a host reads its commands (kill PEER) on stdin
                handle.procs[name] = subprocess.Popen(
                    cmd, stdout=fh, stderr=subprocess.STDOUT,
                    stdin=subprocess.PIPE if name in groups else subprocess.DEVNULL)
    except BaseException:
        handle.stop_all(grace=1.0)
        raise
    return handle


def host_groups(names: list[str], per_process: int) -> dict[str, list[str]]:
    """``h1``, ``h2``, ...: ``per_process`` peers each, in the scenario's order (the last
    host may hold fewer); empty for ``per_process`` 1 (every peer a process of its own)."""
    if per_process < 1:
        raise ValueError(f"per_process must be >= 1, not {per_process}")
    if per_process == 1:
        return {}
    return {f"h{j + 1}": names[i:i + per_process]
            for j, i in enumerate(range(0, len(names), per_process))}


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


def _routed(handle: RunHandle, common: list[str], router_ep: str,
            names: list[str]) -> tuple[list[str], dict[str, str]]:
    """A routed run: the router's command, the clients' config file, every endpoint the
    router's."""
    config = handle.out / "zenoh-client.json5"
    config.write_text(json.dumps({
        "mode": "client", "scouting": {"multicast": {"enabled": False}},
        "transport": {"link": {"tx": {"lease": DEFAULT_LEASE_MS},
                               "rx": {"max_message_size": MAX_MESSAGE_BYTES}}}}, indent=1))
    handle.router_command = [sys.executable, "-m", "sim.router", "--listen", router_ep,
                             "--network", handle.network]  # sensornet router, started faster
    if handle.secure:
        handle.router_command += ["--secure", str(handle.secure), "--name", ROUTER]
    handle.endpoints = {"router": router_ep}
    return [*common, "--config", str(config)], {"router": router_ep, "world": router_ep,
                                               **{n: router_ep for n in names}}


ROUTER = "router"
"""The member name of the router a routed run starts (its key in secure mode)."""
ROUTER_GRACE = 30.0
"""Seconds the peers of a routed run wait for the world to come back (``--world-grace``):
while the router is down every liveliness token is gone, the world's too."""


def wait_run(handle: RunHandle, timeout: float,
             stop: threading.Event | None = None) -> dict[str, int]:
    """Wait for the world to finish and the peers to exit; returns every exit code.

    Everything is stopped (SIGTERM, then SIGKILL after a grace period) when the run outlives
    ``timeout`` (``handle.timed_out``), when ``stop`` is set (``handle.stopped``: the caller's
    SIGINT/SIGTERM handler), when the world fails, or when a peer exits with an error code (a
    crash or a bad flag; peers stopped by a signal, as process faults do, exit with a negative
    code and do not count). Peers get 15 s after the world to finish.
    """
    end = time.monotonic() + timeout
    world = handle.procs["world"]
    peers_end = None
    try:
        while True:
            if stop is not None and stop.is_set():
                handle.stopped = True
                break
            now = time.monotonic()
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
    return {name: p.returncode for name, p in handle.procs.items()}


def summary_files(out: Path, name: str) -> list[Path]:
    """Peer ``name``'s summaries in ``out``, first run first (a restarted peer writes
    ``peer-<name>.restart<n>.json`` beside the earlier ones, never over them)."""
    def restart(p: Path) -> int:
        tail = p.name.removeprefix(f"peer-{name}").removesuffix(".json")
        return int(tail.removeprefix(".restart")) if tail else 0

    paths = [p for p in out.glob(f"peer-{name}*.json")
             if p.name == f"peer-{name}.json"
             or p.name.removeprefix(f"peer-{name}.restart").removesuffix(".json").isdigit()]
    return sorted(paths, key=restart)


def read_summaries(out: Path, names: list[str]) -> dict[str, dict]:
    """The newest summary of each peer (after restarts: the last run's); each carries the
    names of all its summary files under ``"summary_files"``."""
    found = {}
    for n in names:
        paths = summary_files(out, n)
        if paths:
            found[n] = json.loads(paths[-1].read_text())
            found[n]["summary_files"] = [p.name for p in paths]
    return found


def merge_recordings(out: Path) -> Path | None:
    """Merge the per-process ``.rrd`` files into ``<out>/recording.rrd`` with the Rerun CLI."""
    parts = sorted((out / "rerun").glob("*.rrd"))
    if not parts:
        return None
    exe = shutil.which("rerun") or str(Path(sys.executable).with_name("rerun"))
    target = out / "recording.rrd"
    try:
        with target.open("wb") as fh:
            subprocess.run([exe, "rrd", "merge", *map(str, parts)], stdout=fh,
                           stderr=subprocess.DEVNULL, timeout=120, check=True,
                           env={**__import__("os").environ, "RERUN_ANALYTICS": "0"})
    except (OSError, subprocess.SubprocessError):
        target.unlink(missing_ok=True)
        return None
    return target


def format_summary(summaries: dict[str, dict]) -> str:
    """The end-of-run table: per peer OSPA local vs fused, communication cost per scan (the
    seed-004 tuples and the estimate bytes, both counted once per neighbour), traffic,
    rejections, age, latency."""
    def f(v, fmt="{:.1f}"):
        return "-" if v is None else fmt.format(v)

    head = ("| peer | scans | OSPA local | OSPA fused | tuples / scan | B / scan | msgs sent | "
            "msgs recv | kB sent | kB recv | rejected | mean age (scans) | "
            "latency median / p99 (ms) |\n"
            "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    rows = [head]
    for n, s in summaries.items():
        cost = s.get("cost") or {}
        rows.append(
            f"| {n} | {s['scans']} | {f(s['mean_ospa_local'])} | {f(s['mean_ospa_fused'])} | "
            f"{f(cost.get('tuples_per_scan'), '{:.0f}')} | "
            f"{f(cost.get('estimate_bytes_to_neighbours_per_scan'), '{:.0f}')} | "
            f"{s['messages_sent']} | {s['messages_received']} | {s['bytes_sent'] / 1e3:.1f} | "
            f"{s['bytes_received'] / 1e3:.1f} | {s['rejected_total']} | "
            f"{f(s['mean_estimate_age'], '{:.2f}')} | {f(s['latency_ms_median'], '{:.2f}')} / "
            f"{f(s['latency_ms_p99'], '{:.2f}')} |")
    refused = {n: s.get("refused_by_transport") or {} for n, s in summaries.items()}
    if any(refused.values()):  # secure mode: what the access control refused on arrival
        rows += ["", "Refused by access control (secure mode; sender, message, key: count):", ""]
        for n, r in refused.items():
            if r:
                top = sorted(r.items(), key=lambda kv: -kv[1])
                rows.append(f"- {n}: {sum(r.values())} refused: "
                            + ", ".join(f"{label} x{c}" for label, c in top[:6])
                            + (f", ... ({len(top) - 6} more)" if len(top) > 6 else ""))
    stages = [("transit", "world -> peer"), ("local", "local filter"),
              ("neighbours", "waiting for neighbours"), ("fusing", "fusing")]
    parts = {n: s.get("latency_breakdown_ms_median") or {} for n, s in summaries.items()}
    if any(p.get(k) is not None for p in parts.values() for k, _ in stages):
        rows += ["", "Where the latency goes (median ms per scan):", "",
                 "| peer | " + " | ".join(label for _, label in stages) + " |",
                 "|---|" + "---:|" * len(stages)]
        for n, p in parts.items():
            rows.append(f"| {n} | " + " | ".join(f(p.get(k), "{:.2f}") for k, _ in stages)
                        + " |")
    return "\n".join(rows)


REALTIME_DEADLINE_SHARE = 0.05
"""Above this share of fusion rounds run at their deadline a run did not keep real time (the
network benchmark's criterion, with a p99 scan -> tracks latency under one scan interval)."""


def trust_note(summaries: dict[str, dict]) -> str | None:
    """Who was quarantined by whom and when (peers with ``fusion.trust``), one line per
    neighbour; None if nobody was."""
    by: dict[str, list[str]] = {}
    for peer, s in sorted(summaries.items()):
        for ch in ((s.get("trust") or {}).get("changes") or []):
            if ch["to"] == "quarantined":
                by.setdefault(ch["neighbour"], []).append(f"{peer} at scan {ch['k']}")
            elif ch["from"] == "quarantined":
                by.setdefault(ch["neighbour"], []).append(f"readmitted by {peer} at scan "
                                                          f"{ch['k']}")
    if not by:
        return None
    return "\n".join(f"quarantined: {n} by " + ", ".join(v) for n, v in sorted(by.items()))


def realtime_note(summaries: dict[str, dict], interval_s: float, speed: float,
                  cores: int | None) -> str | None:
    """One paragraph when the peers did not keep real time (deadline fusions above
    :data:`REALTIME_DEADLINE_SHARE`, or the pooled p99 scan -> tracks latency over one scan
    interval), saying by how much and what to try; None when they did."""
    fusions = sum(s.get("stats", {}).get("fusions", 0) for s in summaries.values())
    late = sum(s.get("stats", {}).get("deadline_fusions", 0) for s in summaries.values())
    lat = sorted(x for s in summaries.values() for x in s.get("latency_ms_samples") or [])
    share = late / fusions if fusions else 0.0
    p99 = percentile(lat, 0.99)  # the sample at floor(0.99 n), as the benchmarks
    interval_ms = 1e3 * interval_s
    if share <= REALTIME_DEADLINE_SHARE and (p99 is None or p99 <= interval_ms):
        return None
    what = []
    if share > REALTIME_DEADLINE_SHARE:
        what.append(f"{100 * share:.1f} % of fusion rounds ran at their deadline")
    if p99 is not None and p99 > interval_ms:
        what.append(f"p99 scan -> tracks {p99:.0f} ms against a {interval_ms:.0f} ms scan "
                    f"interval")
    slower = speed / 2.0
    return (f"note: these {len(summaries)} peers did not keep real time at {speed:g}x "
            f"({'; '.join(what)}) on {cores or '?'} cores: the scores above include what "
            f"arrived too late. Run slower (--speed {slower:g}) or with fewer peers; "
            f"benchmarks/README.md has what such a machine sustains.")


PROCESS_ACTIONS = ("kill", "stop", "cont", "restart", "term", "killhost")
HOSTED_ACTIONS = ("kill", "killhost")
"""What a run with hosts (``per_process`` > 1) can do: stop one peer inside its host as if
killed, or SIGKILL a whole host (a machine failure)."""


@dataclass(frozen=True)
class ProcessFault:
    """``action`` on peer ``peer`` when the world publishes scan ``scan``."""

    action: str
    peer: str
    scan: int

    @classmethod
    def parse(cls, text: str) -> ProcessFault:
        """``ACTION:PEER@SCAN``, e.g. ``kill:s2@30`` (SIGKILL), ``stop:s3@20`` (SIGSTOP),
        ``cont:s3@40`` (SIGCONT), ``restart:s2@50``, ``term:s1@60`` (SIGTERM); with hosts
        (``per_process`` > 1) ``kill:s2@30`` stops that peer inside its host and
        ``killhost:h1@30`` SIGKILLs host ``h1`` (all its peers)."""
        try:
            head, scan = text.rsplit("@", 1)
            action, peer = head.split(":", 1)
            fault = cls(action.strip(), peer.strip(), int(scan))
        except ValueError:
            raise ValueError(f"bad process fault {text!r}: use ACTION:PEER@SCAN, "
                             f"e.g. kill:s2@30") from None
        if fault.action not in PROCESS_ACTIONS:
            raise ValueError(f"bad process fault {text!r}: action must be one of "
                             f"{', '.join(PROCESS_ACTIONS)}")
        if fault.scan < 1:
            raise ValueError(f"bad process fault {text!r}: scan must be >= 1")
        return fault


def _wait_world(handle: RunHandle, stop: threading.Event) -> None:
    """Return once the world listens, has exited, or ``stop`` is set: a session dialled before
    it listens waits out Zenoh's reconnection back-off, and a short run's scans (all of them,
    in seed001's 12-scan run) passed before the watcher was linked."""
    while not stop.is_set():
        try:
            handle.wait_listening("world", timeout=1.0)
            return
        except SessionError:
            if handle.procs["world"].poll() is not None:
                return


def inject_process_faults(handle: RunHandle, faults: list[ProcessFault], sensor: str,
                          stop: threading.Event) -> list[dict]:
    """Watch the run's scans (a Zenoh subscriber) and apply each fault at its scan.

    Runs until every fault is applied or ``stop`` is set; returns what was done, with wall
    times (also written to ``<out>/process-faults.json``).
    """
    unseal = inner if handle.secure is not None else bytes  # secure: signed scans
    pending = sorted(faults, key=lambda f: f.scan)
    done: list[dict] = []
    current = {"k": 0}
    cond = threading.Condition()

    def on_scan(sample) -> None:
        try:
            k = decode(unseal(sample.payload.to_bytes())).k
        except (Rejected, AttributeError):
            return
        with cond:
            current["k"] = max(current["k"], k)
            cond.notify_all()

    security = None
    if handle.secure is not None:  # watches the scans as the world may (its own key)
        security = Security.load(handle.secure, WORLD, handle.network,
                                 [n for n in handle.procs if n != "world"])
    if "router" not in handle.endpoints:  # a router listens once start_run returns
        _wait_world(handle, stop)
    session = open_session(connect=[handle.endpoints.get("router")
                                    or handle.endpoints["world"]], security=security)
    try:
        sub = session.declare_subscriber(Keys(handle.network).scan(sensor), on_scan)
        while pending and not stop.is_set():
            with cond:
                cond.wait(timeout=0.05)
                k = current["k"]
            while pending and pending[0].scan <= k:
                f = pending.pop(0)
                hosted = handle.host_of(f.peer)
                proc = (handle.router if f.peer == ROUTER else
                        handle.procs[hosted or f.peer])
                sig = {"kill": signal.SIGKILL, "stop": signal.SIGSTOP, "cont": signal.SIGCONT,
                       "term": signal.SIGTERM, "killhost": signal.SIGKILL}.get(f.action)
                if hosted is not None and f.action == "kill":  # that peer only, in its host
                    proc = handle.kill_hosted(f.peer, f.scan)
                elif f.action == "restart":
                    proc = handle.restart(f.peer)
                elif proc.poll() is None:
                    proc.send_signal(sig)
                done.append({"action": f.action, "peer": f.peer, "scan": f.scan, "at_scan": k,
                             "wall": time.time(), "pid": proc.pid,
                             **({"host": hosted} if hosted else {}),
                             **({"peers": handle.hosts[f.peer]} if f.action == "killhost"
                                else {})})
        sub.undeclare()
    finally:
        session.close()
    (handle.out / "process-faults.json").write_text(json.dumps(done, indent=2))
    return done


def fault_report(done: list[dict], summaries: dict[str, dict]) -> str:
    """When each peer saw each killed, stopped or restarted peer leave or come back."""
    lines = []
    for f in done:
        if f["peer"] == ROUTER:  # the peers saw the world (and everyone) go and come back
            seen = [f"{n} " + (", ".join(f"{sec:.2f} s after scan {k}" for k, sec in
                                         s.get("world_outages", [])) or "no outage")
                    for n, s in summaries.items()]
            lines.append(f"{f['action']} router at scan {f['at_scan']}: outages seen by "
                         + "; ".join(seen))
            rec = {n: s["recovery"] for n, s in summaries.items() if "recovery" in s}
            if rec:  # --recover: what came late from the publishers' caches, what was lost
                lines.append("recovered after the outage (scans, estimates; lost): " + "; ".join(
                    f"{n} {r['recovered']['scan']}, {r['recovered']['estimate']}; "
                    f"{sum(r['unrecovered'].values())}" for n, r in rec.items()))
            continue
        if f["action"] == "killhost":  # seen leaving: the last of the host's peers
            members = f.get("peers") or []
            seen = []
            for name, s in summaries.items():
                if name in members or s.get("killed_at_scan", f["at_scan"] + 1) <= f["at_scan"]:
                    continue  # its host's, or itself killed before
                first = [min((w for (peer, what, w, _k) in s.get("peer_events", [])
                              if peer == m and what == "left" and w >= f["wall"] - 0.01),
                             default=None) for m in members]
                seen.append(f"{name} never" if None in first or not first else
                            f"{name} +{max(first) - f['wall']:.2f} s")
            lines.append(f"killhost {f['peer']} ({', '.join(members)}) at scan {f['at_scan']}: "
                         f"seen left by " + ", ".join(seen))
            continue
        seen = []
        for name, s in summaries.items():
            if name == f["peer"]:
                continue
            want = "joined" if f["action"] in ("restart", "cont") else "left"
            times = [w for (peer, what, w, _k) in s.get("peer_events", [])
                     if peer == f["peer"] and what == want and w >= f["wall"] - 0.01]
            seen.append(f"{name} +{min(times) - f['wall']:.2f} s" if times else f"{name} never")
        verb = "rejoined" if f["action"] in ("restart", "cont") else "left"
        lines.append(f"{f['action']} {f['peer']} at scan {f['at_scan']}: seen {verb} by "
                     + ", ".join(seen))
    return "\n".join(lines)
