"""A peer host's watched reports made and sent together (issue 38): the map marks of all its
peers in one vectorised call, equal to the bit to each peer's own; the reports in one message
(protocol.report_bundle) that the view splits back into the same reports and draws on the same
entities; hostile messages bounded before decoding and counted."""

from __future__ import annotations

import msgpack
import numpy as np
import pytest
import rerun as rr
from sensornet.peers.observer import (
    FUSED_SHOWN,
    heaviest_marginals,
    heaviest_marginals_many,
    pack_marks,
)
from sensornet.protocol.bundle import pack_bundles
from sensornet.protocol.codec import Rejected, decode, encode
from sensornet.protocol.messages import Telemetry, Tracks
from sensornet.protocol.report_bundle import REPORTS_HEAD, pack_reports, unpack_reports
from sensornet.sim.scenario import load_scenario
from sensornet.tracking.mixture import GaussianMixture

from benchmarks.bench_watched import watched_twin
from sensornet.bag_play import restamp
from sensornet.view import Batcher, ViewState


class _Rec:
    """A recording stream that keeps what it is sent: (entity, scan indexes, columns)."""

    def __init__(self) -> None:
        self.calls: list[tuple[str, list[int], list]] = []

    def send_columns(self, path, indexes, columns):
        self.calls.append((path, indexes[0].as_arrow_array().to_pylist(),
                           [c.as_arrow_array().to_pylist() for c in columns]))


def _mixture(rng, n: int, dim: int, ties: bool) -> GaussianMixture:
    """Random ``n`` components of ``dim``: asymmetric, indefinite and zero blocks; with
    ``ties`` every weight shared by several components (birth weights are)."""
    A = rng.normal(size=(n, dim, dim))
    covs = A @ A.transpose(0, 2, 1) + rng.normal(scale=0.3, size=(n, dim, dim))
    if n > 2:
        covs[0], covs[1] = 0.0, -np.eye(dim)
    w = rng.integers(1, 4, n) * 0.25 if ties else rng.uniform(0.0, 1.0, n)
    return GaussianMixture.trusted(w, rng.normal(size=(n, dim)) * 100, covs)


def test_a_hosts_marks_in_one_call_equal_each_peers_own_to_the_bit():
    """Mixtures of 4 and 6 dimensions in one call, empty ones, fewer and more components
    than shown, tied weights: the same bytes as :func:`heaviest_marginals` of each."""
    rng = np.random.default_rng(38)
    mixes = [_mixture(rng, n, dim, ties) for n, dim, ties in (
        (30, 4, True), (0, 4, False), (5, 6, False), (70, 4, False), (3, 4, True),
        (40, 6, True), (1, 4, False), (0, 6, False), (64, 4, True))]
    for shown in (1, 8, FUSED_SHOWN):
        got = heaviest_marginals_many(mixes, shown)
        assert len(got) == len(mixes)
        for mix, z in zip(mixes, got, strict=True):
            want = heaviest_marginals(mix, shown)
            assert z.shape == want.shape and z.dtype == want.dtype
            assert z.tobytes() == want.tobytes()
    assert sum(len(z) for z in got) > 3 * 100  # not all left out


def test_pack_marks_replaces_the_held_mixtures_in_every_report():
    rng = np.random.default_rng(1)
    a, b = _mixture(rng, 12, 4, True), _mixture(rng, 7, 4, False)
    reports = [Telemetry("s1", 3, points={"local/mixture": a, "pooled": np.ones((2, 2))}),
               Telemetry("s2", 3, points={"fused/mixture": b})]
    pack_marks(reports)
    assert reports[0].points["local/mixture"].tobytes() == heaviest_marginals(
        a, FUSED_SHOWN).tobytes()
    assert reports[1].points["fused/mixture"].tobytes() == heaviest_marginals(
        b, FUSED_SHOWN).tobytes()
    assert np.array_equal(reports[0].points["pooled"], np.ones((2, 2)))


