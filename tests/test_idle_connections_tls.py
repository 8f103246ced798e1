"""Idle connections do not lock members out of a ``tls/`` listener either (issue 36 item 3).

Zenoh's TLS accept loop sleeps 100 ms after every failed handshake (TLS_ACCEPT_THROTTLE_TIME,
fixed when Zenoh is built): 400 idle TCP connections timing out their TLS handshakes stalled
it 40 s, and an outsider that reopens them as they are closed stalled it for good (a new
member never linked within 25 s). peers.session.open_session sets TCP_DEFER_ACCEPT on its tls/
listeners: a connection that never sends a byte is never handed to Zenoh, so it never times
out a handshake there. Here the member's TLS handshake timeout is 300 ms; after the outsider's
400 idle connections it opens a canary that sends the first bytes of a TLS record and no more,
and waits until the member closes it (its handshake timed out), then a new member comes.
Without the option the 400 reach Zenoh before the canary (the kernel hands connections over in
order) and time out first: they are closed before it (and the canary only after the loop's
40 s of stalls); with it, none is closed and the member links while every one is still held."""

from __future__ import annotations

import socket

import pytest
from sensornet.peers.endpoints import tls_endpoint
from sensornet.peers.security import Security, make_keys
from sensornet.peers.session import DEFER_ACCEPT_S, _ports, free_port, open_session
from sensornet.protocol.keys import Keys

from tests.idle import closed, idle_connections, member, sees_token

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


def _closed_by_server(sock: socket.socket, timeout: float) -> bool:
    """Wait until the other end closes ``sock`` (end of stream or a reset); False on timeout."""
    sock.settimeout(timeout)
    try:
        while sock.recv(4096):
            pass
    except ConnectionResetError:
        return True
    except TimeoutError:
        return False
    return True


def test_endpoint_ports():
    assert _ports(["tls/127.0.0.1:7447#tls_handshake_timeout_ms=300", "tcp/0.0.0.0:9",
                   "tls/[::1]:8000?iface=lo", "tls/127.0.0.1:0"], "tls") == {7447, 8000}
    assert DEFER_ACCEPT_S > 0


def test_a_new_member_links_past_400_idle_connections_on_tls(tmp_path):
    make_keys("idle", ["world", "s1"], tmp_path)
    port = free_port()
    listen = f"{tls_endpoint(port)}#tls_handshake_timeout_ms={HANDSHAKE_MS}"
    with member(MEMBER, str(tmp_path), listen), idle_connections(port, IDLE) as socks:
        # a handshake timeout passes after the 400 came (what used to close them and stall):
        # the canary's, started after theirs would have been
        with socket.create_connection(("127.0.0.1", port), timeout=10) as canary:
            canary.sendall(b"\x16\x03\x01")  # a TLS handshake record's header, cut short
            assert _closed_by_server(canary, 60), "the canary's handshake never timed out"
        closed_before = sum(closed(s) for s in socks)
        new = open_session(connect=[tls_endpoint(port)],
                           security=Security.load(tmp_path, "s1", "idle", ["s1"]))
        try:
            assert sees_token(new, Keys("idle").alive("world")), "the new member never linked"
            # no idle connection reached a TLS handshake (none timed out and was closed), and
            # the member linked while the outsider still held every one
            assert closed_before == 0, (f"{closed_before} idle connections were handshaken "
                                        f"and closed")
            still_open = sum(not closed(s) for s in socks)
            assert still_open == IDLE, f"{IDLE - still_open} idle connections were closed"
        finally:
            new.close()
