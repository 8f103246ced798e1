"""The live view costs the network nothing (issue 38): peers publish one compact Telemetry
message a scan and log nothing to Rerun; ``sensornet view`` subscribes and batches its logging
(one ``send_columns`` per entity per flush), decimating its own work when behind."""

from __future__ import annotations

import json
import os
import queue
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import msgpack
import numpy as np
import pytest
import rerun as rr
from sensornet.peers.core import Publish, Record
from sensornet.peers.host import PeerHost
from sensornet.peers.observer import (
    PENDING_MAX,
    WAIT_SCANS,
    HostReports,
    Observer,
    pack_marginals,
    unpack_marginals,
)
from sensornet.peers.recording import Recorder
from sensornet.peers.rerun_sink import color_of, ellipses, lighter, north_up
from sensornet.peers.rerun_sink import dashed as dashed_lines
from sensornet.peers.runtime import RuntimeOptions
from sensornet.peers.session import open_session
from sensornet.peers.telemetry import Telemetry as PeerTelemetry
from sensornet.protocol.bundle import pack_bundles, unpack_bundle
from sensornet.protocol.codec import Rejected, decode, encode
from sensornet.protocol.keys import Keys
from sensornet.protocol.messages import Estimate, Forward, Scan, ScanSet, Telemetry, Tracks, Truth
from sensornet.protocol.report_bundle import unpack_reports
from sensornet.sim.run import twin
from sensornet.sim.run.launcher import read_summaries, start_run, wait_run
from sensornet.sim.run.peers import make_peer
from sensornet.sim.scenario import load_scenario, parse_overrides
from sensornet.tracking.mixture import GaussianMixture

from sensornet.cli import main
from sensornet.view import (
    BEHIND,
    Batcher,
    LiveView,
    ViewState,
    id_color,
    later_round,
    replay_recordings,
)
from tests.processes import (
    end_once_view_drew,
    env,
    rerun_exe,
    sensornet,
    stop_all,
    when_tracks_reach,
    when_view_drew,
)


class _Rec:
    """A recording stream that keeps what it is sent: (entity, scan indexes, columns)."""

    def __init__(self) -> None:
        self.calls: list[tuple[str, list[int], list]] = []

    def send_columns(self, path, indexes, columns):
        scans = indexes[0].as_arrow_array().to_pylist()
        self.calls.append((path, scans, list(columns)))

    def by_path(self) -> dict:
        return {p: (s, c) for p, s, c in self.calls}


def _mix(n: int, x0: float = 0.0) -> GaussianMixture:
    means = np.zeros((n, 4))
    means[:, 0] = x0 + 10.0 * np.arange(n)
    return GaussianMixture.trusted(np.full(n, 0.9), means, np.tile(np.eye(4), (n, 1, 1)))


def test_batcher_sends_one_call_per_entity_and_decimates_only_map_rows():
    rec = _Rec()
    b = Batcher(rr, rec)
    for k in range(1, 31):
        b.scalar("metrics/latency_ms/s1", k, 0.1 * k, float(k))
        b.points("peers/s1/tracks", k, 0.1 * k, np.full((k % 3, 2), float(k)), (1, 2, 3), 5.0,
                 labels=[f"s1/{i}" for i in range(k % 3)])
    b.scalar("metrics/age/s1", 1, 0.1, float("nan"))  # not finite: no row
    assert b.pending() == 60
    b.flush()
    calls = rec.by_path()
    assert len(rec.calls) == 2 and set(calls) == {"metrics/latency_ms/s1", "peers/s1/tracks"}
    assert calls["metrics/latency_ms/s1"][0] == list(range(1, 31))
    assert calls["peers/s1/tracks"][0] == list(range(1, 31))  # not behind: every frame
    assert b.decimated == 0 and b.pending() == 0
    b.map_keep = 4  # behind: map frames beyond the newest 4 left out, scalars never
    for k in range(31, 41):
        b.scalar("metrics/latency_ms/s1", k, 0.1 * k, 1.0)
        b.points("peers/s1/tracks", k, 0.1 * k, np.zeros((1, 2)), (1, 2, 3), 5.0)
    b.flush()
    last = {p: s for p, s, _ in rec.calls[2:]}
    assert last["metrics/latency_ms/s1"] == list(range(31, 41))
    assert last["peers/s1/tracks"] == [37, 38, 39, 40] and b.decimated == 6
    assert b.calls == 4 and b.rows_sent == 30 + 30 + 10 + 4


class _RerunColumns(Batcher):
    """The reference: the same rows as columns built by Rerun's own archetypes
    (``Archetype.columns(...).partition(...)``), and ellipses drawn one row at a time with
    :func:`peers.rerun_layout.ellipses` (and ``dashed``) as plain strips."""

    def ellipses(self, path, k, t, means, covs, color, radius, dashed=False):
        lines = ellipses(means, covs)
        self.strips(path, k, t, dashed_lines(lines) if dashed else lines, color, radius)

    def _send(self, path, kind, ks, ts, data):
        index = [rr.TimeColumn("scan", sequence=np.asarray(ks, np.int64)),
                 rr.TimeColumn("sim", duration=np.asarray(ts, float))]
        if kind == "scalar":
            cols = rr.Scalars.columns(scalars=np.asarray(data, float))
        elif kind == "points":
            lengths = [len(d[0]) for d in data]
            cols = [*rr.Points2D.columns(
                positions=north_up(np.concatenate([d[0] for d in data])),  # rows: map coords
                colors=np.concatenate([np.broadcast_to(d[1], (len(d[0]), 3)) for d in data]),
                radii=np.repeat([d[2] for d in data], lengths)).partition(lengths)]
            if any(d[3] is not None for d in data):
                labels = [s for d in data for s in (d[3] or [""] * len(d[0]))]
                cols += [*rr.Points2D.columns(labels=labels).partition(lengths),
                         *rr.Points2D.columns(show_labels=[True] * len(data))]
        else:
            assert kind == "strips", kind
            lengths = [len(d[1]) for d in data]
            cols = [*rr.LineStrips2D.columns(
                strips=[s for d in data if len(d[1])
                        for s in np.split(d[0], np.cumsum(d[1])[:-1])],
                colors=np.concatenate([np.broadcast_to(d[2], (len(d[1]), 3)) for d in data]),
                radii=np.repeat([d[3] for d in data], lengths)).partition(lengths)]
        self.rec.send_columns(path, indexes=index, columns=cols)


