"""A host's reports decoded together by the view (issue 38,
:func:`protocol.report_bundle.unpack_reports_together`): the same reports as decoding each
alone (:func:`protocol.report_bundle.unpack_reports`), and for every check of the codec's
Telemetry decoder, a message with one report failing it gives that report refused for the
same reason and the others kept, as each alone does."""

from __future__ import annotations

import dataclasses

import msgpack
import numpy as np
import pytest
from sensornet.protocol import report_bundle
from sensornet.protocol.codec import DEFAULT_LIMITS, Rejected, decode, encode
from sensornet.protocol.messages import Telemetry
from sensornet.protocol.report_bundle import pack_reports, unpack_reports, unpack_reports_together


def _reports(rng, n: int = 5) -> list[Telemetry]:
    """Peers' reports: 0-3 values, events, point sets of 0-6 points (an empty report too)."""
    out = []
    for i in range(n):
        values = {f"v{j}/p{i}": float(rng.normal()) for j in range(i % 4)}
        events = tuple(f"event {j}" for j in range(i % 3))
        points = {f"set{j}": rng.normal(size=(int(rng.integers(0, 7)), 2)) * 1e3
                  for j in range(i % 3)}
        out.append(Telemetry(f"p{i}", 10 + i, values, events, points))
    return out


def _same(a, b) -> None:
    """``a`` and ``b`` the same decoded report (every field, points' dtype and shape too),
    or both refused for the same reason."""
    if isinstance(a, Rejected) or isinstance(b, Rejected):
        assert isinstance(a, Rejected) and isinstance(b, Rejected), (a, b)
        assert a.reason == b.reason
        return
    assert (a.sender, a.k, a.values, a.events, a.send_time, list(a.points), a.mixture) == (
        b.sender, b.k, b.values, b.events, b.send_time, list(b.points), b.mixture)
    assert all(type(v) is float for v in a.values.values())
    for name, z in a.points.items():
        w = b.points[name]
        assert z.dtype == w.dtype and z.shape == w.shape and z.tobytes() == w.tobytes()


def _both(payload: bytes, limits=DEFAULT_LIMITS) -> list:
    """The reports decoded together, checked equal to each alone; returned."""
    together = unpack_reports_together(payload, limits=limits)
    alone = unpack_reports(payload, limits=limits)
    assert (together.send_time, together.entries) == (alone.send_time, alone.entries)
    assert len(together.reports) == len(alone.reports)
    for a, b in zip(together.reports, alone.reports, strict=True):
        _same(a, b)
    return together.reports


def test_together_is_each_alone_and_takes_no_report_alone(monkeypatch):
    """Good messages (1-12 reports, tracks entries among them): each report as the codec
    decodes it alone, and as :func:`unpack_reports` splits it; no report decoded alone."""
    rng = np.random.default_rng(38)
    for n in (1, 2, 5, 12):
        reports = _reports(rng, n)
        items = [(r.sender, b"tracks" if i % 2 else None, r) for i, r in enumerate(reports)]
        (payload,) = pack_reports(items, 77.25)
        alone = unpack_reports(payload)
        with monkeypatch.context() as m:
            m.setattr(report_bundle, "_each_alone", None)  # the batch itself, no fallback
            got = unpack_reports_together(payload)
        assert got.entries == alone.entries and got.send_time == 77.25
        for g, a, r in zip(got.reports, alone.reports, reports, strict=True):
            _same(g, a)
            _same(g, decode(encode(dataclasses.replace(r, send_time=77.25))))


def _body(reports: list[Telemetry]) -> list:
    return msgpack.unpackb(_pack_at(reports), raw=False)


def _pack_at(reports: list[Telemetry]) -> bytes:
    (payload,) = pack_reports([(r.sender, None, r) for r in reports], 5.0)
    return payload


def _with(body: list, i: int, field: int, value) -> bytes:
    """``body`` with report ``i``'s meta ``field`` (0 sender, 1 scan, 2 value names, 3
    events, 4 point-set names, 5 counts) set to ``value``."""
    meta = [list(m) for m in body[2]]
    meta[i][field] = value
    return msgpack.packb([body[0], body[1], meta, body[3], body[4]], use_bin_type=True)


def _block(body: list, i: int, which: int, dtype: str, value: float) -> bytes:
    """``body`` with the first value (``which`` 3) or point coordinate (4) of report ``i``
    set to ``value``."""
    meta = body[2]
    if which == 3:
        at = sum(len(m[2]) for m in meta[:i])
    else:
        at = 2 * sum(sum(m[5]) for m in meta[:i])
    block = np.frombuffer(body[which], dtype=dtype).copy()
    block[at] = value
    out = list(body)
    out[which] = block.tobytes()
    return msgpack.packb(out, use_bin_type=True)


