"""``sensornet router`` in secure mode: members as Zenoh clients of one router process.

The router enforces the network's access control at its ingress (by each client's certificate
name); the members trust the ``router*`` certificate to relay. A router killed and restarted on
the same endpoint: the clients reconnect by themselves and messages flow again.
"""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import threading
import time

import pytest
import zenoh
from sensornet.peers.security import Security, make_keys, tls_endpoint
from sensornet.peers.session import free_port
from sensornet.protocol.keys import Keys

pytestmark = pytest.mark.network
PEERS = ("s1", "s2", "s3")


def _router(keys, ep) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "sensornet", "router", "--listen", ep,
                             "--secure", str(keys)], stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)


def _wait_listening(proc: subprocess.Popen, timeout: float = 30.0) -> None:
    """The router prints one line once it listens."""
    done = threading.Event()
    threading.Thread(target=lambda: (proc.stdout.readline(), done.set()), daemon=True).start()
    assert done.wait(timeout) and proc.poll() is None


def _client(keys, member: str, ep: str) -> zenoh.Session:
    c = zenoh.Config()
    c.insert_json5("mode", '"client"')
    c.insert_json5("scouting/multicast/enabled", "false")
    c.insert_json5("connect/endpoints", json.dumps([ep]))
    Security.load(keys, member, "rnet", PEERS).apply(c)
    return zenoh.open(c)


def test_clients_of_a_secure_router(tmp_path):
    keys = tmp_path / "keys"
    make_keys("rnet", ["world", *PEERS, "router"], keys)
    k = Keys("rnet")
    ep = tls_endpoint(free_port())
    router = _router(keys, ep)
    sessions = []
    try:
        _wait_listening(router)
        s1, s3 = _client(keys, "s1", ep), _client(keys, "s3", ep)
        sessions += [s1, s3]
        got = []
        arrived = threading.Event()

        def on(sample):
            got.append((str(sample.key_expr), sample.payload.to_bytes()))
            arrived.set()

        s1.declare_subscriber(k.estimate("*"), on)
        end = time.monotonic() + 10
        while not arrived.is_set() and time.monotonic() < end:  # the route is up
            s3.put(k.estimate("s2"), b"spoofed")  # refused by the router, every time
            s3.put(k.estimate("s3"), b"own")
            arrived.wait(0.05)
        assert arrived.is_set()
        assert {p for _, p in got} == {b"own"}, got  # s3's own estimate only

        # no certificate: the router refuses the client
        bare = zenoh.Config()
        bare.insert_json5("mode", '"client"')
        bare.insert_json5("connect/endpoints", json.dumps([ep]))
        bare.insert_json5("connect/timeout_ms", "1000")
        bare.insert_json5("connect/exit_on_failure", "true")
        bare.insert_json5("transport/link/tls/root_ca_certificate",
                          json.dumps(str(keys / "ca.pem")))
        try:
            zenoh.open(bare).close()
            refused = False
        except Exception:  # zenoh.ZError: "Unable to connect to any of [...]"
            refused = True
        assert refused

        # the router dies and comes back on the same endpoint: clients resume by themselves
        router.send_signal(signal.SIGKILL)
        router.wait()
        t_down = time.monotonic()
        router = _router(keys, ep)
        _wait_listening(router)
        t_up = time.monotonic()
        arrived.clear()
        while not arrived.is_set() and time.monotonic() < t_up + 15:
            s3.put(k.estimate("s3"), b"after")
            arrived.wait(0.02)
        assert arrived.is_set(), "clients did not resume after the router restart"
        resumed = time.monotonic() - t_up
        print(f"router down {t_up - t_down:.2f} s; messages flowed again {resumed:.2f} s "
              "after it was back")
        assert got[-1] == (k.estimate("s3"), b"after")
        assert all(p != b"spoofed" for _, p in got)
    finally:
        for s in sessions:
            s.close()
        if router.poll() is None:
            router.send_signal(signal.SIGTERM)
            try:
                router.wait(timeout=10)
            except subprocess.TimeoutExpired:
                router.kill()
                router.wait()