def test_columns_built_here_are_rerun_s_own():
    """The batcher builds its Arrow columns itself (Rerun's archetype conversions cost
    ~0.1-0.5 ms an entity): the same arrays, types and descriptors as Rerun's own columns
    of the same rows (points with and without labels, empty rows, strips, scalars with a NaN,
    ellipses local dashed and fused solid of 4-D and 6-D components, drawn at once; the
    reference draws them a row at a time)."""
    sent = {}

    class Keep:
        def __init__(self, side):
            self.side = side

        def send_columns(self, path, indexes, columns):
            sent[self.side, path] = ([(i.timeline_name(), i.as_arrow_array()) for i in indexes],
                                     {str(c.component_descriptor()): c.as_arrow_array()
                                      for c in columns})

    for side, cls in (("here", Batcher), ("rerun", _RerunColumns)):
        rng = np.random.default_rng(7)
        b = cls(rr, Keep(side))
        for k in range(1, 7):
            t = 0.1 * k
            n = int(rng.integers(0, 4))
            b.scalar("m/s1", k, t, float("nan") if k == 3 else rng.normal())
            b.points("p/labelled", k, t, rng.normal(size=(n, 2)),  # one colour, or one each
                     rng.integers(0, 256, (n, 3)) if k % 3 else (7, 7, 7), 2.0,
                     labels=[f"x{i}" for i in range(n)] if k % 2 else None)
            b.points("p/plain", k, t, rng.normal(size=(n, 2)), (1, 2, 3), 3.0)
            lines = [rng.normal(size=(m, 2)) for m in (2, 5)[:n]]
            b.strips("s", k, t, lines, rng.integers(0, 256, (len(lines), 3)) if k % 2
                     else (4, 5, 6), 1.5)
            for name, dim, dash in (("4", 4, True), ("6", 6, False),  # rows unlike: one by one
                                    ("mixed", 4 + 2 * (k % 2), k % 3 == 0)):
                A = rng.normal(size=(n, dim, dim))
                b.ellipses(f"e/{name}", k, t, rng.normal(size=(n, dim)) * 100,
                           A @ A.transpose(0, 2, 1) + np.eye(dim), (9, 8, 7), 1.0, dashed=dash)
        b.flush()
    paths = {p for _, p in sent}
    assert paths == {"m/s1", "p/labelled", "p/plain", "s", "e/4", "e/6", "e/mixed"}
    for path in paths:
        (here_index, here), (ref_index, ref) = sent["here", path], sent["rerun", path]
        assert [n for n, _ in here_index] == [n for n, _ in ref_index] == ["scan", "sim"]
        assert all(a.equals(b) for (_, a), (_, b) in zip(here_index, ref_index, strict=True))
        assert set(here) == set(ref), path
        for name in ref:  # the ellipses too, to the bit (the same operations on a block)
            assert here[name].type == ref[name].type and here[name].equals(ref[name]), (
                path, name)


@pytest.mark.network  # starts the rerun CLI to verify and print the file
def test_batched_columns_write_a_recording_rerun_reads(tmp_path):
    """The columns are valid Rerun data: the file verifies and holds each entity."""
    path = tmp_path / "v.rrd"
    stream = rr.RecordingStream("sensornet-test", recording_id="view-test")
    stream.set_sinks(rr.FileSink(str(path)))
    state = ViewState(Batcher(rr, stream), ["s1", "s2"], 0.5)
    for k in range(1, 6):
        state.message(Truth(k, np.array([3, 4]), np.array([[0.0, 1, 0, 1], [50, 0, 60, 0]])))
        state.message(Tracks("s1", k, np.array([[1.0, 1, 0, 1]])))
        state.message(Estimate("s2", k, _mix(2)))
        state.message(Telemetry("s1", k, {"latency_ms": 5.0, "components/fused": 3},
                                ("s2 joined",), {"particles": np.ones((4, 2))}, _mix(1)))
    state.b.flush()
    stream.flush()
    stream.disconnect()
    check = subprocess.run([rerun_exe(), "rrd", "verify", str(path)], capture_output=True,
                           text=True, timeout=120, env=env())
    assert check.returncode == 0, check.stderr
    text = subprocess.run([rerun_exe(), "rrd", "print", str(path)], capture_output=True,
                          text=True, timeout=120, env=env()).stdout
    for entity in ("/world/truth", "/world/truth/paths", "/peers/s1/tracks", "/peers/s1/tail",
                   "/peers/s2/local/ellipses", "/peers/s1/fused/means", "/peers/s1/particles",
                   "/metrics/latency_ms/s1", "/metrics/components/s1/fused",
                   "/peers/s1/events"):
        assert entity in text, entity


def test_view_state_draws_what_the_network_carries():
    rec = _Rec()
    heard = []
    state = ViewState(Batcher(rr, rec), ["s1", "s2"], scan_period=2.0,
                      on_new_peer=lambda n, i: heard.append((n, i)))
    state.message(Truth(3, np.array([7]), np.array([[100.0, 0, 200, 0]])))
    state.message(Tracks("s2", 3, np.array([[1.0, 0, 2, 0], [5.0, 0, 6, 0]])))
    state.message(Tracks("s2", 4, np.array([[5.5, 0, 6, 0], [1.2, 0, 2, 0]])))
    state.message(Estimate("s1", 3, _mix(3)))
    state.message(Telemetry("s1", 3, {"out_of_sequence/late": 2.0, "age": 1.0,
                                      "trust/s2/weight": 0.5}, ("WARN s2 a -> b (score 3)",)))
    state.message(Tracks("s9", 3, np.zeros((0, 4))))  # not in the scenario: the next colour
    state.b.flush()
    calls = rec.by_path()
    assert heard == [("s9", 2)]
    assert calls["world/truth"][0] == [3] and calls["metrics/cardinality/truth"][0] == [3]
    assert calls["peers/s2/tracks"][0] == [3, 4]
    # the same two tracks in the other order keep their numbers (TrackLabels)
    labels = [c for c in calls["peers/s2/tracks"][1]
              if "labels" in str(c.component_descriptor())]
    assert labels[0].as_arrow_array().to_pylist() == [["s2/0", "s2/1"], ["s2/1", "s2/0"]]
    for path in ("metrics/out_of_sequence/s1/late", "metrics/age/s1",
                 "metrics/trust/s1/s2/weight", "peers/s1/events", "metrics/cardinality/s2/fused",
                 "peers/s1/local/means", "peers/s1/local/ellipses"):
        assert path in calls, path
    # local dashed: 3 ellipses of 33 points as 16 two-point strips each
    strips = calls["peers/s1/local/ellipses"][1][0].as_arrow_array().to_pylist()
    assert len(strips[0]) == 3 * 16
    colors = [c for c in calls["peers/s1/local/means"][1] if "colors" in
              str(c.component_descriptor())][0].as_arrow_array().to_pylist()[0]
    r, g, b = lighter(color_of(0))
    assert colors[0] == (r << 24) | (g << 16) | (b << 8) | 255


