"""The view's flush at 50 peers (issue 38): columns built once for all the entities of a kind
and sent through Rerun's native call write the same recording as an entity at a time through
``send_columns``; the native call is taken only for Rerun's own recordings."""

from __future__ import annotations

from collections import defaultdict

import numpy as np
import rerun as rr
from sensornet.protocol.messages import Telemetry

from benchmarks.bench_view import rrd_rows as _rows  # entity -> its rows, sorted
from sensornet import view_columns, view_state
from sensornet.view import FLUSH_S, SERIES_EVERY, LiveView
from sensornet.view_columns import Batcher, _native_send
from sensornet.view_state import ViewState


class _Wrapper:
    """A recorder that is not a ``RecordingStream``: the batcher goes through its
    ``send_columns`` (Rerun's Python wrapper), an entity at a time."""

    def __init__(self, stream) -> None:
        self.stream = stream

    def send_columns(self, path, indexes, columns):
        self.stream.send_columns(path, indexes=indexes, columns=columns)


class _Calls:
    """A recorder that keeps each call's entity and scans."""

    def __init__(self) -> None:
        self.calls: list[tuple[str, list[int]]] = []

    def send_columns(self, path, indexes, columns):
        self.calls.append((path, indexes[0].as_arrow_array().to_pylist()))


class _OneByOne(Batcher):
    """Every entity's columns built on its own (a subclass's ``_send``: no grouping)."""

    def _send(self, path, kind, ks, ts, data):
        super()._send(path, kind, ks, ts, data)


def _draw(b: Batcher) -> None:
    rng = np.random.default_rng(3)
    for flush in range(3):
        for k in range(10 * flush + 1, 10 * flush + 11):
            t = 0.1 * k
            for p in range(4):
                b.series(k, t, (f"m/a/{p}", f"m/b/{p}"), (float(k), np.nan if k % 7 else 1.0))
                n = int(rng.integers(0, 4))
                b.points(f"p/{p}/tracks", k, t, rng.normal(size=(n, 2)), (1, 2, 3), 5.0,
                         labels=[f"{p}/{i}" for i in range(n)] if k % 3 else None)
                b.points(f"p/{p}/scan", k, t, rng.normal(size=(n + 1, 2)),
                         rng.integers(0, 256, (n + 1, 3)), 2.0)
                A = rng.normal(size=(n, 4, 4))
                b.ellipses(f"p/{p}/local", k, t, rng.normal(size=(n, 4)) * 100,
                           A @ A.transpose(0, 2, 1) + np.eye(4), (9, 8, 7), 1.0, dashed=True)
                b.ellipses(f"p/{p}/fused", k, t, rng.normal(size=(n, 4)) * 100,
                           A @ A.transpose(0, 2, 1) + np.eye(4), (9, 8, 7), 1.5)
            b.text("events", k, t, f"scan {k}")
        b.flush()


def test_grouped_native_flush_writes_what_one_entity_at_a_time_wrote(tmp_path):
    """The same rows (series with values left out, labelled and unlabelled points, dashed
    and solid ellipses, a text log) drawn by the batcher as the view uses it and by one
    building each entity alone and sending it through ``send_columns``: the two ``.rrd``
    files hold the same entities, each with the same rows."""
    written = {}
    for side in ("grouped", "one-by-one"):
        rec = rr.RecordingStream("sensornet-test", recording_id=f"native-{side}")
        rec.set_sinks(rr.FileSink(str(tmp_path / f"{side}.rrd")))
        b = Batcher(rr, rec) if side == "grouped" else _OneByOne(rr, _Wrapper(rec))
        assert (b._native is not None) == (side == "grouped")
        _draw(b)
        rec.flush()
        rec.disconnect()
        assert b.errors == 0
        written[side] = _rows(tmp_path / f"{side}.rrd")
    grouped, alone = written["grouped"], written["one-by-one"]
    assert len(grouped) == 4 * 6 + 1 and set(grouped) == set(alone)
    assert "/m/b/0" in grouped and len(grouped["/m/b/0"]) == 3 * 10 // 7  # finite rows only
    for entity in alone:
        assert grouped[entity] == alone[entity], entity


def test_the_native_call_only_for_rerun_s_own_recordings():
    """A ``RecordingStream``: its native handle; the ``rerun`` module itself (the view's
    global recording): None, as ``rr.send_columns`` passes; anything else: no native call."""
    stream = rr.RecordingStream("sensornet-test", recording_id="native-kinds")
    send, handle = _native_send(rr, stream)
    assert send is not None and handle is not None
    send, handle = _native_send(rr, rr)
    assert send is not None and handle is None
    assert _native_send(rr, _Wrapper(stream)) == (None, None)


