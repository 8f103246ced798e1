"""The live view's batched Rerun writer (issue 38): rows gathered per entity and sent in one
``send_columns`` call each per flush (a Python ``rr.log`` costs ~60 us a row; ``send_columns``
~150 us a call plus ~1 us a row), so one process can show 100 peers at 10 scans/s. Map
entities may be decimated to their newest rows when the view is behind (counted).

Knows nothing of messages: :mod:`sensornet.view_state` turns those into rows.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from itertools import chain

import numpy as np
import pyarrow as pa
import rerun_bindings
from rerun.components import LineStrip2DBatch

from sensornet.peers.rerun_layout import dashed, ellipses
from sensornet.peers.rerun_sink import north_up

MAP_KINDS = ("points", "strips", "ellipses")
"""Kinds of map entities (decimated when the view is behind); the rest are series and logs."""
SERIES_KEEP = 4_096
"""Tuples of series entities whose numbers :meth:`Batcher.series` keeps (then afresh)."""
GROUPED = ("points", "ellipses")
"""Kinds whose columns a flush builds for all their entities at once (:meth:`Batcher._group`;
the series too, :meth:`Batcher._series_sends`: ~1,900 of the ~1,950 entities a flush at 50
peers); the rest an entity at a time."""


@dataclass
class _Rows:
    """The buffered rows of one entity: times and one payload per row."""

    kind: str
    ks: list = field(default_factory=list)
    ts: list = field(default_factory=list)
    rows: list = field(default_factory=list)


class Batcher:
    """Rows per entity, flushed as one ``send_columns`` per entity (``rec``: a Rerun
    ``RecordingStream``, or anything with its ``send_columns``; ``rr``: the module)."""

    def __init__(self, rr, rec, map_keep: int | None = None) -> None:
        """``map_keep``: newest rows of a map entity sent per flush (None: all)."""
        self.rr, self.rec = rr, rec
        self.map_keep = map_keep
        self._rows: dict[str, _Rows] = {}
        self.decimated = 0
        """Map rows left out because newer ones of the same entity were waiting."""
        self.calls = 0
        self.rows_sent = 0
        self._indexes: dict = {}
        self._sent: set[str] = set()
        """Entities sent so far (:meth:`flush`'s ``hold`` keeps back only those)."""
        self.errors = 0
        """Entities Rerun refused (the first said in one warning)."""
        self._native, self._recording = _native_send(rr, rec)
        self._number: dict[str, int] = {}
        """Each series entity's number (:meth:`series`) ..."""
        self._named: list[str] = []
        """... and each number's entity."""
        self._numbers: dict[tuple, np.ndarray] = {}
        """A tuple of series entities -> their numbers (at most :data:`SERIES_KEEP` kept)."""
        self._calls: list = []
        """The series rows since the last flush: one ``(numbers, values, scan, time)`` a
        call, made into columns at the flush for all rows at once (:meth:`_series_rows`)."""
        self._held: tuple | None = None
        """Rows of series already sent that a flush kept back (``hold``): arrays of numbers,
        values, scans and times."""
        self._was_sent = np.zeros(0, bool)
        """Per series number: whether the entity has had rows sent."""
        self.builders: dict = {}
        """Kinds other modules add (:mod:`sensornet.view_map`'s geographic map): ``kind ->
        builder(rr, rows) -> columns``; their entities are map entities (decimated)."""

    def _add(self, path: str, kind: str, k: int, t: float, row) -> None:
        r = self._rows.get(path)
        if r is None:
            r = self._rows[path] = _Rows(kind)
        r.ks.append(int(k))
        r.ts.append(float(t))
        r.rows.append(row)

    def scalar(self, path: str, k: int, t: float, value) -> None:
        if value is not None and math.isfinite(value):
            self.series(k, t, (path,), (float(value),))

    def series(self, k: int, t: float, paths: Sequence[str], values: Iterable) -> None:
        """Many series' rows of one scan at once (a peer's report: ~30 values; ``paths`` its
        names' entities, made once per peer by the caller); those not finite (or None) are
        left out at the flush, as :meth:`scalar` does. Kept as one entry a call: at 50 peers
        ~15,000 values a second, each three list appends when kept per entity."""
        key = paths if type(paths) is tuple else tuple(paths)
        numbers = self._numbers.get(key)
        if numbers is None:
            if len(self._numbers) >= SERIES_KEEP:
                self._numbers.clear()
            numbers = self._numbers[key] = np.array([self._series_number(p) for p in key],
                                                    np.int64)
        values = list(values)
        if len(values) != len(numbers):
            raise ValueError(f"{len(values)} values for {len(numbers)} series")
        self._calls.append((numbers, values, int(k), float(t)))

    def _series_number(self, path: str) -> int:
        i = self._number.get(path)
        if i is None:
            i = self._number[path] = len(self._named)
            self._named.append(path)
        return i

    def _series_rows(self, hold: bool):
        """The series rows to send now, grouped by entity in the order they came: ``(paths,
        starts, counts, scans, times, values)`` (arrays sorted by entity), or None; rows not
        finite left out; with ``hold``, the rows of entities already sent kept back (with
        those held before, first) for a later flush."""
        calls, self._calls = self._calls, []
        held, self._held = self._held, None
        parts = [] if held is None else [held]
        if calls:
            counts = np.fromiter((len(c[0]) for c in calls), np.int64, len(calls))
            V = np.array(list(chain.from_iterable(c[1] for c in calls)), float)
            rows = (np.concatenate([c[0] for c in calls]), V,
                    np.repeat(np.fromiter((c[2] for c in calls), np.int64, len(calls)), counts),
                    np.repeat(np.fromiter((c[3] for c in calls), float, len(calls)), counts))
            ok = np.isfinite(V)
            parts.append(rows if ok.all() else tuple(a[ok] for a in rows))
        if not parts:
            return None
        E, V, K, T = (np.concatenate(a) for a in zip(*parts, strict=True)) if len(parts) > 1 \
            else parts[0]
        if len(self._was_sent) < len(self._named):
            self._was_sent = np.concatenate(
                [self._was_sent, np.zeros(len(self._named) - len(self._was_sent), bool)])
        if hold:
            kept = self._was_sent[E]
            if kept.any():
                self._held = (E[kept], V[kept], K[kept], T[kept])
                go = ~kept
                E, V, K, T = E[go], V[go], K[go], T[go]
        if not len(E):
            return None
        order = np.argsort(E, kind="stable")  # by entity, each's rows in the order they came
        E, V, K, T = E[order], V[order], K[order], T[order]
        starts = np.flatnonzero(np.concatenate(([True], E[1:] != E[:-1])))
        counts = np.diff(np.append(starts, len(E)))
        first = E[starts]
        self._was_sent[first] = True
        named = self._named
        paths = [named[i] for i in first.tolist()]
        self._sent.update(paths)
        return paths, starts, counts, K, T, V

    def ellipses(self, path: str, k: int, t: float, means: np.ndarray, covs: np.ndarray,
                 color, radius: float, dashed: bool = False) -> None:
        """The 2-sigma ellipses of the position marginals of ``means (n, d)``, ``covs (n, d,
        d)`` (:func:`peers.rerun_layout.ellipses`; ``dashed``: every other segment), drawn
        as line strips of ``color``. Kept as given until a flush, which draws the ellipses
        of all the entity's rows in one vectorised call (and none of the rows a behind view
        decimates)."""
        self._add(path, "ellipses", k, t, (means, covs, color, -abs(radius), dashed))

    def points(self, path: str, k: int, t: float, xy, colors, radius: float,
               labels: list[str] | None = None) -> None:
        """Points (map coordinates ``(n, 2)``, kept as given until a flush turns all rows
        north-up in one call); ``colors`` one ``(3,)`` or ``(n, 3)`` (one is repeated when
        flushed, with the other rows' in one call)."""
        xy = np.asarray(xy, float).reshape(-1, 2)
        self._add(path, "points", k, t, (xy, _colors(colors, len(xy), path), -abs(radius),
                                         labels))

    def strips(self, path: str, k: int, t: float, lines, color, radius: float) -> None:
        """Polylines (map coordinates): an ``(n, m, 2)`` array or a list of ``(m_i, 2)``;
        ``color`` one ``(3,)`` or one per line. Kept flat (points and lengths): a flush then
        hands Rerun one Arrow array, not a Python object per line."""
        if isinstance(lines, np.ndarray) and lines.ndim == 3:
            flat = lines.reshape(-1, 2)
            lengths = np.full(len(lines), lines.shape[1], dtype=np.int64)
        else:
            lines = [np.asarray(a, float).reshape(-1, 2) for a in lines]
            flat = np.concatenate(lines) if lines else np.zeros((0, 2))
            lengths = np.array([len(a) for a in lines], dtype=np.int64)
        self._add(path, "strips", k, t, (north_up(flat), lengths,
                                         _colors(color, len(lengths), path), -abs(radius)))

    def text(self, path: str, k: int, t: float, message: str, level: str = "INFO") -> None:
        self._add(path, "text", k, t, (message, level))

    def translation(self, path: str, k: int, t: float, xy) -> None:
        x, y = north_up(np.asarray(xy, float).reshape(2))
        self._add(path, "transform", k, t, (x, y, 0.0))

    def pending(self) -> int:
        series = sum(int(np.isfinite(np.array(c[1], float)).sum()) for c in self._calls)
        held = 0 if self._held is None else len(self._held[0])
        return sum(len(r.ks) for r in self._rows.values()) + series + held

    def flush(self, between=None, every: int = 200, hold: tuple[str, ...] = ()) -> None:
        """Every entity's rows in one call each (map entities: the newest :attr:`map_keep`);
        ``between()`` called after each ``every`` entities (the view handles what arrived
        meanwhile: rows it adds go to the next flush), so that a long flush does not hold
        back the messages waiting. Entities of the kinds in ``hold`` keep their rows for a
        later flush (the view sends its many health series less often than its map), once
        their first rows have gone: a new entity (a peer's first report) goes at once."""
        rows, self._rows = self._rows, {}
        if hold:  # kept back first: rows added meanwhile join them
            sent = self._sent
            self._rows = {p: r for p, r in rows.items() if r.kind in hold and p in sent}
            rows = {p: r for p, r in rows.items() if p not in self._rows}
        series = self._series_rows("scalar" in hold)
        self._sent.update(rows)
        self._indexes = {}
        grouped = type(self)._send is Batcher._send  # a subclass's own _send: row by row
        total = len(rows) + (0 if series is None else len(series[0]))
        kinds: dict[str, list] = {}
        for path, r in rows.items():
            ks, ts, data = r.ks, r.ts, r.rows
            keep = self.map_keep
            if (keep is not None and (r.kind in MAP_KINDS or r.kind in self.builders)
                    and len(ks) > keep):
                self.decimated += len(ks) - keep
                ks, ts, data = ks[-keep:], ts[-keep:], data[-keep:]
            kinds.setdefault(_group_of(r.kind, data) if grouped else "", []).append(
                (path, r.kind, ks, ts, data))
        i = 0
        if series is not None:
            kinds = {"series": [], **kinds}
        for kind, items in kinds.items():
            if kind == "series":  # the series' columns at once (:meth:`_series_rows`)
                sends = self._series_sends(series, grouped)
            elif kind:  # the entities' columns at once, then sent entity by entity
                sends = self._group(kind, items)
            else:
                sends = ((path, k, ks, ts, data) for path, k, ks, ts, data in items)
            for item in sends:
                if kind and len(item) == 4:
                    self._put(*item)
                else:
                    self._send(*item)
                i += 1
                if between is not None and i % every == 0 and i < total:
                    between()

    def _series_sends(self, series: tuple, grouped: bool):
        """Each series entity's ``(path, index, columns, rows)`` (its part of columns built
        once, as :meth:`_group` builds them), or ``(path, "scalar", ks, ts, values)`` for a
        subclass's own :meth:`_send`."""
        paths, starts, counts, K, T, V = series
        if not grouped:
            for path, s, n in zip(paths, starts.tolist(), counts.tolist(), strict=True):
                yield path, "scalar", K[s:s + n].tolist(), T[s:s + n].tolist(), \
                    V[s:s + n].tolist()
            return
        scan = pa.array(K)
        sim = pa.array((T * 1e9).astype("timedelta64[ns]"), pa.duration("ns"))
        values = _rows(pa.array(V, pa.float64()))
        descriptor = _descriptor(self.rr, "Scalars", "scalars")
        for path, s, n in zip(paths, starts.tolist(), counts.tolist(), strict=True):
            yield (path, [_Index("scan", scan.slice(s, n)), _Index("sim", sim.slice(s, n))],
                   [_Column(descriptor, values.slice(s, n))], n)

    def _send(self, path: str, kind: str, ks: list, ts: list, data: list) -> None:
        rr = self.rr
        index = self._index(ks, ts)
        if kind == "scalar":
            cols = [_Column(_descriptor(rr, "Scalars", "scalars"),
                            _rows(pa.array(data, pa.float64())))]
        elif kind == "points":
            cols, lengths = self._point_columns(data)
            cols += self._label_columns(data, lengths) or []
        elif kind == "ellipses":
            cols = self._ellipse_columns(data)
        elif kind == "strips":
            lengths = np.fromiter((len(d[1]) for d in data), np.int64, len(data))
            cols = self._strip_columns(
                np.concatenate([d[0] for d in data]), np.concatenate([d[1] for d in data]),
                lengths, repeat_colors([d[2] for d in data], lengths),
                np.fromiter((d[3] for d in data), np.float32, len(data)))
        elif kind in self.builders:
            cols = self.builders[kind](rr, data)
        elif kind == "text":
            cols = rr.TextLog.columns(text=[d[0] for d in data], level=[d[1] for d in data])
        else:  # transform
            cols = rr.Transform3D.columns(translation=np.asarray(data, float))
        self._put(path, index, cols, len(ks))

    def _put(self, path: str, index: list, cols: list, rows: int) -> None:
        """One entity's columns to the recording: straight to Rerun's native call for a real
        recording stream (its Python ``send_columns`` wrapper, error context and argument
        checks cost ~35 us an entity, as much as the call: thousands of entities a second at
        50 peers), else its ``send_columns`` (tests' recorders)."""
        native = self._native
        if native is None:
            self.rec.send_columns(path, indexes=index, columns=cols)
        else:
            try:
                native(path, timelines={i.timeline_name(): i.as_arrow_array() for i in index},
                       components={c.component_descriptor(): c.as_arrow_array() for c in cols},
                       recording=self._recording)
            except Exception as exc:  # as Rerun's own wrapper: said, never the view's end
                self.errors += 1
                if self.errors == 1:
                    warnings.warn(f"view: Rerun refused {path}: {exc}", stacklevel=2)
        self.calls += 1
        self.rows_sent += rows

    def _group(self, kind: str, items: list):
        """``(path, index, columns, rows)`` of every entity of ``kind`` in ``items`` (``(path,
        kind, ks, ts, rows)``): each column built once for all their rows (one NumPy and one
        Arrow call per column, not per entity) and sliced per entity (Arrow slices share the
        buffers), the same arrays as :meth:`_send` builds an entity at a time."""
        counts = np.fromiter((len(it[2]) for it in items), np.int64, len(items))
        starts = np.zeros(len(items) + 1, np.int64)
        np.cumsum(counts, out=starts[1:])
        ks = np.fromiter(chain.from_iterable(it[2] for it in items), np.int64, int(starts[-1]))
        ts = np.fromiter(chain.from_iterable(it[3] for it in items), float, int(starts[-1]))
        scan = pa.array(ks)
        sim = pa.array((ts * 1e9).astype("timedelta64[ns]"), pa.duration("ns"))
        data = [d for it in items for d in it[4]]
        if kind == "points":
            cols, extra = self._points_all(data, items, starts)
        else:  # ("ellipses", dimension, dashed): rows alike
            cols, extra = self._ellipses_all(data, kind[2]), None
        for j, (path, _, _, _, _) in enumerate(items):
            s, n = int(starts[j]), int(counts[j])
            index = [_Index("scan", scan.slice(s, n)), _Index("sim", sim.slice(s, n))]
            entity = [_Column(d, a.slice(s, n)) for d, a in cols]
            if extra is not None and extra[j] is not None:
                entity += extra[j]
            yield path, index, entity, n

    def _point_columns(self, data: list) -> tuple[list, np.ndarray]:
        """Points2D columns (positions, north-up, radii, colours) of these rows, one entity's
        or many's, and each row's number of points."""
        rr = self.rr
        lengths = np.fromiter((len(d[0]) for d in data), np.int64, len(data))
        xy = np.concatenate([d[0] for d in data]) if data else np.zeros((0, 2))
        xy[:, 1] *= -1.0  # north_up of every row at once (the concatenation is a copy)
        colors = repeat_colors([d[1] for d in data], lengths)
        radii = np.repeat(np.fromiter((d[2] for d in data), np.float32, len(data)), lengths)
        off = offsets_of(lengths)
        return [_Column(_descriptor(rr, "Points2D", "positions"),
                        list_array(xy, off, _datatype(rr, "Points2D", "positions"),
                                   np.float32)),
                _Column(_descriptor(rr, "Points2D", "radii"), _rows(pa.array(radii), off)),
                _Column(_descriptor(rr, "Points2D", "colors"),
                        _rows(pa.array(packed_colors(colors)), off))], lengths

    def _label_columns(self, rows: list, lengths: np.ndarray) -> list | None:
        """One entity's Points2D label columns (``lengths``: its rows' points), always shown;
        None if no row of it is labelled (no label columns then)."""
        if not any(d[3] is not None for d in rows):
            return None
        rr = self.rr
        labels = [s for d in rows for s in (d[3] or [""] * len(d[0]))]
        return [_Column(_descriptor(rr, "Points2D", "labels"),
                        _rows(pa.array(labels, pa.string()), offsets_of(lengths))),
                _Column(_descriptor(rr, "Points2D", "show_labels"),
                        _rows(pa.array(np.ones(len(rows), bool))))]

    def _points_all(self, data: list, items: list, starts: np.ndarray) -> tuple[list, list]:
        """Points2D columns of all rows (:meth:`_point_columns`) and per entity its label
        columns (:meth:`_label_columns`, None: none)."""
        cols, lengths = self._point_columns(data)
        extra = [self._label_columns(data[starts[j]:starts[j + 1]],
                                     lengths[starts[j]:starts[j + 1]])
                 for j in range(len(items))]
        return [(c.descriptor, c.array) for c in cols], extra

    def _ellipses_all(self, data: list, dash: bool) -> list:
        """LineStrips2D columns of rows of :meth:`ellipses` alike (one state dimension, all
        dashed or none) of many entities: :meth:`_alike_ellipse_columns`."""
        return [(c.descriptor, c.array) for c in self._alike_ellipse_columns(data, dash)]

    def _strip_columns(self, points: np.ndarray, per_strip: np.ndarray, per_row: np.ndarray,
                       colors: np.ndarray, radii: np.ndarray) -> list:
        """LineStrips2D columns: ``points (P, 2)`` end to end, ``per_strip (S,)`` points per
        strip, ``per_row (rows,)`` strips per row, ``colors (S, 3)`` and ``radii (rows,)``."""
        rr = self.rr
        off = offsets_of(per_row)
        return [_Column(_descriptor(rr, "LineStrips2D", "strips"),
                        _rows(strip_array(points, per_strip), off)),
                _Column(_descriptor(rr, "LineStrips2D", "radii"),
                        _rows(pa.array(np.repeat(radii.astype(np.float32), per_row)), off)),
                _Column(_descriptor(rr, "LineStrips2D", "colors"),
                        _rows(pa.array(packed_colors(colors)), off))]

    def _ellipse_columns(self, data: list) -> list:
        """Rows of :meth:`ellipses` as LineStrips2D columns: every row's ellipses (and their
        dashes) computed at once when the rows are alike (one state dimension, all dashed or
        none, as an entity's are), else row by row (:func:`ellipse_strips`)."""
        dims = {np.shape(d[0])[-1] for d in data}
        dash = {bool(d[4]) for d in data}
        if len(dims) != 1 or len(dash) != 1:
            rows = ellipse_strips(data)
            lengths = np.fromiter((len(r[1]) for r in rows), np.int64, len(rows))
            return self._strip_columns(
                np.concatenate([r[0] for r in rows]), np.concatenate([r[1] for r in rows]),
                lengths, repeat_colors([r[2] for r in rows], lengths),
                np.fromiter((r[3] for r in rows), np.float32, len(rows)))
        return self._alike_ellipse_columns(data, dash.pop())

    def _alike_ellipse_columns(self, data: list, dash: bool) -> list:
        """LineStrips2D columns of rows of :meth:`ellipses` alike (one state dimension, all
        dashed or none): every row's ellipses (and dashes) computed in one call."""
        counts = np.fromiter((len(d[0]) for d in data), np.int64, len(data))
        lines = north_up(ellipses(np.concatenate([np.asarray(d[0], float) for d in data]),
                                  np.concatenate([np.asarray(d[1], float) for d in data])))
        if dash:
            lines = dashed(lines)  # (N * 16, 2, 2): each ellipse's 16 dashes, in order
        per_ellipse = len(lines) // max(1, counts.sum()) if len(lines) else 0
        per_row = counts * per_ellipse
        colors = np.repeat(np.stack([np.asarray(d[2], np.uint8).reshape(3) for d in data]),
                           per_row, axis=0)
        return self._strip_columns(lines.reshape(-1, 2),
                                   np.full(len(lines), lines.shape[1], np.int64), per_row,
                                   colors, np.fromiter((d[3] for d in data), np.float32,
                                                       len(data)))

    def _index(self, ks: list, ts: list) -> list:
        """The scan and sim time columns of these rows: made once per flush for the many
        entities (a peer's series) that have rows of the same scans."""
        key = (tuple(ks), tuple(ts))
        index = self._indexes.get(key)
        if index is None:
            index = self._indexes[key] = [
                _Index("scan", pa.array(np.asarray(ks, np.int64))),
                _Index("sim", pa.array((np.asarray(ts, float) * 1e9).astype("timedelta64[ns]"),
                                       pa.duration("ns")))]
        return index


def _group_of(kind: str, data: list):
    """The group of an entity whose columns a flush builds with others' (:data:`GROUPED`):
    its kind, and for ellipses ``("ellipses", dimension, dashed)`` when its rows are alike
    (as an entity's are); ``""``: built on its own (:meth:`Batcher._send`)."""
    if kind not in GROUPED:
        return ""
    if kind != "ellipses":
        return kind
    dims = {np.shape(d[0])[-1] for d in data}
    dash = {bool(d[4]) for d in data}
    if len(dims) != 1 or len(dash) != 1:
        return ""
    return ("ellipses", dims.pop(), dash.pop())


def _native_send(rr, rec) -> tuple:
    """Rerun's native ``send_arrow_chunk`` (the binding :func:`rerun.send_columns` calls
    itself, pinned with ``rerun-sdk`` 0.41) and the recording to pass it: ``rec``'s native
    handle when ``rec`` is one of ``rr``'s recording streams, None (the global recording, as
    ``rr.send_columns`` passes) when ``rec`` is the ``rr`` module itself (``sensornet view``'s
    sink); ``(None, None)`` otherwise (a test's recorder, another Rerun): ``rec.send_columns``."""
    stream = getattr(rr, "RecordingStream", None)
    if stream is None or not (rec is rr or isinstance(rec, stream)):
        return None, None
    send = getattr(rerun_bindings, "send_arrow_chunk", None)
    if send is None:
        return None, None
    return send, (None if rec is rr else rec.to_native())


def ellipse_strips(data: list) -> list:
    """Rows of :meth:`Batcher.ellipses` ``(means (n, d), covs (n, d, d), color, radius,
    dashed)`` as rows of line strips (:meth:`Batcher.strips`' layout: flat north-up points,
    points per strip, one colour, radius), the ellipses of all the rows of one state
    dimension computed in one call."""
    lines: list = [None] * len(data)
    by_dim: dict[int, list[int]] = {}
    for i, d in enumerate(data):
        by_dim.setdefault(np.shape(d[0])[-1], []).append(i)
    for rows in by_dim.values():
        counts = np.fromiter((len(data[i][0]) for i in rows), np.int64, len(rows))
        drawn = north_up(ellipses(np.concatenate([np.asarray(data[i][0], float) for i in rows]),
                                  np.concatenate([np.asarray(data[i][1], float)
                                                  for i in rows])))  # (N, 33, 2)
        for i, part in zip(rows, np.split(drawn, np.cumsum(counts)[:-1]), strict=True):
            lines[i] = part
    out = []
    for part, (_, _, color, radius, dash) in zip(lines, data, strict=True):
        if dash:
            part = dashed(part)
        n, m = part.shape[:2]
        out.append((part.reshape(-1, 2), np.full(n, m, np.int64),
                    np.asarray(color, np.uint8).reshape(-1, 3), radius))
    return out


_ONE_COLOR: dict[tuple, np.ndarray] = {}
"""A colour given as a tuple (a peer's: tens of thousands of rows a second at 50 peers) ->
its ``(1, 3)`` array, made once (read-only: rows share it; at most 4,096 kept)."""


def _colors(colors, n: int, path: str) -> np.ndarray:
    """``colors`` as ``(1, 3)`` or ``(n, 3)`` uint8 (one for all ``n`` marks, or one each)."""
    if type(colors) is tuple:
        c = _ONE_COLOR.get(colors)
        if c is not None:
            return c
    c = np.asarray(colors, np.uint8).reshape(-1, 3)
    if len(c) not in (1, n):
        raise ValueError(f"{path}: {len(c)} colours for {n} marks (give one, or one each)")
    if type(colors) is tuple and len(c) == 1 and len(_ONE_COLOR) < 4096:
        c.flags.writeable = False
        _ONE_COLOR[colors] = c
    return c


def repeat_colors(colors: list, counts: np.ndarray) -> np.ndarray:
    """Rows' colours (each ``(1, 3)`` or ``(counts[i], 3)``) as one ``(sum counts, 3)``: a
    row's one colour repeated for each of its marks, in one call for all rows."""
    if not colors:
        return np.zeros((0, 3), np.uint8)
    given = np.fromiter((len(c) for c in colors), np.int64, len(colors))
    flat = np.concatenate(colors)
    if (given == counts).all():
        return flat
    return np.repeat(flat, np.repeat(np.where(given == counts, 1, counts), given), axis=0)


class _Index:
    """A time column (Rerun's ``TimeColumnLike``: a timeline's name and its Arrow array)."""

    __slots__ = ("name", "array")

    def __init__(self, name: str, array: pa.Array) -> None:
        self.name, self.array = name, array

    def timeline_name(self) -> str:
        return self.name

    def as_arrow_array(self) -> pa.Array:
        return self.array


class _Column:
    """A component column built here in Arrow (what ``send_columns`` reads of Rerun's
    ``ComponentColumn``: its descriptor and its array, one list per row). Rerun's own
    ``Archetype.columns(...).partition(...)`` costs ~0.1-0.5 ms an entity in Python
    conversions, and the view flushes thousands of entities a second at 50 peers."""

    __slots__ = ("descriptor", "array")

    def __init__(self, descriptor, array: pa.Array) -> None:
        self.descriptor, self.array = descriptor, array

    def component_descriptor(self):
        return self.descriptor

    def as_arrow_array(self) -> pa.Array:
        return self.array


_TEMPLATES: dict[tuple[str, str], tuple] = {}


def _template(rr, archetype: str, field: str) -> tuple:
    """Rerun's descriptor and list type of an archetype's component, from a one-row column
    Rerun builds itself (once)."""
    got = _TEMPLATES.get((archetype, field))
    if got is None:
        sample = {"positions": np.zeros((1, 2)), "radii": [1.0], "colors": [0],
                  "labels": ["a"], "show_labels": [True], "scalars": [0.0],
                  "strips": [np.zeros((2, 2))]}[field]
        (col,) = getattr(rr, archetype).columns(**{field: sample}).partition([1])
        got = _TEMPLATES[(archetype, field)] = (col.component_descriptor(),
                                                col.as_arrow_array().type)
    return got


def _descriptor(rr, archetype: str, field: str):
    return _template(rr, archetype, field)[0]


def _datatype(rr, archetype: str, field: str) -> pa.DataType:
    return _template(rr, archetype, field)[1]


_ONES: dict[int, pa.Array] = {}


def _rows(values: pa.Array, lengths=None) -> pa.Array:
    """``values`` end to end as one list per row of ``lengths`` (Arrow ``list<...>``; None:
    one value a row, the offsets kept per row count; a ``pa.Array``: the offsets, made once
    by :func:`offsets_of` for the columns of one entity)."""
    if lengths is None:
        offsets = _ONES.get(len(values))
        if offsets is None:
            offsets = _ONES[len(values)] = pa.array(np.arange(len(values) + 1, dtype=np.int32))
    else:
        offsets = lengths if isinstance(lengths, pa.Array) else offsets_of(lengths)
    return pa.ListArray.from_arrays(offsets, values)


def offsets_of(lengths) -> pa.Array:
    """Arrow list offsets ``(n + 1,)`` int32 of rows of ``lengths (n,)``."""
    o = np.zeros(len(lengths) + 1, dtype=np.int32)
    np.cumsum(lengths, out=o[1:])
    return pa.array(o)


def packed_colors(colors: np.ndarray) -> np.ndarray:
    """``(n, 3)`` uint8 RGB as Rerun's packed ``0xRRGGBBAA`` uint32 (opaque), ``(n,)``."""
    c = np.asarray(colors).reshape(-1, 3).astype(np.uint32)
    return (c[:, 0] << 24) | (c[:, 1] << 16) | (c[:, 2] << 8) | np.uint32(0xFF)


def strip_array(points: np.ndarray, lengths: np.ndarray) -> pa.Array:
    """Line strips as Rerun's Arrow type, built in one go: ``points (P, 2)`` end to end,
    ``lengths (n,)`` points per strip (Rerun's own conversion of a list of strips costs ~5 us
    a strip in Python; a view of 100 peers draws ~30,000 dashed segments a scan)."""
    return list_array(points, lengths, LineStrip2DBatch._ARROW_DATATYPE, np.float32)


def list_array(points: np.ndarray, lengths, dt: pa.DataType, dtype) -> pa.Array:
    """Rows of fixed-size points as an Arrow list array of type ``dt`` (a list of fixed-size
    lists of ``dtype``): ``points (P, m)`` end to end, ``lengths (n,)`` points per row (or
    their offsets, :func:`offsets_of`)."""
    flat = pa.array(np.ascontiguousarray(points, dtype).reshape(-1), pa.from_numpy_dtype(dtype))
    offsets = lengths if isinstance(lengths, pa.Array) else offsets_of(lengths)
    return pa.ListArray.from_arrays(offsets,
                                    pa.FixedSizeListArray.from_arrays(flat, type=dt.value_type),
                                    type=dt)