def test_the_local_estimate_rides_in_the_telemetry():
    """A peer's local mixture goes as position marginals in its telemetry (no view needs the
    estimates): round trip against the mixture's own position block, then drawn dashed."""
    rng = np.random.default_rng(2)
    A = rng.normal(size=(5, 4, 4))
    mix = GaussianMixture.trusted(rng.uniform(0.1, 1, 5), rng.normal(size=(5, 4)),
                                  A @ A.transpose(0, 2, 1) + np.eye(4))
    back = unpack_marginals(pack_marginals(mix))
    np.testing.assert_allclose(back.weights, mix.weights)
    np.testing.assert_allclose(back.means[:, [0, 2]], mix.means[:, [0, 2]])
    np.testing.assert_allclose(back.covs[:, [0, 2]][:, :, [0, 2]],
                               mix.covs[:, [0, 2]][:, :, [0, 2]])
    rec = _Rec()
    state = ViewState(Batcher(rr, rec), ["s1"])
    msg = decode(encode(Telemetry("s1", 2, points={"local/mixture": pack_marginals(mix)})))
    state.message(msg)
    state.b.flush()
    calls = rec.by_path()
    means = calls["peers/s1/local/means"][1][0].as_arrow_array().to_pylist()[0]
    np.testing.assert_allclose(np.array(means)[:, 0], mix.means[:, 0], rtol=1e-6)
    assert len(calls["peers/s1/local/ellipses"][1][0].as_arrow_array().to_pylist()[0]) == 5 * 16
    assert "peers/s1/local/mixture" not in calls


def test_labelled_tracks_get_one_colour_and_label_per_id_at_every_peer():
    rec = _Rec()
    state = ViewState(Batcher(rr, rec), ["s1", "s2"])
    ids = np.array([[1, 5, 0], [2, 9, 1]])
    X = np.array([[0.0, 0, 0, 0], [10.0, 0, 10, 0]])
    state.message(Tracks("s1", 5, X, ids=ids))
    state.message(Tracks("s2", 5, X[::-1], ids=ids[::-1]))
    state.b.flush()
    calls = rec.by_path()

    def column(path, name):
        return [c for c in calls[path][1] if name in str(c.component_descriptor())][0] \
            .as_arrow_array().to_pylist()[0]

    c1, c2 = column("peers/s1/tracks", "colors"), column("peers/s2/tracks", "colors")
    assert c1 == c2[::-1] and c1[0] != c1[1]
    assert column("peers/s1/tracks", "labels") == ["1.5.0", "2.9.1"]
    np.testing.assert_array_equal(id_color(ids), id_color(ids.copy()))  # stable


def test_a_bundle_and_later_rounds():
    rec = _Rec()
    state = ViewState(Batcher(rr, rec), ["a", "b"])
    entries = [(n, encode(Scan(n, 2, np.ones((3, 2))))) for n in ("a", "b")]
    (bundle,) = pack_bundles(2, entries)
    state.receive("sensornet/net/scans/h1", bundle)
    later = encode(Forward("a", 2, ScanSet({"a": np.ones((2, 2))}), round=1))
    first = encode(Forward("a", 2, ScanSet({"a": np.ones((2, 2))}), round=0))
    assert later_round(later) and not later_round(first) and not later_round(b"\x93junk")
    state.receive("sensornet/net/estimate/a", later)
    state.receive("sensornet/net/estimate/a", first)
    state.receive("sensornet/net/tracks/a", b"junk")
    state.b.flush()
    assert {"world/scans/a", "world/scans/b", "peers/a/local"} <= set(rec.by_path())
    assert (state.skipped, state.rejected, state.handled) == (1, 1, 3)


class _Sample:
    def __init__(self, key: str, payload: bytes) -> None:
        self.key_expr, self.payload = key, type("P", (), {"to_bytes": lambda s: payload})()


def test_a_view_behind_drops_and_skips_its_own_work_and_says_so():
    said = []
    view = LiveView("net", lambda b: ViewState(b, ["s1"]), rr, _Rec(), say=said.append)
    view.q = queue.Queue(maxsize=BEHIND + 10)
    est = encode(Estimate("s1", 1, _mix(1)))
    tracks = encode(Tracks("s1", 1, np.zeros((1, 4))))
    for i in range(BEHIND + 20):  # a burst larger than the queue: the rest dropped on arrival
        view._on_sample(_Sample("sensornet/net/estimate/s1" if i % 2 else
                                "sensornet/net/tracks/s1", est if i % 2 else tracks))
    assert view.dropped == 10
    view.drain(30.0)
    assert view.q.empty() and view.skipped > 0
    assert view.state.handled + view.skipped == BEHIND + 10
    view.note(final=True)
    assert len(said) == 1 and "10 messages dropped" in said[0] and "peers are not" in said[0]


def test_a_long_flush_handles_what_arrives_meanwhile():
    """A flush sends its entities in parts and handles the messages waiting between them (a
    flush of 2,000 entities at 50 peers held them back up to 0.8 s); their rows go to the
    next flush, none lost, and the flush period doubles on the flush's own time only."""
    rec = _Rec()
    view = LiveView("net", lambda b: ViewState(b, ["s1"]), rr, rec)
    for i in range(450):
        view.batcher.scalar(f"metrics/m{i}/s1", 1, 0.1, 1.0)
    for k in (1, 2):
        view.q.put(("sensornet/net/telemetry/s1", encode(Tracks("s1", k, np.zeros((1, 4))))))
    handled = []
    receive = view.state.receive
    view.state.receive = lambda key, payload: (handled.append(len(rec.calls)),
                                               receive(key, payload))
    view.flush()
    assert view.q.empty() and handled == [200, 200]  # after the first 200 entities' part
    assert len(rec.calls) == 450 and "peers/s1/tracks" not in rec.by_path()
    view.batcher.flush()
    assert rec.by_path()["peers/s1/tracks"][0] == [1, 2]


