"""The one way every process (peer, world, tools) builds its Zenoh session from flags.

Peer mode with explicit TCP endpoints on loopback by default: multicast scouting does not
work on every host network, so it is off unless a user's own config file turns it on.
"""

from __future__ import annotations

import json
import os
import random
import socket
import threading
from collections.abc import Sequence
from pathlib import Path

import zenoh
from sensornet.peers.endpoints import check_endpoints
from sensornet.peers.errors import SessionError

DEFAULT_LEASE_MS = 1500
"""Zenoh link lease: a frozen (SIGSTOP) process is noticed within about this long (Zenoh's own
default, 10 s, let a frozen neighbour hold up every deadline for 10 s)."""

MAX_MESSAGE_BYTES = (1 << 20) + 4096
"""Largest message the transport assembles (the codec's limit plus framing): a bigger one is
dropped by Zenoh before it costs memory (a 50 MB payload used to be received whole)."""


ACCEPT_PENDING = 1024
"""Incoming links Zenoh keeps in their opening handshake at once (its default, 100, let an
outsider's 400 idle TCP connections keep a new member out for 13 s: it waited for a slot)."""
ACCEPT_TIMEOUT_MS = 3000
"""How long an incoming link may take to finish its handshake (Zenoh's default 10 s): a flood
of idle connections larger than :data:`ACCEPT_PENDING` clears within this."""

DEFER_ACCEPT_S = 3600
"""Seconds a connection to a ``tls/`` listener may stay silent before the kernel hands it to
Zenoh anyway (Linux ``TCP_DEFER_ACCEPT``, :func:`defer_accept`). Zenoh's TLS accept loop sleeps
100 ms after every failed handshake (its ``TLS_ACCEPT_THROTTLE_TIME``, fixed when Zenoh is
built, meant for a process out of file descriptors), so 400 idle connections timing out their
handshakes stalled it 40 s, and an outsider reopening them stalled it for good. A member's
first bytes (its TLS ClientHello) go with its connection, so it is accepted at once; an idle
one waits in the kernel's SYN queue (Zenoh's backlog, 1,024) for this long, then reaches
Zenoh and costs its 100 ms (measured: with 5 s and 120 s the 400 came through after that
long and stalled the loop 40 s; so, an hour). Not covered: more idle connections than the
backlog (the kernel's SYN cookies accept the rest at once) and connections that send junk
(accepted, refused, 100 ms each): docs/security.md."""


SHARED_MEMORY_NOTE = """Zenoh's shared-memory transport optimisation is off: with it, a large
message (over 3 kB) from a sender on the same host comes through that sender's 16 MiB pool,
which every receiver maps: +20 MB resident in a peer flooded with 240 kB estimates (+2 MB
without), and up to 16 MiB more per large-message sender. Estimates are a few hundred bytes;
bounded memory is worth more than a copy saved on a rare large one."""


DIAL_SOON = {"period_init_ms": 100, "period_max_ms": 500, "period_increase_factor": 1.5}
"""Connect retry of a session that may open before the process it dials listens: every
session without a Zenoh config file (:func:`zenoh_config`; a file's own settings stand). A
run's processes start at once and each listens only once it has loaded: with Zenoh's default
back-off (1 s, doubling to 4 s) a peer that dialled an earlier one still loading linked up 1-3 s
late, and the world, waiting for every peer's ``ready``, started the run that much later; the
view missed a short run's first scans."""
ANNOUNCE = "announce"
"""Gossip on (others still learn of this process and link to it) but no links made from it:
only its ``connect`` endpoints are dialled. Zenoh dials a lost link again only from the side
whose configured connector opened it; a link gossip made is dialled again by nobody, so a peer
frozen past the lease could stay unlinked from a neighbour for the rest of a run (seen once in
a suite pass: a 4-peer run's s4 never fused s3 again after its 5 s freeze). The launcher gives
every pair of its processes one configured dialler and this mode, so each lost link has one
side that dials it again."""


PEER_WAIT = 60.0
"""Seconds the world waits for its peers to be ready (it starts as soon as they are): four
processes on a loaded 2-core machine once took more than 30 s to start and link up."""




