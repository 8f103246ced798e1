"""What the idle-connection tests share (tests/test_idle_connections.py, plain, and
tests/test_idle_connections_tls.py): a member process on a listener, an outsider's idle TCP
connections held on it, whether one was closed, and a new member seeing the member's token."""

from __future__ import annotations

import select
import socket
import subprocess
import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager


@contextmanager
def member(script: str, *args: str) -> Iterator[subprocess.Popen]:
    """``python -c script args`` once it printed ``ready`` (its token declared); on the way out
    its stdin is closed (it closes its session and ends), killed if it takes over 30 s."""
    proc = subprocess.Popen([sys.executable, "-c", script, *args], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline().strip() == "ready"
        yield proc
    finally:
        proc.stdin.close()
        try:
            proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


@contextmanager
def idle_connections(port: int, n: int) -> Iterator[list[socket.socket]]:
    """``n`` TCP connections to 127.0.0.1:``port`` that never send a byte, closed on the way out."""
    socks: list[socket.socket] = []
    try:
        for _ in range(n):
            socks.append(socket.create_connection(("127.0.0.1", port), timeout=10))
        yield socks
    finally:
        for s in socks:
            s.close()


def closed(sock: socket.socket) -> bool:
    """Whether the other end closed this connection (readable with nothing to read)."""
    ready, _, _ = select.select([sock], [], [], 0)
    return bool(ready) and sock.recv(1, socket.MSG_PEEK) == b""


def sees_token(session, key: str, timeout: float = 60) -> bool:
    """Whether ``session`` sees the liveliness token ``key`` (linked to its holder) in time."""
    seen = threading.Event()
    sub = session.liveliness().declare_subscriber(key, lambda sample: seen.set(), history=True)
    try:
        return seen.wait(timeout)
    finally:
        sub.undeclare()