def test_what_arrives_before_the_recording_opens_waits_and_is_drawn():
    """The view process subscribes before it opens its recording (0.8 s): what the run sends
    meanwhile (its first scans) waits in the queue and is drawn once the recording is open."""
    view = LiveView("net", None, None, None)
    assert view.state is None
    view._on_sample(_Sample("sensornet/net/truth", encode(Truth(1, np.array([3]),
                                                                np.zeros((1, 4))))))
    view._on_sample(_Sample("sensornet/net/tracks/s1", encode(Tracks("s1", 1, np.zeros((1, 4))))))
    rec = _Rec()
    view.draw_into(lambda b: ViewState(b, ["s1"]), rr, rec)
    view.run(duration=0.0)  # drains what waits and flushes
    assert view.state.handled == 2 and view.q.empty()
    assert rec.by_path()["world/truth"][0] == [1] and rec.by_path()["peers/s1/tracks"][0] == [1]


def test_a_view_stops_after_count_messages_drawn():
    """``--count N`` detaches once N messages are drawn, however long they take to come (a
    test or a script waits on what the view saw, not on seconds); below N it keeps watching
    until stopped."""
    def watch(count):
        rec = _Rec()
        view = LiveView("net", lambda b: ViewState(b, ["s1"]), rr, rec)
        for k in range(1, 6):
            view.q.put(("sensornet/net/tracks/s1", encode(Tracks("s1", k, np.zeros((1, 4))))))
        t = threading.Thread(target=view.run, kwargs={"count": count}, daemon=True)
        t.start()
        return view, t

    view, t = watch(3)
    t.join(60)
    assert not t.is_alive() and view.drawn == view.state.handled == 5  # and drew them all
    view, t = watch(10)
    try:
        deadline = time.monotonic() + 60
        while view.drawn < 5 and time.monotonic() < deadline:
            time.sleep(0.01)
        assert view.drawn == 5 and t.is_alive()  # 5 of 10 drawn: still watching
    finally:
        view.stop.set()
        t.join(60)
    assert not t.is_alive()


def test_a_view_says_whose_first_reports_its_recording_has():
    """After a flush, one line names the peers whose first reports that flush sent (a test
    waits on it before stopping a peer: a view that starts late on a busy machine heard
    nothing of a short run); a report drawn during the flush is named after the next one,
    once its rows are sent, and a peer is named once."""
    said: list[str] = []
    rec = _Rec()
    view = LiveView("net", lambda b: ViewState(b, ["s1", "s2"]), rr, rec, say=said.append)
    for i in range(450):  # a flush in parts: what waits is handled after the first 200
        view.batcher.scalar(f"metrics/m{i}/s1", 1, 0.1, 1.0)

    def report(name: str, k: int) -> bytes:
        return encode(Telemetry(name, k, {"ospa/fused": 2.0}, (), {}, _mix(1)))

    view.state.receive("sensornet/net/telemetry/s1", report("s1", 3))
    view.q.put(("sensornet/net/telemetry/s2", report("s2", 4)))
    view.flush()
    assert view.q.empty() and said == ["view: drew the first reports of s1 (scan 3)"]
    assert {"metrics/ospa/s1/fused", "peers/s1/fused/means"} <= set(rec.by_path())
    assert "peers/s2/fused/means" not in rec.by_path()  # drawn meanwhile: the next flush's
    view.state.receive("sensornet/net/telemetry/s1", report("s1", 5))
    view.flush()
    assert said[1:] == ["view: drew the first reports of s2 (scan 4)"]
    assert {"metrics/ospa/s2/fused", "peers/s2/fused/means"} <= set(rec.by_path())
    view.state.receive("sensornet/net/telemetry/s2", report("s2", 6))
    view.flush()
    assert len(said) == 2  # nobody new


def test_telemetry_round_trip_and_refusals():
    msg = Telemetry("s1", 4, {"ospa/fused": 3.5, "age": 2.0}, ("s2 left",),
                    {"particles": np.arange(6.0).reshape(3, 2)}, _mix(2))
    back = decode(encode(msg))
    assert back.values == {"ospa/fused": 3.5, "age": 2.0} and back.events == ("s2 left",)
    np.testing.assert_array_equal(back.points["particles"], msg.points["particles"])
    np.testing.assert_array_equal(back.mixture.means, msg.mixture.means)
    assert decode(encode(Telemetry("s1", 4))).mixture is None
    body = msgpack.unpackb(encode(msg))
    body[9] = [5]  # point counts that do not add up
    with pytest.raises(Rejected) as exc:
        decode(msgpack.packb(body, use_bin_type=True))
    assert exc.value.reason == "shape"


def test_telemetry_points_go_as_float32_and_bad_ones_are_refused():
    """Protocol 2 of a report: its map points as float32 (4 bytes a number, within float32's
    rounding of the float64 ones); points beyond float32's range go as protocol 1 (float64,
    exactly); a float32 block of the wrong size or holding NaN is refused, with its reason."""
    rng = np.random.default_rng(5)
    z = rng.uniform(-5e4, 5e4, (300, 2))
    payload = encode(Telemetry("s1", 4, {"age": 1.0}, (), {"pooled": z, "none": z[:0]}))
    body = msgpack.unpackb(payload)
    assert body[0] == 2 and len(body[10]) == 4 * z.size  # "pf": 4 bytes a number
    back = decode(payload).points
    np.testing.assert_allclose(back["pooled"], z, rtol=2 ** -24)
    np.testing.assert_array_equal(back["pooled"], z.astype(np.float32))
    assert back["none"].shape == (0, 2)
    far = np.array([[1e300, 0.0]])
    body1 = msgpack.unpackb(encode(Telemetry("s1", 4, points={"far": far})))
    assert body1[0] == 1
    np.testing.assert_array_equal(decode(msgpack.packb(body1, use_bin_type=True)).points["far"],
                                  far)
    for blob, reason in ((body[10][:-4], "shape"),
                         (np.full(z.size, np.nan, np.float32).tobytes(), "nonfinite")):
        bad = list(body)
        bad[10] = blob
        with pytest.raises(Rejected) as exc:
            decode(msgpack.packb(bad, use_bin_type=True))
        assert exc.value.reason == reason