def _ephemeral_low() -> int:
    """First port of the kernel's range for outgoing connections (Linux; else IANA's)."""
    try:
        return int(Path("/proc/sys/net/ipv4/ip_local_port_range").read_text().split()[0])
    except (OSError, ValueError, IndexError):
        return 49152


_LISTEN_LOW = 20000
"""Listening ports are drawn from here up to the ephemeral range."""
_RANDOM = random.SystemRandom()  # not the global generator a test or a run may have seeded
_HANDED_OUT: set[int] = set()  # every port free_port returned in this process (not again)
_HANDED_LOCK = threading.Lock()


def _bindable(host: str, port: int) -> bool:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        try:
            s.bind((host, port))
        except OSError:
            return False
    return True


def free_port(host: str = "127.0.0.1") -> int:
    """A TCP port that is free right now on ``host``, for a process to listen on later.

    Drawn at random *below* the kernel's ephemeral range: a port the OS hands out itself
    (``bind(0)``) comes from the range every outgoing connection also takes its local port
    from, and on a busy machine one of them took such a port between this choice and the
    listener's bind ("Address already in use": a whole run failed to start). Never the same
    port twice in one process: the ports of a run are all chosen before any is bound, and two
    random draws once gave the world and a peer the same port (a loaded suite pass lost a
    run). Falls back to the OS's choice when the range below is too small or full.
    """
    hi = _ephemeral_low()
    with _HANDED_LOCK:
        if hi - _LISTEN_LOW >= 1000:
            for _ in range(50):
                port = _RANDOM.randrange(_LISTEN_LOW, hi)
                if port not in _HANDED_OUT and _bindable(host, port):
                    _HANDED_OUT.add(port)
                    return port
        for _ in range(50):
            with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
                s.bind((host, 0))
                port = int(s.getsockname()[1])
            if port not in _HANDED_OUT:
                _HANDED_OUT.add(port)
                return port
    raise SessionError("no free TCP port found on " + host)


def endpoint(port: int, host: str = "127.0.0.1") -> str:
    return f"tcp/{host}:{port}"


def zenoh_config(listen: Sequence[str] = (), connect: Sequence[str] = (),
                 config_file: str | None = None, lease_ms: int | None = None,
                 gossip: bool | str = True, max_message: int | None = MAX_MESSAGE_BYTES,
                 security=None, retry: dict | None = None) -> zenoh.Config:
    """A peer-mode config: the user's JSON5 file if given, then the flags on top of it
    (``retry``: Zenoh's ``connect/retry`` settings; :data:`DIAL_SOON` unless a file is given).

    ``gossip``: ``True`` (Zenoh's discovery: links to whoever gossip names), ``False`` (links
    only to the ``connect`` endpoints) or :data:`ANNOUNCE` (see there).

    ``security`` (a :class:`peers.security.Security`): mutual TLS against the network's CA
    and the network's access control policy; every endpoint must then be ``tls/``.

    Defaults on top of Zenoh's: a lease of :data:`DEFAULT_LEASE_MS`, a maximum message size
    of :data:`MAX_MESSAGE_BYTES` (a user's file may set both; flags still win), no
    shared-memory transport optimisation (:data:`SHARED_MEMORY_NOTE`) and room for
    :data:`ACCEPT_PENDING` handshakes of at most :data:`ACCEPT_TIMEOUT_MS` each.
    """
    if config_file:
        path = Path(config_file)
        if not path.is_file():
            raise SessionError(f"Zenoh config file {config_file!r} not found")
        try:
            conf = zenoh.Config.from_file(str(path))
        except Exception as exc:
            raise SessionError(f"Zenoh config file {config_file!r}: {exc}") from None
    else:
        conf = zenoh.Config()
        conf.insert_json5("mode", '"peer"')
        conf.insert_json5("scouting/multicast/enabled", "false")
    try:
        if listen:
            conf.insert_json5("listen/endpoints", json.dumps(list(listen)))
        if connect:
            conf.insert_json5("connect/endpoints", json.dumps(list(connect)))
        if lease_ms or not config_file:
            conf.insert_json5("transport/link/tx/lease", str(int(lease_ms or DEFAULT_LEASE_MS)))
        if max_message and not config_file:
            conf.insert_json5("transport/link/rx/max_message_size", str(int(max_message)))
        if not config_file:  # see SHARED_MEMORY_NOTE
            conf.insert_json5("transport/shared_memory/transport_optimization/enabled", "false")
        if not config_file:  # idle connections must not lock members out (ACCEPT_PENDING)
            conf.insert_json5("transport/unicast/accept_pending", str(ACCEPT_PENDING))
            conf.insert_json5("transport/unicast/accept_timeout", str(ACCEPT_TIMEOUT_MS))
        if not gossip:  # links only to the given endpoints (large networks: fewer links)
            conf.insert_json5("scouting/gossip/enabled", "false")
        elif gossip == ANNOUNCE:
            conf.insert_json5("scouting/gossip/autoconnect", '{"router": [], "peer": []}')
        if security is not None:
            check_endpoints([*listen, *connect])
            if not listen:  # not Zenoh's default plain tcp/[::]:0 listener: others would
                # learn it by gossip and link to it unauthenticated (every message refused)
                conf.insert_json5("listen/endpoints", "[]")
            security.apply(conf)
        if retry is not None or not config_file:
            conf.insert_json5("connect/retry", json.dumps(retry or DIAL_SOON))
    except SessionError:
        raise
    except Exception as exc:
        raise SessionError(f"bad Zenoh endpoint or setting: {exc}") from None
    return conf