def _reports() -> list[Telemetry]:
    rng = np.random.default_rng(5)
    return [Telemetry("s1", 4, {"latency_ms": 12.5, "trust/s2/weight": 0.25, "age": 1.0},
                      ("s2 joined", "WARN s3 trusted -> suspect (score 3.1)"),
                      {"local/mixture": heaviest_marginals(_mixture(rng, 9, 4, False), 64),
                       "particles": rng.normal(size=(5, 2)) * 1e3}),
            Telemetry("s2", 4, {}, (), {}),
            Telemetry("s3", 5, {"components/fused": 3.0}, (),
                      {"pda/s1": np.abs(rng.normal(size=(7, 2))), "cells": np.zeros((0, 2))})]


def _same(a: Telemetry, b: Telemetry) -> None:
    assert (a.sender, a.k, a.values, a.events, list(a.points)) == (
        b.sender, b.k, b.values, b.events, list(b.points))
    for name in a.points:
        assert a.points[name].tobytes() == b.points[name].tobytes()
    assert a.mixture is None and b.mixture is None


def _drawn(heard: list[tuple[str, bytes]], names=("s1", "s2", "s3")) -> tuple[dict, ViewState]:
    rec = _Rec()
    state = ViewState(Batcher(rr, rec), list(names))
    for key, payload in heard:
        state.receive(key, payload)
    state.b.flush()
    return {p: (s, c) for p, s, c in rec.calls}, state


def test_a_host_message_splits_into_the_reports_each_would_have_been_alone():
    """Each report split off equals the same report encoded alone and decoded (protocol 2:
    float32 points), the tracks ride as sent; the view draws the host's message on the same
    entities, rows and values as each peer's own bundle of tracks and report."""
    reports = _reports()
    tracks = {r.sender: encode(Tracks(r.sender, r.k, np.full((2, 4), 3.0))) for r in reports}
    items = [(r.sender, tracks[r.sender] if r.sender != "s2" else None, r) for r in reports]
    (payload,) = pack_reports(items, 1234.5)
    assert payload[:1] == REPORTS_HEAD
    msg = unpack_reports(payload)
    assert msg.send_time == 1234.5
    assert msg.entries == [("s1", tracks["s1"]), ("s3", tracks["s3"])]
    for got, r in zip(msg.reports, reports, strict=True):
        _same(got, decode(encode(r)))
    own = [(f"sensornet/net/telemetry/{n}", b) for n, t, r in items
           for b in pack_bundles(0, [*([(n, t)] if t else []), (n, encode(r))])]
    host, hs = _drawn([("sensornet/net/telemetries/h1", payload)])
    alone, als = _drawn(own)
    assert host == alone and hs.handled == als.handled == 5 and hs.rejected == 0
    assert {"peers/s1/local/means", "peers/s1/particles", "peers/s3/pda/s1/returns",
            "metrics/latency_ms/s1", "peers/s3/tracks"} <= set(host)


def test_points_beyond_float32_go_alone_as_protocol_1():
    """A report whose points do not fit float32 goes encoded alone (float64), as the codec
    writes it, and is drawn at full precision; a message of many splits past max_bytes."""
    big = Telemetry("s1", 2, {"age": 1.0}, (), {"particles": np.array([[1e40, 2.0]])})
    (payload,) = pack_reports([("s1", None, big)], 1.0)
    msg = unpack_reports(payload)
    assert msg.reports == [] and [n for n, _ in msg.entries] == ["s1"]
    assert decode(msg.entries[0][1]).points["particles"][0, 0] == 1e40
    many = [(f"s{i}", None, Telemetry(f"s{i}", 1, {"age": float(i)}, (),
                                      {"particles": np.ones((100, 2)) * i})) for i in range(40)]
    parts = pack_reports(many, 2.0, max_bytes=4000)
    assert len(parts) > 4 and all(len(p) < 4000 for p in parts)
    split = [r for p in parts for r in unpack_reports(p).reports]
    assert [(r.sender, r.values["age"]) for r in split] == [(f"s{i}", float(i))
                                                             for i in range(40)]