def _one_refused(payload: bytes, i: int, reason: str, limits=DEFAULT_LIMITS) -> None:
    got = _both(payload, limits)
    assert [isinstance(r, Rejected) for r in got] == [j == i for j in range(len(got))]
    assert got[i].reason == reason


BASE = [Telemetry("p0", 1, {"a": 1.0}, ("hello",), {"s": np.ones((2, 2))}),
        Telemetry("p1", 2, {"a": 2.0, "b": 3.0}, ("x", "y"), {"s": np.ones((3, 2)),
                                                             "t": np.zeros((1, 2))}),
        Telemetry("p2", 3, {"c": 4.0}, (), {"u": np.full((2, 2), 5.0)})]
"""Three reports with values, events and points each; report 1 is made bad below."""


@pytest.mark.parametrize("field, value, reason", [
    (0, 7, "field"),                    # sender not a string
    (0, "", "field"),                   # sender empty
    (0, "p" * 65, "field"),             # sender longer than max_name
    (1, True, "field"),                 # scan a bool
    (1, 2.0, "field"),                  # scan a float
    (1, -1, "field"),                   # scan negative
    (1, 1 << 53, "field"),              # scan beyond 2**53
    (2, ["a", 3], "field"),             # a value name not a string
    (2, ["a", ""], "field"),            # a value name empty
    (2, ["a", "b" * 65], "field"),      # a value name too long
    (3, "x", "field"),                  # events not a list
    (3, ["x"] * 65, "field"),           # 65 events
    (3, ["x", 4], "field"),             # an event not a string
    (3, ["x", "y" * 401], "field"),     # an event of 401 characters
    (4, "st", "field"),                 # point-set names not a list
    (4, ["s", 5], "field"),             # a point-set name not a string
    (4, ["s", ""], "field"),            # a point-set name empty
    (4, ["s", "t" * 65], "field"),      # a point-set name too long
    (4, ["s"], "shape"),                # fewer names than counts
])
def test_a_report_failing_a_check_is_refused_alone(field, value, reason):
    """One report's meta failing one of the Telemetry decoder's checks: that report refused
    for the reason decoding it alone gives, the two others decoded as alone."""
    _one_refused(_with(_body(BASE), 1, field, value), 1, reason)


def test_too_many_point_sets_or_values_or_points_refused_alone():
    """17 point sets; more value names than 4 max_entries; more points in a report than
    max_measurements (each set within it): refused alone, as alone."""
    sets = Telemetry("p1", 2, {}, (), {f"s{j}": np.ones((1, 2)) for j in range(17)})
    _one_refused(_pack_at([BASE[0], sets, BASE[2]]), 1, "too-many")
    small = dataclasses.replace(DEFAULT_LIMITS, max_entries=2, max_measurements=4)
    many = Telemetry("p1", 2, {f"v{j}": 1.0 for j in range(9)}, (), {})
    _one_refused(_pack_at([BASE[0], many, BASE[2]]), 1, "too-many", small)
    wide = Telemetry("p1", 2, {}, (), {"s": np.ones((3, 2)), "t": np.ones((2, 2))})
    _one_refused(_pack_at([BASE[0], wide, BASE[2]]), 1, "too-many", small)
    fits = Telemetry("p1", 2, {f"v{j}": 1.0 for j in range(8)}, (), {"s": np.ones((4, 2))})
    assert not any(isinstance(r, Rejected) for r in _both(_pack_at([fits]), small))


@pytest.mark.parametrize("which, dtype", [(3, "<f8"), (4, "<f4")])
@pytest.mark.parametrize("value", [np.nan, np.inf])
def test_a_report_with_a_value_or_point_not_finite_is_refused_alone(which, dtype, value):
    """A NaN or infinite value (float64 block) or map point (float32 block) in report 1:
    refused alone ('nonfinite'), the others kept."""
    _one_refused(_block(_body(BASE), 1, which, dtype, value), 1, "nonfinite")


def test_a_send_time_not_finite_refuses_every_report():
    """The message's send time is every report's: infinite, each refused as alone."""
    body = _body(BASE)
    body[0] = float("inf")
    got = _both(msgpack.packb(body, use_bin_type=True))
    assert [r.reason for r in got] == ["nonfinite"] * 3


def test_a_refused_whole_is_refused_as_before():
    """Layout failures are :func:`unpack_reports`' own: refused whole, the same reason."""
    body = _body(BASE)
    for bad in ([body[0], body[1], body[2], body[3]], [*body[:4], body[4][:-8]]):
        payload = msgpack.packb(bad, use_bin_type=True)
        with pytest.raises(Rejected) as alone:
            unpack_reports(payload)
        with pytest.raises(Rejected) as together:
            unpack_reports_together(payload)
        assert together.value.reason == alone.value.reason