def _ports(endpoints: Sequence[str], protocol: str) -> set[int]:
    """The explicit ports of ``endpoints`` of ``protocol`` (``tls/host:port[?..][#..]``)."""
    out = set()
    for e in endpoints:
        if e.startswith(protocol + "/"):
            tail = e.split("?", 1)[0].split("#", 1)[0].rsplit(":", 1)[-1]
            if tail.isdigit() and int(tail):
                out.add(int(tail))
    return out


def defer_accept(ports: set[int], seconds: int = DEFER_ACCEPT_S) -> int:
    """Set ``TCP_DEFER_ACCEPT`` on this process's listening TCP sockets on ``ports`` (found
    among its open file descriptors: Zenoh makes them and offers no such setting; a duplicate
    of the descriptor sets the option on the same socket). Returns how many were set; 0 where
    the platform has no such option (not Linux). Why: :data:`DEFER_ACCEPT_S`."""
    opt = getattr(socket, "TCP_DEFER_ACCEPT", None)
    if opt is None or not ports or not os.path.isdir("/proc/self/fd"):
        return 0
    done = 0
    for name in os.listdir("/proc/self/fd"):
        try:
            fd = os.dup(int(name))
        except (OSError, ValueError):
            continue
        try:
            s = socket.socket(fileno=fd)
        except OSError:  # not a socket
            os.close(fd)
            continue
        try:
            if (s.type == socket.SOCK_STREAM
                    and s.getsockopt(socket.SOL_SOCKET, socket.SO_ACCEPTCONN)
                    and s.getsockname()[1] in ports):
                s.setsockopt(socket.IPPROTO_TCP, opt, int(seconds))
                done += 1
        except OSError:
            pass
        finally:
            s.close()  # the duplicate only
    return done


def open_session(listen: Sequence[str] = (), connect: Sequence[str] = (),
                 config_file: str | None = None, lease_ms: int | None = None,
                 gossip: bool | str = True, max_message: int | None = MAX_MESSAGE_BYTES,
                 security=None, retry: dict | None = None) -> zenoh.Session:
    """Open a Zenoh session; a bad endpoint or a port in use is a :class:`SessionError`."""
    conf = zenoh_config(listen, connect, config_file, lease_ms, gossip, max_message, security,
                        retry)
    try:
        session = zenoh.open(conf)
    except Exception as exc:
        raise SessionError(f"cannot open Zenoh session (listen {list(listen)}, connect "
                           f"{list(connect)}): {exc}") from None
    defer_accept(_ports(listen, "tls"))  # idle connections must not stall TLS accepts
    return session
