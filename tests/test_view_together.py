"""A host's tracks decoded together by the view (issue 38, :func:`view_state.tracks_together`):
the same messages as decoding each alone, and a refused one refused alone (counted) while
the others of its host are drawn."""

from __future__ import annotations

import numpy as np
import pytest
import rerun as rr
from sensornet.protocol.codec import decode, encode
from sensornet.protocol.messages import Telemetry, Tracks
from sensornet.protocol.report_bundle import pack_reports

from sensornet.view_columns import Batcher
from sensornet.view_state import ViewState, tracks_together

FIELDS = ("states", "ids", "covs", "existence", "status")


class _Calls:
    def __init__(self) -> None:
        self.paths: list[str] = []

    def send_columns(self, path, indexes, columns):
        self.paths.append(path)


def _tracks(peer: str, k: int, n: int, rng, d: int = 4, labelled: bool = True) -> Tracks:
    A = rng.normal(size=(n, d, d))
    return Tracks(peer, k, rng.normal(size=(n, d)) * 100, seq=k, send_time=12.5,
                  **({"ids": rng.integers(0, 9, (n, 3)),
                      "covs": A @ A.transpose(0, 2, 1) + np.eye(d),
                      "existence": rng.uniform(0, 1, n),
                      "status": rng.integers(0, 2, n).astype(np.int8)} if labelled else {}))


def test_together_is_each_alone():
    """Peers with 0-3 tracks: every field as :func:`decode` gives it, dtype and shape too."""
    rng = np.random.default_rng(5)
    payloads = [encode(_tracks(f"p{i}", 7, i % 4, rng)) for i in range(9)]
    got = tracks_together(payloads)
    assert got is not None and len(got) == 9
    for payload, g in zip(payloads, got, strict=True):
        alone = decode(payload)
        assert (g.sender, g.k, g.seq, g.send_time) == (alone.sender, alone.k, alone.seq,
                                                       alone.send_time)
        for f in FIELDS:
            a, b = getattr(alone, f), getattr(g, f)
            assert a.dtype == b.dtype and a.shape == b.shape and np.array_equal(a, b), f


def _bad_status(t: Tracks) -> Tracks:
    return Tracks(t.sender, t.k, t.states, ids=t.ids, covs=t.covs, existence=t.existence,
                  status=np.full(len(t.states), 2, np.int8))


def _bad_cov(t: Tracks) -> Tracks:
    return Tracks(t.sender, t.k, t.states, ids=t.ids, covs=-t.covs, existence=t.existence,
                  status=t.status)


@pytest.mark.parametrize("odd", ["status", "cov", "unlabelled", "six-d", "telemetry"])
def test_one_unlike_or_refused_leaves_each_alone(odd):
    """One entry refused (status 2, a covariance not positive definite) or unlike the rest
    (protocol 1, another dimension, a report): no batch (None), and the view decodes each
    alone: the refused one counted, every other peer's tracks drawn."""
    rng = np.random.default_rng(6)
    tracks = [_tracks(f"p{i}", 3, 2, rng) for i in range(4)]
    if odd == "status":
        tracks[2] = _bad_status(tracks[2])
    elif odd == "cov":
        tracks[2] = _bad_cov(tracks[2])
    elif odd == "unlabelled":
        tracks[2] = _tracks("p2", 3, 2, rng, labelled=False)
    elif odd == "six-d":
        tracks[2] = _tracks("p2", 3, 2, rng, d=6)
    payloads = [encode(t) for t in tracks]
    if odd == "telemetry":
        payloads[2] = encode(Telemetry("p2", 3, {"age": 1.0}, (), {}, None))
    assert tracks_together(payloads) is None
    refused = odd in ("status", "cov")
    rec = _Calls()
    state = ViewState(Batcher(rr, rec), [f"p{i}" for i in range(4)])
    items = [(f"p{i}", p, Telemetry(f"p{i}", 3, {"age": 1.0}, (), {}, None))
             for i, p in enumerate(payloads)]
    (message,) = pack_reports(items, 1.0)
    state.receive("sensornet/net/telemetries/h1", message)
    state.b.flush()
    assert state.rejected == int(refused)
    drawn = {p.split("/")[1] for p in rec.paths if p.endswith("/tracks")}
    assert drawn == ({"p0", "p1", "p3"} if refused else
                     {"p0", "p1", "p2", "p3"} if odd != "telemetry" else {"p0", "p1", "p3"})


def _kept_state(names: list[str]) -> tuple[ViewState, dict[str, list]]:
    """A view state whose flushes land in the returned dict: entity path -> its columns."""
    rows: dict[str, list] = {}

    class Keep:
        def send_columns(self, path, indexes, columns):
            rows[path] = [c.as_arrow_array().to_pylist() for c in columns]

    return ViewState(Batcher(rr, Keep()), names), rows


def test_a_host_s_tracks_drawn_together_as_alone():
    """A host's reports with every tracks entry alike: the view draws the same rows as from
    the same tracks heard one by one on each peer's report key; an entry naming another peer
    is refused, counted."""
    rng = np.random.default_rng(8)
    tracks = [_tracks(f"p{i}", 4, i % 3, rng) for i in range(5)]
    kept = {}
    for side in ("host", "alone"):
        state, rows = _kept_state([t.sender for t in tracks])
        if side == "host":
            items = [(t.sender, encode(t), Telemetry(t.sender, 4, {}, (), {}, None))
                     for t in tracks]
            items[4] = ("p4", encode(tracks[0]), items[4][2])  # p0's tracks on p4's entry
            (message,) = pack_reports(items, 1.0)
            state.receive("sensornet/net/telemetries/h1", message)
            assert state.rejected == 1
        else:
            for t in tracks[:4]:
                state.receive(f"sensornet/net/telemetry/{t.sender}", encode(t))
        state.b.flush()
        kept[side] = {p: r for p, r in rows.items() if p.startswith("peers/")}
    assert kept["host"] == kept["alone"] and len(kept["host"]) >= 4 * 2


def test_a_host_s_marginals_drawn_together_as_alone():
    """Reports with local and fused position marginals (0-5 each) and other point sets, in
    one host message: the rows each peer's own report would draw (the marks made in one call,
    :func:`view_state.marginal_marks_many`); a set not of whole marginals (4 points) counted
    as refused, not drawn and not raised, on either path."""
    rng = np.random.default_rng(9)
    reports = []
    for i in range(6):
        points = {"local/mixture": rng.normal(size=(3 * (i % 4), 2)) * 50,
                  "particles": rng.normal(size=(i, 2)),
                  "fused/mixture": np.abs(rng.normal(size=(3 * (5 - i), 2)))}
        if i == 2:
            points["fused/mixture"] = np.ones((4, 2))
        reports.append(Telemetry(f"p{i}", 4, {"age": float(i)}, (), points))
    kept = {}
    for side in ("host", "alone"):
        state, rows = _kept_state([r.sender for r in reports])
        if side == "host":
            (message,) = pack_reports([(r.sender, None, r) for r in reports], 1.0)
            state.receive("sensornet/net/telemetries/h1", message)
        else:
            for r in reports:
                state.receive(f"sensornet/net/telemetry/{r.sender}", encode(r))
        state.b.flush()
        assert (state.handled, state.rejected) == (6, 1)
        kept[side] = {p: r for p, r in rows.items() if p.startswith("peers/")}
    assert kept["host"] == kept["alone"]
    assert {"peers/p3/local/means", "peers/p3/local/ellipses", "peers/p0/fused/ellipses",
            "peers/p1/particles"} <= set(kept["host"]) and "peers/p2/fused/means" not in kept[
                "host"]
