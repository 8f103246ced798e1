"""Scan bundles (protocol.bundle): one message per scan for a host's sensors, each entry the
exact bytes of that sensor's own scan message; bounded before anything is built."""

from __future__ import annotations

import msgpack
import numpy as np
import pytest
from sensornet.protocol.bundle import MAX_ENTRIES, pack_bundles, unpack_bundle
from sensornet.protocol.codec import Rejected, decode, encode
from sensornet.protocol.messages import Scan
from sensornet.sim.run.world_process import WorldError, run_world
from sensornet.sim.scenario import load_scenario


def _scan(name: str, k: int, n: int) -> bytes:
    z = np.arange(2 * n, dtype=float).reshape(n, 2)
    return encode(Scan(name, k, z, seq=k, send_time=1.0))


def test_a_bundle_carries_each_scan_byte_for_byte():
    entries = [(f"p{i:02d}", _scan(f"p{i:02d}", 7, i + 1)) for i in range(25)]
    (one,) = pack_bundles(7, entries)
    b = unpack_bundle(one)
    assert b.k == 7 and b.entries == entries
    assert decode(b.entries[3][1]).sensor == "p03"


def test_large_scans_are_cut_into_several_bundles_each_under_the_limit():
    entries = [(f"p{i:02d}", _scan(f"p{i:02d}", 2, 300)) for i in range(10)]  # ~10 kB each
    size = len(entries[0][1])
    parts = pack_bundles(2, entries, max_bytes=3 * size)
    assert len(parts) > 1 and all(len(p) <= 3 * size + 64 for p in parts)
    got = [e for p in parts for e in unpack_bundle(p).entries]
    assert got == entries  # nothing lost, in order
    (alone,) = pack_bundles(2, entries[:1], max_bytes=10)  # larger than the limit: alone
    assert unpack_bundle(alone).entries == entries[:1]


@pytest.mark.parametrize("data, reason", [
    (b"\xc1", "malformed"),
    (msgpack.packb({"k": 1}), "malformed"),
    (msgpack.packb([1, [["p00", "not bytes"]]]), "malformed"),
    (msgpack.packb([-1, []]), "malformed"),
    (msgpack.packb([1, [["p00", b"x"]] * (MAX_ENTRIES + 1)], use_bin_type=True), "malformed"),
    (b"\x00" * (3 << 20), "too-large"),
])
def test_a_bad_bundle_is_a_rejection_not_a_crash(data, reason):
    with pytest.raises(Rejected) as exc:
        unpack_bundle(data)
    assert exc.value.reason == reason


@pytest.mark.parametrize("bundles, kw, says", [
    ({"h1": ["s1", "s9"]}, {}, "unknown sensors ['s9']"),
    ({"h1": ["s1", "s2"], "h2": ["s2"]}, {}, "more than once"),
    ({"h1": ["s1", "s1"]}, {}, "more than once"),
    ({"h1": ["s1"]}, {"recover": True}, "plain runs"),
])
def test_the_world_refuses_bundles_it_cannot_send(bundles, kw, says):
    """Before any session opens: each a one-line error."""
    with pytest.raises(WorldError, match=says.replace("[", r"\[").replace("]", r"\]")):
        run_world(load_scenario("seed000"), "bundlenet", bundles=bundles, **kw)
