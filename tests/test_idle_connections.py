"""Idle connections do not lock members out (issue 25): an outsider holding 400 idle TCP
connections on a member's listener (no Zenoh handshake, ever) used to fill Zenoh's 100 pending
handshakes for 10 s each, so a new member waited 13 s for its link. With room for
peers.session.ACCEPT_PENDING handshakes the new member links while every idle connection is
still held open (none of them has timed out yet: no wall-clock budget needed)."""

from __future__ import annotations

import pytest
from sensornet.peers.session import ACCEPT_PENDING, endpoint, free_port, open_session
from sensornet.protocol.keys import Keys

from tests.idle import closed, idle_connections, member, sees_token

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


def test_a_new_member_links_past_400_idle_connections():
    assert ACCEPT_PENDING > IDLE
    port = free_port()
    with member(MEMBER, str(port)), idle_connections(port, IDLE) as socks:
        new = open_session(connect=[endpoint(port)])
        try:
            assert sees_token(new, Keys("idle").alive("member")), "the new member never linked"
            # linked while the outsider still held every idle connection: they did not hold it
            # up (before, it linked only after they had timed out and been closed, 13 s)
            still_open = sum(not closed(s) for s in socks)
            assert still_open == IDLE, f"{IDLE - still_open} idle connections were closed first"
        finally:
            new.close()