def test_a_peer_reports_each_scan_once_when_idle_with_its_ospa():
    scn = load_scenario("seed000", {"scenario.num_scans": 3})
    core = make_peer(scn, scn.sensor_names[0], score_truth=False)  # truth from the network
    assert core.wants_truth
    sent: list[bytes] = []
    obs = Observer(core, 1.0).attach(sent.append)
    tr = Tracks(core.name, 7, np.zeros((2, 4)))
    obs.record(Record("local", 7, {"n_components": 9, "n_published": 4}), 1.5)
    obs.record(Record("estimate", 7, {"sender": "x"}))  # not read
    obs.published(Publish("tracks", 7, b"", tr), 12.0)
    obs.flush(idle=False)
    obs.flush(idle=True)
    assert sent == []  # the peer scores OSPA: its report waits for it
    obs.record(Record("ospa", 7, {"which": "fused", "value": 4.0}))
    obs.flush(idle=True)
    (msg,) = [decode(b) for b in _entries(sent)]
    assert msg.k == 7 and msg.values["latency_ms"] == 12.0
    assert msg.values["components/before_level2"] == 9 and msg.values["ospa/fused"] == 4.0
    assert msg.values["compute_ms/filter"] == 1.5
    obs.watched = False  # nobody hears the key any more: nothing gathered, nothing sent
    obs.record(Record("local", 20, {"n_components": 1}))
    obs.published(Publish("tracks", 20, b"", Tracks(core.name, 20, np.zeros((0, 4)))), 1.0)
    assert not obs.enabled and 20 not in obs._pending and not obs.wants_flush
    obs.watched = True
    obs.record(Record("local", 8, {"n_components": 1}))  # no OSPA ever: sent all the same
    for k in range(9, 9 + WAIT_SCANS):
        obs.published(Publish("tracks", k, b"", Tracks(core.name, k, np.zeros((0, 4)))), 1.0)
    obs.flush(idle=True)
    assert 8 in [decode(b).k for b in _entries(sent[1:])]


def test_with_several_rounds_the_age_is_the_first_rounds(monkeypatch):
    """With 2 consensus rounds a scan, the fused estimates' ages are measured in the first
    round (the later round's record says 0 for every sender): a peer's "age" series and its
    mean estimate age (process and twin) are the first round's, not the last record's 0s.
    A twin run where s2's round-0 estimate of every third scan reaches the others late;
    the reference: the first-round records' ages, and the delayed scans."""
    scn = load_scenario("seed000", {"scenario.num_scans": 12, "network.rounds": 2})
    fusions: list[tuple[str, Record]] = []
    tally = twin.TwinResult.tally

    def kept(self, peer, outputs):
        fusions.extend((peer, o) for o in outputs if isinstance(o, Record) and o.kind == "fusion")
        return tally(self, peer, outputs)

    monkeypatch.setattr(twin.TwinResult, "tally", kept)
    late = {k for k in range(1, 13) if k % 3 == 0}
    result = twin.run_twin(scn, 0, delay=lambda a, b, e: (
        0.9 * scn.scan_period if a == "s2" and e.round == 0 and e.k in late else 0.0))
    first = [(p, r) for p, r in fusions if r.values["round"] == 1]
    assert {r.values["round"] for _, r in fusions} == {1, 2}
    assert all(not any(r.values["ages"].values()) for _, r in fusions if r.values["round"] == 2)
    for name in ("s1", "s3"):
        core = make_peer(scn, name, score_truth=False)
        core.wants_truth = False
        sent: list[bytes] = []
        obs = Observer(core, 1.0).attach(sent.append)
        tel = PeerTelemetry()
        for p, r in fusions:
            if p == name:
                obs.record(r)
                tel.handled("estimate", 0.0, 0.0, [r])
        for k in range(1, 13):
            obs.published(Publish("tracks", k, b"", Tracks(name, k, np.zeros((0, 4)))), 1.0)
        obs.flush(idle=True, force=True)
        ages = {m.k: m.values["age"] for m in map(decode, _entries(sent)) if "age" in m.values}
        want = {r.k: float(max(r.values["ages"].values())) for p, r in first if p == name}
        # a scan whose s2 estimate is late fuses s2's one before: age 1 there, 0 elsewhere
        assert ages == want and {k for k, a in ages.items() if a > 0} == late
        mine = [a for p, r in first if p == name for a in r.values["ages"].values()]
        assert list(tel.ages) == mine == result.ages[name] and sum(mine) > 0


_NICE_CHILD = """
import json, os, threading
from sensornet.view import nice_process
stop = threading.Event()
t = threading.Thread(target=stop.wait)  # a thread started before: os.nice would miss it
t.start()
nice_process(3)
u = threading.Thread(target=stop.wait)  # one started after: inherits it
u.start()
print(json.dumps(sorted(int(open(f"/proc/self/task/{i}/stat").read().rsplit(")", 1)[1].split()[16])
                        for i in os.listdir("/proc/self/task"))))
stop.set()
"""


@pytest.mark.network  # a child process
@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="per-thread nice: Linux")
def test_the_view_lowers_the_priority_of_every_thread_it_has():
    """On Linux a nice value is per thread: the view's Zenoh and Rerun threads are lowered
    too, not only the one that asks (a child process: the test's own stays as it is)."""
    out = subprocess.run([sys.executable, "-c", _NICE_CHILD], capture_output=True, text=True,
                         timeout=120, env=env())
    assert out.returncode == 0, out.stderr[-2000:]
    nices = json.loads(out.stdout.strip().splitlines()[-1])
    base = os.getpriority(os.PRIO_PROCESS, 0)
    assert len(nices) >= 3 and set(nices) == {min(19, base + 3)}


def _entries(puts: list[bytes]) -> list[bytes]:
    """The messages in a peer's puts on its report key (each a bundle of its tracks and
    reports)."""
    return [p for b in puts for _, p in unpack_bundle(b).entries]


