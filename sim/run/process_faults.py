"""Process faults from the launcher (``--fault kill:s2@30``): parsed, applied at their scan by a
watcher of the world's scans, and reported (when every other peer saw each one)."""

from __future__ import annotations

import json
import signal
import threading
import time
from dataclasses import dataclass

from sensornet.peers.security import WORLD, Security
from sensornet.peers.session import (
    SessionError,
    open_session,
)
from sensornet.protocol.bundle import unpack_bundle
from sensornet.protocol.codec import Rejected, decode
from sensornet.protocol.envelope import inner
from sensornet.protocol.keys import Keys
from sensornet.sim.run.run_handle import ROUTER, RunHandle

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
    in a 12-scan run of two peers) passed before the watcher was linked."""
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
            data = unseal(sample.payload.to_bytes())
            k = (unpack_bundle(data).k if "/scans/" in str(sample.key_expr)
                 else decode(data).k)
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
        keys = Keys(handle.network)
        subs = [session.declare_subscriber(keys.scan(sensor), on_scan)]
        host = handle.host_of(sensor)
        if host is not None:  # its scans may come in its host's bundles (protocol.bundle)
            subs.append(session.declare_subscriber(keys.scans(host), on_scan))
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
        for sub in subs:
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

