"""The live view's batched Rerun writer (issue 38): rows gathered per entity and sent in one
``send_columns`` call each per flush (a Python ``rr.log`` costs ~60 us a row; ``send_columns``
~150 us a call plus ~1 us a row), so one process can show 100 peers at 10 scans/s. Map
entities may be decimated to their newest rows when the view is behind (counted).

Knows nothing of messages: :mod:`sensornet.view_state` turns those into rows.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pyarrow as pa
from rerun.components import LineStrip2DBatch

from sensornet.peers.rerun_sink import north_up


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
        if value is not None and np.isfinite(value):
            self._add(path, "scalar", k, t, float(value))

    def points(self, path: str, k: int, t: float, xy, colors, radius: float,
               labels: list[str] | None = None) -> None:
        """Points (map coordinates ``(n, 2)``); ``colors`` one ``(3,)`` or ``(n, 3)``."""
        xy = north_up(np.asarray(xy, float).reshape(-1, 2))
        c = np.broadcast_to(np.asarray(colors, np.uint8).reshape(-1, 3), (len(xy), 3))
        self._add(path, "points", k, t, (xy, c, -abs(radius), labels))

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
        c = np.broadcast_to(np.asarray(color, np.uint8).reshape(-1, 3), (len(lengths), 3))
        self._add(path, "strips", k, t, (north_up(flat), lengths, c, -abs(radius)))

    def text(self, path: str, k: int, t: float, message: str, level: str = "INFO") -> None:
        self._add(path, "text", k, t, (message, level))

    def translation(self, path: str, k: int, t: float, xy) -> None:
        x, y = north_up(np.asarray(xy, float).reshape(2))
        self._add(path, "transform", k, t, (x, y, 0.0))

    def pending(self) -> int:
        return sum(len(r.ks) for r in self._rows.values())

    def flush(self) -> None:
        """Every entity's rows in one call each (map entities: the newest :attr:`map_keep`)."""
        rows, self._rows = self._rows, {}
        for path, r in rows.items():
            ks, ts, data = r.ks, r.ts, r.rows
            keep = self.map_keep
            if (keep is not None and (r.kind in ("points", "strips") or r.kind in self.builders)
                    and len(ks) > keep):
                self.decimated += len(ks) - keep
                ks, ts, data = ks[-keep:], ts[-keep:], data[-keep:]
            self._send(path, r.kind, ks, ts, data)

    def _send(self, path: str, kind: str, ks: list, ts: list, data: list) -> None:
        rr = self.rr
        index = [rr.TimeColumn("scan", sequence=np.asarray(ks, np.int64)),  # arrays: a list
                 rr.TimeColumn("sim", duration=np.asarray(ts, float))]  # costs 5x as much
        if kind == "scalar":
            cols = rr.Scalars.columns(scalars=np.asarray(data, float))
        elif kind == "points":
            lengths = [len(d[0]) for d in data]
            xy = np.concatenate([d[0] for d in data]) if data else np.zeros((0, 2))
            colors = np.concatenate([d[1] for d in data]) if data else np.zeros((0, 3))
            radii = np.repeat([d[2] for d in data], lengths)
            cols = [*rr.Points2D.columns(positions=xy, colors=colors, radii=radii).partition(
                lengths)]
            if any(d[3] is not None for d in data):  # labels always shown
                labels = [s for d in data for s in (d[3] or [""] * len(d[0]))]
                cols += [*rr.Points2D.columns(labels=labels).partition(lengths),
                         *rr.Points2D.columns(show_labels=[True] * len(data))]
        elif kind == "strips":
            lengths = [len(d[1]) for d in data]
            colors = np.concatenate([d[2] for d in data])
            radii = np.repeat([d[3] for d in data], lengths)
            cols = [*rr.LineStrips2D.columns(
                strips=strip_array(np.concatenate([d[0] for d in data]),
                                   np.concatenate([d[1] for d in data])),
                colors=colors, radii=radii).partition(lengths)]
        elif kind in self.builders:
            cols = self.builders[kind](rr, data)
        elif kind == "text":
            cols = rr.TextLog.columns(text=[d[0] for d in data], level=[d[1] for d in data])
        else:  # transform
            cols = rr.Transform3D.columns(translation=np.asarray(data, float))
        self.rec.send_columns(path, indexes=index, columns=cols)
        self.calls += 1
        self.rows_sent += len(ks)


def strip_array(points: np.ndarray, lengths: np.ndarray) -> pa.Array:
    """Line strips as Rerun's Arrow type, built in one go: ``points (P, 2)`` end to end,
    ``lengths (n,)`` points per strip (Rerun's own conversion of a list of strips costs ~5 us
    a strip in Python; a view of 100 peers draws ~30,000 dashed segments a scan)."""
    return list_array(points, lengths, LineStrip2DBatch._ARROW_DATATYPE, np.float32)


def list_array(points: np.ndarray, lengths: np.ndarray, dt: pa.DataType, dtype) -> pa.Array:
    """Rows of fixed-size points as an Arrow list array of type ``dt`` (a list of fixed-size
    lists of ``dtype``): ``points (P, m)`` end to end, ``lengths (n,)`` points per row."""
    flat = pa.array(np.ascontiguousarray(points, dtype).reshape(-1), pa.from_numpy_dtype(dtype))
    offsets = np.zeros(len(lengths) + 1, dtype=np.int32)
    np.cumsum(lengths, out=offsets[1:])
    return pa.ListArray.from_arrays(pa.array(offsets),
                                    pa.FixedSizeListArray.from_arrays(flat, type=dt.value_type),
                                    type=dt)