def _report_scan(obs: Observer, k: int, n: int) -> None:
    """Scan ``k`` of a peer that scores nothing: a local step and ``n`` tracks out."""
    obs.record(Record("local", k, {"n_components": n + 3, "n_published": n}), 1.5)
    tracks = Tracks(obs.name, k, np.full((n, 4), float(n)))
    obs.published(Publish("tracks", k, b"", tracks), 10.0 + n)


def test_a_hosts_peers_report_in_one_bundle_drawn_as_their_own():
    """A host's observers send their reports through its HostReports: nothing until the host
    flushes them (not in a peer's own step), then one put for all; the view draws the bundle
    as the same reports sent one per peer (the reference: observers of their own). A bad
    bundle, or a bad report in one, is counted and the rest drawn."""
    scn = load_scenario("seed000", {"scenario.num_scans": 3})
    names = scn.sensor_names[:2]
    bundles: list[bytes] = []
    reports = HostReports(bundles.append)
    own: list[bytes] = []
    hosted, alone = [], []
    for n in names:
        for group, obs in ((hosted, reports.add(Observer(make_peer(scn, n, score_truth=False)))),
                           (alone, Observer(make_peer(scn, n, score_truth=False)).attach(
                               own.append))):
            obs.core.wants_truth = False
            group.append(obs)
    for i, (a, b) in enumerate(zip(hosted, alone, strict=True)):
        for obs in (a, b):
            _report_scan(obs, 4, i + 1)
            obs.flush(idle=True)
    reports.send()
    assert bundles == [] and len(own) == 2  # hosted: only when the host flushes them
    for obs in hosted:
        obs.flush(idle=True, host=True)
    reports.send()
    assert len(bundles) == 1 and reports.sent == 1
    drawn = {}
    for name, heard in (("bundle", [("sensornet/net/telemetries/h1", bundles[0])]),
                        ("own", [(f"sensornet/net/telemetry/{n}", b)
                                 for n, b in zip(names, own, strict=True)])):
        rec = _Rec()
        state = ViewState(Batcher(rr, rec), names)
        for key, payload in heard:
            state.receive(key, payload)
        state.b.flush()
        assert state.rejected == 0 and state.handled == 2
        drawn[name] = {p: (s, [c.as_arrow_array().to_pylist() for c in cols])
                       for p, s, cols in rec.calls}
    assert drawn["bundle"] == drawn["own"]
    assert {f"metrics/latency_ms/{n}" for n in names} <= set(drawn["own"])
    rec = _Rec()
    state = ViewState(Batcher(rr, rec), names)
    state.receive("sensornet/net/telemetries/h1", b"\x93not a bundle")
    bad = msgpack.packb([0, [[names[0], _entries(own[:1])[0]], [names[1], b"\x91\x01"]]],
                        use_bin_type=True)
    state.receive("sensornet/net/telemetries/h1", bad)
    state.b.flush()
    assert state.rejected == 2 and state.handled == 1
    assert f"metrics/latency_ms/{names[0]}" in rec.by_path()
    reports._matching(type("Status", (), {"matching": False})())  # nobody listens: no work
    assert not reports.watched and not any(obs.enabled for obs in hosted)


def test_a_host_sends_its_peers_reports_when_idle_or_crowded():
    """A host sends its peers' complete reports once none of its peers has work waiting, in
    one bundle; a host never idle sends them once a peer holds PENDING_MAX scans' (the
    oldest, those WAIT_SCANS behind the newest but 8), so it never gathers without end."""
    scn = load_scenario("seed000", {"scenario.num_scans": 3})
    names = scn.sensor_names[:2]
    host = PeerHost("h1", [(make_peer(scn, n, network="net", score_truth=False),
                            RuntimeOptions(rerun=False)) for n in names],
                    ((), (), None, None, False))
    bundles: list[bytes] = []
    host.reports._put = bundles.append
    for rt in host.peers:
        rt.core.wants_truth = False
        rt.observer.watched = True
    host._active = [0, 1]
    obs = host.peers[0].observer
    _report_scan(obs, 1, 1)
    obs.flush(idle=True)  # the peer's own step: not its to send
    host._backlog[1].append((0.0, ("msg", "x", b"")))  # the other peer has work waiting
    host._report()
    assert bundles == [] and obs.pending == 1
    host._backlog[1].clear()
    host._report()
    (reports,) = [unpack_reports(b).reports for b in bundles]
    assert [(r.sender, r.k) for r in reports] == [(names[0], 1)] and obs.pending == 0
    host._backlog[1].append((0.0, ("msg", "x", b"")))
    for k in range(2, 2 + PENDING_MAX):  # no tracks out: none complete
        obs.record(Record("local", k, {"n_components": 1}))
        host._report()
    newest = 1 + PENDING_MAX
    sent = [r.k for r in unpack_reports(bundles[-1]).reports]
    assert len(bundles) == 2 and sent == list(range(2, newest - 8 - WAIT_SCANS + 1))
    assert obs.pending == PENDING_MAX - len(sent) < PENDING_MAX