def test_hostile_host_messages_are_bounded_and_counted():
    """Too large: refused before anything is unpacked; not the layout, or blocks that do not
    match the counts: refused whole; a report that fails the Telemetry checks (a NaN point,
    65 events, a name too long): refused alone, the others drawn. The view counts each."""
    good = _reports()
    (payload,) = pack_reports([(r.sender, None, r) for r in good], 3.0)
    with pytest.raises(Rejected, match="too-large"):
        unpack_reports(payload, max_bytes=len(payload) - 1)
    body = msgpack.unpackb(payload, raw=False)
    bad = {"layout": [body[0], body[1], body[2], body[3]],
           "ts": ["now", *body[1:]],
           "counts": [body[0], body[1], [[*m[:5], [c + 1 for c in m[5]]] for m in body[2]],
                      body[3], body[4]],
           "negative": [body[0], body[1], [[*m[:5], [-1] * len(m[5])] for m in body[2]],
                        body[3], body[4]],
           "blocks": [*body[:4], body[4][:-8]]}
    for b in bad.values():
        with pytest.raises(Rejected):
            unpack_reports(msgpack.packb(b, use_bin_type=True))
    with pytest.raises(Rejected, match="malformed"):
        unpack_reports(b"\x95\xc1")
    nan = Telemetry("s2", 4, {}, (), {"particles": np.array([[np.nan, 0.0]])})
    loud = Telemetry("s3", 4, {}, tuple("x" for _ in range(65)), {})
    long = Telemetry("s1", 4, {"x" * 65: 1.0}, (), {})
    items = [(r.sender, None, r) for r in (good[0], loud, long, good[2])]
    (mixed,) = pack_reports(items, 3.0)
    got = unpack_reports(mixed).reports
    assert [type(r).__name__ for r in got] == ["Telemetry", "Rejected", "Rejected",
                                               "Telemetry"]
    (alone,) = pack_reports([("s2", None, nan)], 3.0)  # not finite: alone, then refused
    heard = [("sensornet/net/telemetries/h1", p) for p in (
        payload[:-3], mixed, b"\x95" + b"\x00" * 10, alone, msgpack.packb(bad["blocks"]))]
    _, state = _drawn(heard)
    assert state.rejected == 1 + 2 + 1 + 1 + 1 and state.handled == 2


def test_a_recorded_host_message_is_restamped_for_play():
    r = _reports()[0]
    tracks = encode(Tracks("s1", 4, np.zeros((1, 4)), send_time=5.0))
    (payload,) = pack_reports([("s1", tracks, r)], 5.0)
    out = restamp("sensornet/net/telemetries/h1", payload, 99.0)
    msg = unpack_reports(out)
    assert msg.send_time == 99.0 and decode(msg.entries[0][1]).send_time == 99.0
    _same(msg.reports[0], unpack_reports(payload).reports[0])


def test_the_view_draws_a_hosts_twin_run_as_its_peers_own_reports():
    """The twin of a network with every peer watched, its reports sent per host (two) and
    each peer its own: the view's picture is the same, entity by entity, row by row."""
    scn = load_scenario("seed000", {"scenario.num_scans": 6})
    heard: dict[int, list[tuple[str, bytes]]] = {0: [], 2: []}
    for hosts in heard:
        watched_twin(scn, 0, hosts, lambda t, key, b, h=hosts: heard[h].append((key, b)))
    assert all(k.split("/")[2] == "telemetries" for k, _ in heard[2])
    assert {b[:1] for _, b in heard[2]} == {REPORTS_HEAD}
    host, hs = _drawn(heard[2], scn.sensor_names)
    alone, als = _drawn(heard[0], scn.sensor_names)
    assert hs.rejected == als.rejected == 0 and hs.handled == als.handled > 0
    assert set(host) == set(alone)
    for path in alone:  # rows of an entity in the same order; the values equal
        assert host[path] == alone[path], path
    assert any(p.endswith("/local/means") for p in host)
