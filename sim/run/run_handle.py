"""The processes of one run (world, peers, hosts, router) and how they are stopped, restarted
and waited on: the handle :func:`sim.run.launcher.start_run` returns."""

from __future__ import annotations

import signal
import socket
import subprocess
import time
from dataclasses import dataclass, field
from pathlib import Path

from sensornet.peers.session import (
    SessionError,
    free_port,
)

ROUTER = "router"
"""The member name of the router a routed run starts (its key in secure mode)."""
ROUTER_GRACE = 30.0
"""Seconds the peers of a routed run wait for the world to come back (``--world-grace``):
while the router is down every liveliness token is gone, the world's too."""
WORLD_STARTED = "world: starting "
"""The line the world logs as its first scan goes out: a run's length counts from here
(:func:`sim.run.launcher.wait_run`)."""
VIEW_WAIT = 15.0
"""Seconds from the world's start (its publishers declared) that it waits at most for a view
to subscribe to the truth before its first scan, when asked to (``--view-wait``: ``sensornet
run`` asks when it starts a view). In a simulated run no peer subscribes to the truth (each
scores against its own truth function), so the truth publisher's matching status is the view:
without the wait a view still importing (20 s at load 15) missed the run's first seconds. It
counts from the world's start, overlapping the wait for the peers, so a ready peer waits at
most this long for its first scan, within its 30 s ``--idle-timeout``."""


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