@pytest.mark.network
def test_a_run_records_through_the_view_and_a_view_attaches_by_hand(tmp_path):
    """``sensornet run`` (view on): world and peers write no .rrd, the view's recording holds
    truth, scans, tracks, local and fused marks and the health series. Beside it, a view
    attached by hand to a network someone else started and runs, detached by Ctrl-C: the
    peers handle every scan all the same. Both runs last until the test ends them (their
    world's SIGTERM: its end message ends the run), each only once its view says it drew
    every peer (an event): a view imports for seconds longer than the peers on a busy
    machine (20.7 against 12.5 s at load 15) and linked after a short run's end."""
    sets = ["scenario.num_scans=3000"]  # at 2 scans/s: no run ends before the test ends it
    scn = load_scenario("seed000", parse_overrides(sets))
    names = scn.sensor_names
    out = tmp_path / "run"
    others = start_run(scn, "seed000", tmp_path / "others", network="byhand", overrides=sets,
                       rerun=False, speed=2.0)  # started by someone else, no view of its own
    view, log, session = None, tmp_path / "byhand.log", None
    try:
        with sensornet(["run", "--viewer", "none", "--out", str(out), "--speed", "2",
                        *(a for s in sets for a in ("--set", s))], tmp_path) as run:
            # by hand: once the others' peers run, attach, and detach once it drew them all
            session = open_session(connect=[others.endpoints["world"]])
            keys = Keys("byhand")
            when_tracks_reach(session, keys, names[0], 3, timeout=240.0)
            with log.open("w") as fh:
                view = subprocess.Popen(
                    [sys.executable, "-m", "sensornet", "view", "byhand",
                     "--connect", others.endpoints["world"], "--scenario", "seed000",
                     "--out", str(tmp_path / "mine.rrd")],
                    cwd=tmp_path, env=env(), stdout=subprocess.DEVNULL, stderr=fh)
            when_view_drew(log, names, lambda: view.poll() is None, timeout=240.0)
            view.send_signal(signal.SIGINT)  # Ctrl-C: it detaches
            assert view.wait(timeout=120) == 0, log.read_text()[-2000:]
            assert "messages drawn" in log.read_text()
            for name in names:  # the peers go on without it
                now = when_tracks_reach(session, keys, name, 1)
                when_tracks_reach(session, keys, name, now + 5)
            others.procs["world"].send_signal(signal.SIGTERM)

            end_once_view_drew(run, out, names)
            _, err = run.proc.communicate(timeout=300)
            assert run.proc.returncode == 0, err[-2000:]

        codes = wait_run(others, timeout=120.0)
        assert all(c == 0 for c in codes.values()), codes
        assert sorted(p.name for p in (out / "rerun").glob("*.rrd")) == ["view.rrd"]
        view_log = (out / "logs" / "view.log").read_text()
        assert "messages drawn" in view_log, view_log
        text = subprocess.run([rerun_exe(), "rrd", "print", str(out / "recording.rrd")],
                              capture_output=True, text=True, timeout=120, env=env()).stdout
        for entity in ["/world/truth", "/world/scans/s1", "/world/sensors", "/legend"] + [
                f"/peers/{p}/{what}" for p in ("s1", "s2", "s3")
                for what in ("tracks", "local/means", "fused/ellipses")] + [
                f"/metrics/{m}/s2" for m in ("latency_ms", "age")] + [
                f"/metrics/{m}/s3/{w}" for m, w in (("ospa", "fused"), ("cardinality", "local"),
                                                   ("compute_ms", "fusion"))]:
            assert entity in text, entity
        for name in names:
            s = (out / f"peer-{name}.json").read_text()
            assert '"rerun"' not in s and '"telemetry"' in s  # the peers logged nothing

        mine = tmp_path / "mine.rrd"
        verify = subprocess.run([rerun_exe(), "rrd", "verify", str(mine)], capture_output=True,
                                text=True, timeout=120, env=env())
        assert verify.returncode == 0, verify.stderr[-2000:]
        text = subprocess.run([rerun_exe(), "rrd", "print", str(mine)], capture_output=True,
                              text=True, timeout=120, env=env()).stdout
        assert "/world/truth" in text and "/peers/s1/tracks" in text
        summaries = read_summaries(tmp_path / "others", names)
        ended = {n: (s["stop_reason"], s["scans"], s["last_k"], s["scans_skipped_behind"])
                 for n, s in summaries.items()}
        last = summaries[names[0]]["last_k"]  # attached and detached: no scan lost
        assert set(ended.values()) == {("end of run", last, last, 0)}, ended
        assert last < scn.num_scans, ended
    finally:
        if session is not None:
            session.close()
        stop_all([view] if view is not None else [])
        others.stop_all()


def test_ellipses_lie_at_two_sigma_of_their_component():
    """Every point of a drawn ellipse is at Mahalanobis distance 2 from its mean (the closed
    form Cholesky factor against NumPy's inverse of the position block)."""
    rng = np.random.default_rng(3)
    A = rng.normal(size=(40, 4, 4))
    P = A @ A.transpose(0, 2, 1) + 0.05 * np.eye(4)
    m = rng.normal(size=(40, 4))
    E = ellipses(m, P)
    d = E - m[:, None, [0, 2]]
    q = np.einsum("npi,nij,npj->np", d, np.linalg.inv(P[:, [0, 2]][:, :, [0, 2]]), d)
    np.testing.assert_allclose(q, 4.0, rtol=1e-9)
    # closed, and once round the mean: the angle turned adds up to 2 pi
    np.testing.assert_allclose(E[:, 0], E[:, -1], atol=1e-9)
    turn = np.diff(np.unwrap(np.arctan2(d[..., 1], d[..., 0]), axis=1), axis=1).sum(axis=1)
    np.testing.assert_allclose(np.abs(turn), 2 * np.pi, rtol=1e-9)


def _two_recordings(out, bad_key: bool = False) -> None:
    """Two peers' recordings in ``out``: each heard s1's scan 1 and the truth and published its
    tracks; with ``bad_key`` s2's also holds a received record whose key is not a string."""
    scan = encode(Scan("s1", 1, np.ones((3, 2))))
    truth = encode(Truth(1, np.array([1]), np.zeros((1, 4))))
    for i, peer in enumerate(("s1", "s2")):
        rec = Recorder(out / f"peer-{peer}.mcap", {"peer": peer, "network": "net"})
        rec.receive(10.0 + i, "sensornet/net/scan/s1", scan)
        rec.receive(10.5 + i, "sensornet/net/truth", truth)
        rec.tracks(10.6 + i, 1, encode(Tracks(peer, 1, np.ones((2, 4)))))
        if bad_key and peer == "s2":
            rec._log("receive", 10.7, {"t": 10.7, "key": 5, "payload": "AA==", "message": None})
        rec.close()


def test_the_view_rebuilds_offline_from_peers_mcap_recordings(tmp_path):
    """Two peers' recordings (what each received, and its own tracks): the scans and the truth
    both heard are drawn once, each peer's tracks under its own name."""
    _two_recordings(tmp_path)
    calls = _Rec()
    state = ViewState(Batcher(rr, calls), ["s1", "s2"])
    drawn = replay_recordings(state, sorted(tmp_path.glob("*.mcap")))
    state.b.flush()
    assert drawn == 4 and state.handled == 4  # scan, truth, two peers' tracks
    got = calls.by_path()
    assert got["world/scans/s1"][0] == [1] and got["world/truth"][0] == [1]
    assert {"peers/s1/tracks", "peers/s2/tracks"} <= set(got)


