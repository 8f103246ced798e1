"""One key parse and one decode per delivered message (issue 37 item 5).

A message goes from :meth:`peers.transport.Transport.deliver` (admission) through the inbox and
:meth:`peers.runtime.PeerRuntime.step` (link faults) to the core. Counting wrappers replace
``parse_key`` in every module that imported it and the core's decode: each delivered message
is parsed and decoded exactly once, with link faults on or off, and the core still takes it.
"""

from __future__ import annotations

import sys
import time
from collections import Counter

import numpy as np
import pytest
from sensornet.peers import admission
from sensornet.peers.faultplan import Constant, FaultPlan, LinkFaults
from sensornet.peers.faults import FaultInjector
from sensornet.peers.host import PeerHost
from sensornet.peers.inbound import Delivered, delivered
from sensornet.peers.runtime import PeerRuntime, RuntimeOptions
from sensornet.protocol.codec import encode
from sensornet.protocol.messages import Estimate, Scan
from sensornet.sim.run.peers import make_peer
from sensornet.sim.scenario import load_scenario
from sensornet.sim.world.graphs import network_scenario
from sensornet.tracking.mixture import GaussianMixture


def _counting(monkeypatch, *rts: PeerRuntime) -> Counter:
    """Count every ``parse_key`` call (in any module that imported it) and the cores' decodes."""
    calls: Counter = Counter()
    original = admission.parse_key

    def parse_key(key, network):
        calls["parse_key"] += 1
        return original(key, network)

    for mod in list(sys.modules.values()):
        if mod is not None and getattr(mod, "parse_key", None) is original:
            monkeypatch.setattr(mod, "parse_key", parse_key)
    for rt in rts:
        monkeypatch.setattr(rt.core, "decode", _counted(rt.core.decode, calls))
    return calls


def _counted(decode, calls: Counter):
    """``decode``, counting its calls under ``decode`` in ``calls``."""
    def counted_decode(payload, limits):
        calls["decode"] += 1
        return decode(payload, limits)

    return counted_decode


def _runtime(tmp_path, faults: FaultInjector | None = None) -> PeerRuntime:
    path = tmp_path / "three.toml"
    path.write_text(network_scenario(3, 2, scans=10, rounds=1, speed=5.0, deadline=1.0))
    core = make_peer(load_scenario(str(path)), "p00", network="net")
    return PeerRuntime(core, RuntimeOptions(rerun=False, faults=faults))


def _deliver(rt: PeerRuntime, key: str, payload: bytes) -> None:
    rt.transport.deliver(key, payload)
    items = []
    while not rt.transport.q.empty():
        items.append(rt.transport.q.get_nowait())
    assert len(items) == 1 and type(items[0]) is Delivered
    rt.step(items, rt.transport.q.empty)


def _estimate() -> bytes:
    mix = GaussianMixture(np.ones(1), np.zeros((1, 4)), np.eye(4)[None])
    return encode(Estimate("p01", 1, mix))


@pytest.mark.parametrize("faults", [None, FaultInjector(
    FaultPlan(default=LinkFaults(delay=Constant(0.0))), seed=1)], ids=["plain", "faults"])
def test_an_estimate_is_parsed_and_decoded_once(tmp_path, monkeypatch, faults):
    rt = _runtime(tmp_path, faults)
    calls = _counting(monkeypatch, rt)
    _deliver(rt, rt.core.keys.estimate("p01"), _estimate())
    assert calls == {"parse_key": 1, "decode": 1}
    assert rt.core.received["estimate"] == 1 and not rt.core.rejected
    assert rt.core.admission.queued_total == 0  # taken off the inbox
    if faults is not None:
        assert len(faults.log) == 1 and len(rt.held) == 0  # held, then fed when due


def test_a_scan_is_parsed_and_decoded_once(tmp_path, monkeypatch):
    rt = _runtime(tmp_path)
    calls = _counting(monkeypatch, rt)
    _deliver(rt, rt.core.keys.scan("p00"), encode(Scan("p00", 1, np.zeros((2, 2)), seq=1)))
    assert calls == {"parse_key": 1, "decode": 1}
    assert rt.core.received["scan"] == 1 and not rt.core.rejected
    assert rt.core.consensus.last_k == 1


def test_a_batched_hosts_scans_are_parsed_and_decoded_once(tmp_path, monkeypatch):
    """A host computing its peers' local steps together (:mod:`peers.host_batching`) reads each
    scan ahead of its step (``PeerCore.scan_step``) with the route its transport parsed; the
    step then takes the route and the message decoded there, so neither is done again."""
    path = tmp_path / "three.toml"
    path.write_text(network_scenario(3, 2, scans=10, rounds=1, speed=5.0, deadline=1.0))
    scn = load_scenario(str(path))
    host = PeerHost("h1", [(make_peer(scn, n, network="net"), RuntimeOptions(rerun=False))
                           for n in ("p00", "p01")], ((), (), None, None, False))
    assert host._batched == {0, 1}
    calls = _counting(monkeypatch, *host.peers)
    host._active = [0, 1]
    sent: list[str] = []  # not opened: what the peers publish is only noted (no hand-over)
    for rt in host.peers:
        monkeypatch.setattr(rt.transport, "publish", lambda channel, payload: sent.append(channel))
        sensor = rt.core.cfg.sensor
        rt.transport.deliver(rt.core.keys.scan(sensor),
                             encode(Scan(sensor, 1, np.zeros((2, 2)), seq=1)))
    while not host.q.empty():
        slot, item = host.q.get_nowait()
        assert type(item) is Delivered
        host._backlog[slot].append((time.time(), item))
    host._work(time.time(), time.monotonic())
    assert calls == {"parse_key": 2, "decode": 2}
    assert host.counts["steps_prepared"] == 2  # the look ahead ran: the case counted here
    for rt in host.peers:
        assert rt.core.received["scan"] == 1 and not rt.core.rejected
        assert rt.core.consensus.last_k == 1


def test_a_malformed_estimate_is_decoded_once_and_counted(tmp_path, monkeypatch):
    rt = _runtime(tmp_path, FaultInjector(FaultPlan(default=LinkFaults()), seed=1))
    calls = _counting(monkeypatch, rt)
    _deliver(rt, rt.core.keys.estimate("p01"), b"\x93not an estimate")
    assert calls == {"parse_key": 1, "decode": 1}
    assert sum(rt.core.rejected.values()) == 1


def test_a_plain_inbox_item_gets_its_route_once():
    item = ("msg", "sensornet/net/estimate/p01", b"x")
    d = delivered(item, "net")
    assert d == item and d.route == admission.Route("estimate", "p01")
    assert delivered(d, "net") is d  # already parsed: as it is
    live = ("live", "p01", True)
    assert delivered(live, "net") is live
    assert delivered(("msg", "other/net/x", b""), "net").route is None
