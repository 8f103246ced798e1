"""The world's scan bundles decoded together by the view (issue 38,
:func:`sensornet.view_scans.scans_together`): the same scans as :func:`decode` of each, and
for every check of the codec's scan decoder a payload that only it refuses: together gives
None, and the view refuses that one scan alone (counted) and draws the others as if each had
come on its own key."""

from __future__ import annotations

import math

import msgpack
import numpy as np
import pytest
import rerun as rr
from sensornet.protocol.bundle import pack_bundles
from sensornet.protocol.codec import DEFAULT_LIMITS, Limits, Rejected, decode, encode
from sensornet.protocol.messages import Scan, Tracks

from sensornet.view_columns import Batcher
from sensornet.view_scans import scans_together
from sensornet.view_state import ViewState

NAMES = [f"s{i}" for i in range(5)]


def _scans(rng) -> list[Scan]:
    """Five sensors' scans: 0-4 plots, protocol 1 and (with ages) protocol 2 mixed."""
    return [Scan(n, 7, rng.normal(size=(i, 2)) * 100, seq=7 + i, send_time=3.25 + i,
                 ages=rng.uniform(0, 0.1, i) if i % 2 else None)
            for i, n in enumerate(NAMES)]


def _same(a: Scan, b: Scan) -> None:
    assert (a.sensor, a.k, a.seq, a.send_time) == (b.sensor, b.k, b.seq, b.send_time)
    assert type(a.send_time) is type(b.send_time) is float
    for f in ("z", "ages"):
        x, y = getattr(a, f), getattr(b, f)
        assert (x is None) == (y is None), f
        if x is not None:
            assert x.dtype == y.dtype and x.shape == y.shape and np.array_equal(x, y), f


def _wire(i: int, v: int = 1, s="s2", k=7, q=9, ts=1.5, x=None, a=None, kind="S") -> bytes:
    """Scan ``i``'s message written field by field (each field as given, checked or not)."""
    x = np.arange(2 * i, dtype="<f8").tobytes() if x is None else x
    if v == 1:
        return msgpack.packb([1, kind, s, k, q, ts, x], use_bin_type=True)
    a = np.zeros(i, "<f8").tobytes() if a is None else a
    return msgpack.packb([2, kind, s, k, q, ts, a, x], use_bin_type=True)


def test_together_is_each_alone():
    """Every field as decode gives it, dtype and shape too; an int send time read as a
    float, as the codec does; no scans: an empty list."""
    payloads = [encode(s) for s in _scans(np.random.default_rng(3))]
    payloads.append(_wire(2, ts=12))
    got = scans_together(payloads)
    assert got is not None and len(got) == len(payloads)
    for payload, g in zip(payloads, got, strict=True):
        _same(decode(payload), g)
    assert scans_together([]) == []


_NAN = np.array([[1.0, math.nan]]).tobytes()
BAD = {  # what one check of the codec's scan decoder refuses (and nothing else does)
    "not msgpack": b"\xc1\x00",
    "points not bytes": _wire(1, x="a" * 16),
    "points not whole rows": _wire(1, x=b"\x00" * 24),
    "too many points": _wire(4),
    "ages not bytes": _wire(1, v=2, a="a" * 8),
    "ages too few": _wire(2, v=2, a=b"\x00" * 8),
    "ages not finite": _wire(1, v=2, a=np.array([math.inf]).tobytes()),
    "points not finite": _wire(1, x=_NAN),
    "sensor not a name": _wire(1, s=5),
    "sensor empty": _wire(1, s=""),
    "sensor too long": _wire(1, s="s" * 65),
    "scan index negative": _wire(1, k=-1),
    "scan index too large": _wire(1, k=1 << 53),
    "scan index a bool": _wire(1, k=True),
    "scan index a float": _wire(1, k=7.0),
    "sequence negative": _wire(1, q=-1),
    "sequence too large": _wire(1, q=1 << 53),
    "sequence a bool": _wire(1, q=False),
    "send time not finite": _wire(1, ts=math.inf),
    "send time NaN": _wire(1, ts=math.nan),
    "send time a bool": _wire(1, ts=True),
    "send time a string": _wire(1, ts="1.5"),
}
LIMITS = Limits(max_measurements=3)


def _kept_state() -> tuple[ViewState, dict[str, list]]:
    """A view state whose flushes land in the returned dict: entity path -> its columns."""
    rows: dict[str, list] = {}

    class Keep:
        def send_columns(self, path, indexes, columns):
            rows[path] = [c.as_arrow_array().to_pylist() for c in columns]

    return ViewState(Batcher(rr, Keep()), NAMES), rows


def _drawn(entries: list[tuple[str, bytes]], bundled: bool) -> tuple[ViewState, dict]:
    state, rows = _kept_state()
    if bundled:
        (message,) = pack_bundles(7, entries)
        state.receive("sensornet/net/scans/h1", message)
    else:
        for name, payload in entries:
            state.receive(f"sensornet/net/scan/{name}", payload)
    state.b.flush()
    return state, rows


def test_a_bundle_s_scans_drawn_as_each_alone():
    """A good bundle: decoded together, the rows of its scans heard one by one on their keys."""
    entries = [(s.sensor, encode(s)) for s in _scans(np.random.default_rng(4))]
    assert scans_together([p for _, p in entries]) is not None
    (a, rows_a), (b, rows_b) = _drawn(entries, True), _drawn(entries, False)
    assert (a.handled, a.rejected) == (b.handled, b.rejected) == (5, 0)
    assert rows_a == rows_b and {f"world/scans/{n}" for n in NAMES} <= set(rows_a)


@pytest.mark.parametrize("case", sorted(BAD))
def test_a_scan_failing_a_check_is_refused_alone(case):
    """The bad scan is refused by decode (the reference), makes the batch None, and in a
    bundle is counted as refused while the other four are drawn as each alone."""
    bad = BAD[case]
    limits = LIMITS if case == "too many points" else DEFAULT_LIMITS
    with pytest.raises(Rejected):
        decode(bad, limits)
    good = [encode(s) for s in _scans(np.random.default_rng(5))]
    assert scans_together([*good[:2], bad, *good[3:]], limits) is None
    assert scans_together([bad], limits) is None
    if limits is not DEFAULT_LIMITS:
        return  # the view decodes with the default limits
    entries = [(n, bad if n == "s2" else p) for n, p in zip(NAMES, good, strict=True)]
    (a, rows_a), (b, rows_b) = _drawn(entries, True), _drawn(entries, False)
    assert (a.handled, a.rejected) == (b.handled, b.rejected) == (4, 1)
    assert rows_a == rows_b and "world/scans/s2" not in rows_a


def test_another_message_on_a_scan_key_drawn_as_alone():
    """Not a scan (tracks in the world's bundle): no batch, and drawn as each alone draws it
    (decode takes any message type there), none refused."""
    good = [encode(s) for s in _scans(np.random.default_rng(6))]
    entries = [(n, encode(Tracks("s2", 7, np.ones((1, 4)))) if n == "s2" else p)
               for n, p in zip(NAMES, good, strict=True)]
    assert scans_together([p for _, p in entries]) is None
    (a, rows_a), (b, rows_b) = _drawn(entries, True), _drawn(entries, False)
    assert (a.handled, a.rejected) == (b.handled, b.rejected) == (5, 0)
    assert rows_a == rows_b and "peers/s2/tracks" in rows_a