def test_the_health_series_go_once_their_flush_periods_add_up_to_series_every():
    """The view's flush (``SERIES_EVERY`` periods of ``FLUSH_S``): at a 1 s period a series
    already sent keeps its rows for 3 flushes and sends them all with the 4th, at 2 s with the
    2nd; the map goes every flush; a new series (a peer's first report) goes at once. No row
    is lost or sent twice."""
    assert SERIES_EVERY == 4
    for period, sent_at in ((FLUSH_S, (1, 5, 9)), (2 * FLUSH_S, (1, 3, 5, 7, 9))):
        rec = _Calls()
        view = LiveView("net", lambda b: ViewState(b, ["s1"]), rr, rec, say=lambda s: None)
        for k in range(1, 10):
            b = view.batcher
            b.scalar("metrics/old", k, 0.1 * k, float(k))
            if k == 2:
                b.scalar("metrics/new", k, 0.1 * k, 1.0)
            b.points("peers/s1/tracks", k, 0.1 * k, np.zeros((1, 2)), (1, 2, 3), 5.0)
            view.flush_s = period  # as the loop left it (a slow flush doubles it)
            view.flush()
        by = defaultdict(list)
        for path, scans in rec.calls:
            by[path].append(scans)
        assert by["peers/s1/tracks"] == [[k] for k in range(1, 10)]
        assert [s[-1] for s in by["metrics/old"]] == list(sent_at)
        assert [k for s in by["metrics/old"] for k in s] == list(range(1, 10))
        assert by["metrics/new"][0] == [2]  # new: at once, though series were held


def test_the_report_names_cache_is_bounded(monkeypatch):
    """A report leaves out values that are not finite, so a peer's tuples of value names vary
    scan to scan: the view keeps at most PATHS_KEEP of them, and every row still goes to its
    own series."""
    monkeypatch.setattr(view_state, "PATHS_KEEP", 2)
    rec = _Calls()
    state = ViewState(Batcher(rr, rec), ["s1"])
    names = ("ospa/fused", "age", "trust/s2/weight")
    for k in range(1, 9):  # every scan another subset of the names
        values = {x: float(k) for i, x in enumerate(names) if (k >> i) & 1 or i == 0}
        state.telemetry(Telemetry("s1", k, values, (), {}, None))
        assert len(state._paths) <= 2
    state.b.flush()
    scans = {path: s for path, s in rec.calls if path.startswith("metrics/")}
    assert sorted(scans["metrics/ospa/s1/fused"]) == list(range(1, 9))
    assert len(scans) == 3 and sorted(len(s) for s in scans.values()) == [4, 4, 8]


def test_id_marks_start_afresh_with_every_id_of_the_call(monkeypatch):
    """Past ID_MARKS_KEEP ids the cache is cleared; the ids of that call it held before are
    made again (they were looked up after the clear: a KeyError, the view's end)."""
    monkeypatch.setattr(view_state, "ID_MARKS_KEEP", 3)
    marks = view_state.IdMarks()
    marks(np.array([[0, 1, 1], [0, 1, 2]]))
    ids = np.array([[0, 1, 1], [0, 1, 3], [0, 1, 4]])
    colors, labels = marks(ids)
    np.testing.assert_array_equal(colors, view_state.id_color(ids))
    assert labels == view_state.id_labels(ids) == ["0.1.1", "0.1.3", "0.1.4"]
    assert len(marks._marks) == 3


def test_the_series_numbers_cache_is_bounded(monkeypatch):
    """The batcher keeps the entity numbers of at most SERIES_KEEP tuples of series (a
    peer's report names vary scan to scan); past it, it starts afresh and every row still
    goes to its own series, in the order it came, values not finite (NaN, None) left out."""
    monkeypatch.setattr(view_columns, "SERIES_KEEP", 2)
    rec = _Calls()
    b = Batcher(rr, rec)
    names = ("m/a", "m/b", "m/c")
    for k in range(1, 9):  # every scan another subset of the names
        paths = tuple(x for i, x in enumerate(names) if (k >> i) & 1 or i == 0)
        b.series(k, 0.1 * k, paths, [float(k)] * (len(paths) - 1) + [None if k == 5 else 1.0])
        assert len(b._numbers) <= 2
    b.scalar("m/a", 9, 0.9, float("nan"))
    assert b.pending() == 16 - 1  # 16 values, one None
    b.flush()
    scans = dict(rec.calls)
    assert len(rec.calls) == 3 and scans["m/a"] == list(range(1, 9))
    assert scans["m/b"] == [2, 3, 6, 7] and scans["m/c"] == [4, 6, 7]  # 5: None