class _Scorer:
    """What a recorder reads of a peer's scorer: the truth of scan k (one target at k = 1,
    none at k = 2; ids None at k = 3: not drawable) and the position columns."""

    pos = (0, 2)

    def truth(self, k: int) -> np.ndarray:
        return np.array([[5.0, 1, 6, 1]]) if k in (1, 3) else np.zeros((0, 4))

    def truth_ids(self, k: int) -> np.ndarray | None:
        return {1: np.array([7]), 2: np.zeros(0, np.int64)}.get(k)


def test_the_offline_view_draws_the_truth_the_peers_scored_against(tmp_path):
    """Peers of a run hear no truth message: their recordings hold the truth their scorers
    had (``sensornet run --record``), which the offline view draws as the world's (once,
    however many peers recorded it; a scan with no target too, which clears the map); one
    without ids is counted as undecodable."""
    for peer in ("s1", "s2"):
        rec = Recorder(tmp_path / f"peer-{peer}.mcap", {"peer": peer, "network": "net"})
        rec.attach(type("Core", (), {"scorer": _Scorer()})())
        for k in (1, 2, 3):
            rec.tracks(10.0 + k, k, encode(Tracks(peer, k, np.ones((1, 4)))))
        rec.close()
    calls = _Rec()
    state = ViewState(Batcher(rr, calls), ["s1", "s2"])
    drawn = replay_recordings(state, sorted(tmp_path.glob("*.mcap")))
    state.b.flush()
    assert drawn == 8 and state.rejected == 2  # 6 tracks, 2 truths; k = 3's truth per peer
    got = calls.by_path()
    assert got["world/truth"][0] == [1, 2]
    assert got["metrics/cardinality/truth"][0] == [1, 2]


@pytest.mark.network  # the command in a child process, and the rerun CLI
def test_view_from_mcap_writes_a_recording_and_refuses_a_bad_file(tmp_path):
    """``sensornet view NET --from-mcap FILE... --out F.rrd`` (the picture rebuilt offline):
    a recording Rerun verifies, with the scenario's sensors and legend, the scans and truth
    once and each peer's tracks; a record of the wrong shape counted as undecodable; a file
    that is not a whole recording (garbage, cut short) a one-line error naming it."""
    _two_recordings(tmp_path, bad_key=True)
    files = [str(p) for p in sorted(tmp_path.glob("peer-*.mcap"))]
    rrd = tmp_path / "offline.rrd"

    def view(*paths: str) -> subprocess.CompletedProcess:
        return subprocess.run(
            [sys.executable, "-m", "sensornet", "view", "net", "--scenario", "seed000",
             "--from-mcap", *paths, "--out", str(rrd)], cwd=tmp_path, env=env(),
            capture_output=True, text=True, timeout=120)

    done = view(*files)
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stderr.strip().splitlines()[-1] == (
        f"view: 4 recorded messages drawn from 2 recordings (1 undecodable) -> {rrd}")
    verify = subprocess.run([rerun_exe(), "rrd", "verify", str(rrd)], capture_output=True,
                            text=True, timeout=120, env=env())
    assert verify.returncode == 0, verify.stderr[-2000:]
    text = subprocess.run([rerun_exe(), "rrd", "print", str(rrd)], capture_output=True,
                          text=True, timeout=120, env=env()).stdout
    for entity in ("/world/sensors", "/legend", "/world/scans/s1", "/world/truth",
                   "/peers/s1/tracks", "/peers/s2/tracks"):
        assert entity in text, entity
    whole = Path(files[0]).read_bytes()
    (tmp_path / "garbage.mcap").write_bytes(b"not a recording")
    (tmp_path / "cut.mcap").write_bytes(whole[: len(whole) // 2])
    for bad in ("garbage.mcap", "cut.mcap"):
        done = view(files[0], str(tmp_path / bad))
        err = done.stderr.strip().splitlines()
        assert done.returncode == 2 and len(err) == 1, done.stderr[-2000:]
        assert err[0].startswith(f"sensornet: error: --from-mcap: {tmp_path / bad}: "), err


def test_view_command_errors_are_one_line(capsys):
    with pytest.raises(SystemExit):
        main(["view", "bad/name"])
    capsys.readouterr()
    assert main(["view", "net"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--connect" in err[0]
    assert main(["view", "net", "--connect", "tcp/127.0.0.1:1"]) == 2
    assert "--out" in capsys.readouterr().err


def test_a_flooding_peer_sends_the_last_pooled_scans_of_a_scan_sampled_in_order():
    """A flooding peer's fusion records come per round and flood step, each with a new scan
    set: the report carries the plane points of the last one (packed once, when sent), at
    most POOLED_SHOWN of them by a fixed stride, in the place the first record gave them;
    a value that is not finite is left out."""
    scn = load_scenario("seed004", {"scenario.num_scans": 3})
    names = scn.sensor_names
    core = make_peer(scn, names[0], score_truth=False)
    core.wants_truth = False
    sent: list[bytes] = []
    obs = Observer(core, 1.0).attach(sent.append)
    rng = np.random.default_rng(4)
    first = ScanSet({n: rng.uniform(1.0, 50.0, (3, 2)) for n in names[:2]})
    last = ScanSet({n: rng.uniform(1.0, 50.0, (40, 2)) for n in names[:12]})
    core.consensus.last_fused = first
    obs.record(Record("fusion", 5, {"n_fused": 2}))
    obs.record(Record("cost", 5, {"bad": float("nan"), "good": 3.0}))
    core.consensus.last_fused = last
    obs.record(Record("fusion", 5, {"n_fused": 12}))
    obs.published(Publish("tracks", 5, b"", Tracks(core.name, 5, np.zeros((0, 4)))), 2.0)
    obs.flush(idle=True)
    (msg,) = [decode(b) for b in _entries(sent)]
    p = np.asarray(core.consensus.hooks.plane(last), float).reshape(-1, 2)
    assert len(p) == 480 and len(msg.points["pooled"]) == 240  # every 2nd: at most 400
    np.testing.assert_allclose(msg.points["pooled"], p[::2])
    assert msg.values["flooding/scans_held"] == 12 and msg.values["components/fused"] == 12
    assert msg.values["cost/good"] == 3.0 and "cost/bad" not in msg.values
