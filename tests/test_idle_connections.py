"""Idle connections do not lock members out (issue 25): an outsider holding 400 idle TCP
connections on a member's listener (no Zenoh handshake, ever) used to fill Zenoh's 100 pending
handshakes for 10 s each, so a new member waited 13 s for its link. With room for
peers.session.ACCEPT_PENDING handshakes the new member links while every idle connection is
still held open (none of them has timed out yet: no wall-clock budget needed)."""

from __future__ import annotations

import select
import socket
import subprocess
import sys
import threading

import pytest
from sensornet.peers.session import ACCEPT_PENDING, endpoint, free_port, open_session
from sensornet.protocol.keys import Keys

pytestmark = pytest.mark.network

IDLE = 400
MEMBER = """
import sys
from peers.session import open_session, endpoint
from protocol.keys import Keys
s = open_session(listen=[endpoint(int(sys.argv[1]))])
token = s.liveliness().declare_token(Keys("idle").alive("member"))
print("ready", flush=True)
sys.stdin.read()
s.close()
"""


def _closed(sock: socket.socket) -> bool:
    """Whether the other end closed this connection (readable with nothing to read)."""
    ready, _, _ = select.select([sock], [], [], 0)
    return bool(ready) and sock.recv(1, socket.MSG_PEEK) == b""


def test_a_new_member_links_past_400_idle_connections(tmp_path):
    assert ACCEPT_PENDING > IDLE
    port = free_port()
    member = subprocess.Popen([sys.executable, "-c", MEMBER, str(port)], stdin=subprocess.PIPE,
                              stdout=subprocess.PIPE, text=True)
    socks: list[socket.socket] = []
    new = None
    try:
        assert member.stdout.readline().strip() == "ready"
        for _ in range(IDLE):
            socks.append(socket.create_connection(("127.0.0.1", port), timeout=10))
        seen = threading.Event()
        new = open_session(connect=[endpoint(port)])
        sub = new.liveliness().declare_subscriber(Keys("idle").alive("member"),
                                                  lambda sample: seen.set(), history=True)
        assert seen.wait(60), "the new member never linked"
        sub.undeclare()
        # linked while the outsider still held every idle connection: they did not hold it up
        # (before, it linked only after they had timed out and been closed, 13 s)
        still_open = sum(not _closed(s) for s in socks)
        assert still_open == IDLE, f"{IDLE - still_open} idle connections were closed first"
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
