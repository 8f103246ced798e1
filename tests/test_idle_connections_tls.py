"""Idle connections do not lock members out of a ``tls/`` listener either (issue 36 item 3).

Zenoh's TLS accept loop sleeps 100 ms after every failed handshake (TLS_ACCEPT_THROTTLE_TIME,
fixed when Zenoh is built): 400 idle TCP connections timing out their TLS handshakes stalled
it 40 s, and an outsider that reopens them as they are closed stalled it for good (a new
member never linked within 25 s). peers.session.open_session sets TCP_DEFER_ACCEPT on its tls/
listeners: a connection that never sends a byte is never handed to Zenoh, so it never times
out a handshake there. Here the member's TLS handshake timeout is 300 ms and the outsider's
400 connections are held 2 s (six timeouts) before the new member comes: without the option
the server closes them as they time out (and a new member waits 40 s); with it, none is
closed and the member links while every one is still held."""

from __future__ import annotations

import select
import socket
import subprocess
import sys
import threading
import time

import pytest
from sensornet.peers.endpoints import tls_endpoint
from sensornet.peers.security import Security, make_keys
from sensornet.peers.session import DEFER_ACCEPT_S, _ports, free_port, open_session
from sensornet.protocol.keys import Keys

pytestmark = pytest.mark.network

IDLE = 400
HANDSHAKE_MS = 300
MEMBER = """
import sys
from sensornet.peers.security import Security
from sensornet.peers.session import open_session
from sensornet.protocol.keys import Keys
s = open_session(listen=[sys.argv[2]],
                 security=Security.load(sys.argv[1], "world", "idle", ["s1"]))
token = s.liveliness().declare_token(Keys("idle").alive("world"))
print("ready", flush=True)
sys.stdin.read()
s.close()
"""


def _closed(sock: socket.socket) -> bool:
    """Whether the other end closed this connection (readable with nothing to read)."""
    ready, _, _ = select.select([sock], [], [], 0)
    return bool(ready) and sock.recv(1, socket.MSG_PEEK) == b""


def test_endpoint_ports():
    assert _ports(["tls/127.0.0.1:7447#tls_handshake_timeout_ms=300", "tcp/0.0.0.0:9",
                   "tls/[::1]:8000?iface=lo", "tls/127.0.0.1:0"], "tls") == {7447, 8000}
    assert DEFER_ACCEPT_S > 0


def test_a_new_member_links_past_400_idle_connections_on_tls(tmp_path):
    make_keys("idle", ["world", "s1"], tmp_path)
    port = free_port()
    listen = f"{tls_endpoint(port)}#tls_handshake_timeout_ms={HANDSHAKE_MS}"
    member = subprocess.Popen([sys.executable, "-c", MEMBER, str(tmp_path), listen],
                              stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    socks: list[socket.socket] = []
    new = None
    try:
        assert member.stdout.readline().strip() == "ready"
        for _ in range(IDLE):
            socks.append(socket.create_connection(("127.0.0.1", port), timeout=10))
        time.sleep(2.0)  # several handshake timeouts: what used to close them and stall
        closed_before = sum(_closed(s) for s in socks)
        seen = threading.Event()
        new = open_session(connect=[tls_endpoint(port)],
                           security=Security.load(tmp_path, "s1", "idle", ["s1"]))
        sub = new.liveliness().declare_subscriber(Keys("idle").alive("world"),
                                                  lambda sample: seen.set(), history=True)
        assert seen.wait(60), "the new member never linked"
        sub.undeclare()
        # no idle connection reached a TLS handshake (none timed out and was closed), and the
        # member linked while the outsider still held every one
        assert closed_before == 0, f"{closed_before} idle connections were handshaken and closed"
        still_open = sum(not _closed(s) for s in socks)
        assert still_open == IDLE, f"{IDLE - still_open} idle connections were closed"
    finally:
        if new is not None:
            new.close()
        for s in socks:
            s.close()
        member.stdin.close()
        try:
            member.wait(timeout=30)
        except subprocess.TimeoutExpired:
            member.kill()
            member.wait()
