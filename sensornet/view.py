"""The live view: a process of its own that subscribes to a network and builds its Rerun
recording from what is on the wire (issue 38; ``sensornet view NETWORK --connect EP``).

Peers log nothing to Rerun: like RViz or Foxglove on ROS 2 topics, the view only subscribes
(scans and scan bundles, estimates, tracks, truth, control and each peer's per-scan
:class:`protocol.messages.Telemetry`), so a network never pays for who watches it, and a view
that falls behind drops or decimates its own work (counted, and said in one line), never the
peers'. Logging is batched (:class:`Batcher`): each entity's rows of a flush period go to Rerun
in one ``send_columns`` call (a Python ``rr.log`` costs ~60 us a row; ``send_columns`` ~150 us
a call plus ~1 us a row), so one process can show 100 peers at 10 scans/s.

The picture is the one the peers and the world drew themselves before: the blueprint, legend
and series styles of :mod:`peers.rerun_layout`, per-peer colours, local dashed and fused solid,
truth in gold, the health tabs (now with ``metrics/compute_ms/*`` and
``metrics/cardinality/*/local`` filled).
"""

from __future__ import annotations

import hashlib
import os
import queue
import sys
import threading
import time
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import msgpack
import numpy as np
import pyarrow as pa
from rerun.components import LineStrip2DBatch

from sensornet.peers.observer import unpack_marginals
from sensornet.peers.recording import read as read_recording
from sensornet.peers.rerun_layout import cell_marks
from sensornet.peers.rerun_sink import (
    TRUTH_COLOR,
    TrackLabels,
    TruthPaths,
    color_of,
    dashed,
    ellipses,
    lighter,
    north_up,
    position_columns,
)
from sensornet.peers.session import open_session
from sensornet.protocol.bundle import unpack_bundle
from sensornet.protocol.codec import Rejected, decode
from sensornet.protocol.envelope import inner, is_sealed
from sensornet.protocol.keys import ROOT, Keys
from sensornet.protocol.messages import (
    Control,
    Estimate,
    Forward,
    Returns,
    Scan,
    Telemetry,
    Tracks,
    Truth,
)
from sensornet.tracking.mixture import GaussianMixture

FLUSH_S = 1.0
"""Seconds of rows gathered per entity before one ``send_columns`` (doubled, up to
:data:`FLUSH_MAX_S`, while a flush takes more than :data:`FLUSH_SHARE` of its period)."""
FLUSH_MAX_S = 8.0
FLUSH_SHARE = 0.25
MAP_KEEP = 12
"""Newest scans of one map entity kept per flush while the view is behind (more than
:data:`BEHIND` / 4 messages waiting): older ones are decimated (counted)."""
QUEUE_MAX = 20_000
"""Messages waiting for the view; more are dropped on arrival (counted)."""
BEHIND = 2_000
"""Waiting messages above which estimates (the heaviest to draw) are skipped unread."""
TAIL = 20
"""Scans of each peer's fused tracks kept as its trail."""


def later_round(payload: bytes) -> bool:
    """Whether an estimate-channel message (``E``, ``F``, ``R``: ``[v, type, sender, k,
    round, ...]``) is of a consensus round after 0, read from its head without decoding the
    rest (a malformed one: False, the decoder says why)."""
    try:
        u = msgpack.Unpacker(max_buffer_size=len(payload) + 1)
        u.feed(payload)
        if u.read_array_header() < 5:
            return False
        _, _, _, _, rnd = u.unpack(), u.unpack(), u.unpack(), u.unpack(), u.unpack()
    except Exception:  # msgpack raises several types on bad input
        return False
    return type(rnd) is int and rnd > 0


def id_color(ids: np.ndarray) -> np.ndarray:
    """One colour per track id ``(n, 3)`` -> ``(n, 3) uint8``, the same at every peer and in
    every run: bytes of a BLAKE2 hash of the id (bright enough to see on the dark map)."""
    ids = np.asarray(ids, dtype=np.int64).reshape(-1, 3)
    out = np.empty((len(ids), 3), dtype=np.uint8)
    for i, row in enumerate(ids):
        h = hashlib.blake2b(row.tobytes(), digest_size=3).digest()
        out[i] = [64 + b * 191 // 255 for b in h]
    return out


def id_labels(ids: np.ndarray) -> list[str]:
    """``origin.birth.index`` of each id ``(n, 3)``: one label per target, at every peer."""
    return [f"{a}.{b}.{c}" for a, b, c in np.asarray(ids).reshape(-1, 3).tolist()]


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
            if keep is not None and r.kind in ("points", "strips") and len(ks) > keep:
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
    dt = LineStrip2DBatch._ARROW_DATATYPE
    flat = pa.array(np.ascontiguousarray(points, np.float32).reshape(-1), pa.float32())
    offsets = np.zeros(len(lengths) + 1, dtype=np.int32)
    np.cumsum(lengths, out=offsets[1:])
    return pa.ListArray.from_arrays(pa.array(offsets),
                                    pa.FixedSizeListArray.from_arrays(flat, type=dt.value_type),
                                    type=dt)


class ViewState:
    """What the network's messages look like on the map and the plots: turns each decoded
    message into rows of a :class:`Batcher` (no I/O of its own; tests feed it messages).

    ``peers``: the scenario's sensor names in order (their colours); names first heard later
    get the next colours. ``scan_period``: seconds per scan (the "sim" timeline).
    ``sensors``: ``name -> (kind, position)`` to draw range-bearing scans where they point.
    ``on_new_peer``: called with a peer's name and colour index the first time it is heard.
    """

    def __init__(self, batcher: Batcher, peers: Sequence[str] = (), scan_period: float = 1.0,
                 sensors: dict | None = None, single_target: bool = False,
                 ospa_cutoff: float | None = None,
                 on_new_peer: Callable[[str, int], None] | None = None,
                 label_gate: float = 100.0) -> None:
        self.b = batcher
        self.index = {p: i for i, p in enumerate(peers)}
        self.scan_period = scan_period
        self.sensors = sensors or {}
        self.single_target = single_target
        self.ospa_cutoff = ospa_cutoff
        self.on_new_peer = on_new_peer
        self.label_gate = label_gate
        self.labels: dict[str, TrackLabels] = {}
        self.tails: dict[str, deque] = {}
        self.truth_paths = TruthPaths()
        self.handled = 0
        self.rejected = 0
        self.skipped = 0
        """Estimates of later consensus rounds, left undecoded (not drawn)."""
        self.lag_ms: deque = deque(maxlen=100_000)
        """How far behind the view runs: wall time from a peer publishing its tracks to the
        view handling them (ms; same clock on one machine)."""
        self.ended = False
        self.newest_k = 0

    def color(self, name: str) -> tuple[int, int, int]:
        i = self.index.get(name)
        if i is None:
            i = self.index[name] = len(self.index)
            if self.on_new_peer is not None:
                self.on_new_peer(name, i)
        return color_of(i)

    def _t(self, k: int) -> float:
        self.newest_k = max(self.newest_k, k)
        return k * self.scan_period

    # -- one message ----------------------------------------------------------------------
    def receive(self, key: str, payload: bytes) -> None:
        """Decode and draw one message heard on ``key`` (a bad one is counted, never raised)."""
        body = inner(payload) if is_sealed(payload) else payload
        if "/estimate/" in key and later_round(body):  # only a peer's own (round 0) is drawn
            self.skipped += 1
            return
        try:
            if f"/{ROOT_SCANS}/" in key:
                for sensor, entry in unpack_bundle(body).entries:
                    self.receive(f"{key.rsplit('/', 2)[0]}/scan/{sensor}", entry)
                return
            msg = decode(body)
        except Rejected:
            self.rejected += 1
            return
        self.handled += 1
        self.message(msg)

    def message(self, msg) -> None:
        if isinstance(msg, Tracks):
            self.tracks(msg)
        elif isinstance(msg, Telemetry):
            self.telemetry(msg)
        elif isinstance(msg, Estimate):
            if msg.round == 0 and msg.kind == "posterior":  # the peer's own local estimate
                self.mixture(f"peers/{msg.sender}", "local", msg.k, msg.mixture,
                             self.color(msg.sender))
        elif isinstance(msg, Forward | Returns):
            if msg.round == 0:  # flooding / measurement sharing: the own scan's points
                if isinstance(msg, Returns):
                    z = msg.z
                else:
                    z = msg.scans.scans.get(msg.sender, np.zeros((0, 2)))
                self.b.points(f"peers/{msg.sender}/local", msg.k, self._t(msg.k), z,
                              lighter(self.color(msg.sender)), 2.0)
        elif isinstance(msg, Scan):
            self.scan(msg)
        elif isinstance(msg, Truth):
            self.truth(msg)
        elif isinstance(msg, Control) and msg.command == "end":
            self.ended = True

    def scan(self, msg: Scan) -> None:
        z = np.asarray(msg.z, float).reshape(-1, 2)
        kind, pos = self.sensors.get(msg.sensor, ("", None))
        if kind == "range-bearing" and len(z) and pos is not None:  # shown where they point
            z = np.asarray(pos) + z[:, :1] * np.column_stack([np.cos(z[:, 1]), np.sin(z[:, 1])])
        self.b.points(f"world/scans/{msg.sensor}", msg.k, self._t(msg.k), z,
                      self.color(msg.sensor), 2.0)

    def truth(self, msg: Truth) -> None:
        k, t = msg.k, self._t(msg.k)
        X = np.asarray(msg.states, float)
        xy = X[:, position_columns(X.shape[1])] if len(X) else np.zeros((0, 2))
        self.b.points("world/truth", k, t, xy, TRUTH_COLOR, 6.0,
                      labels=[str(i) for i in np.asarray(msg.ids).tolist()])
        self.truth_paths.add(msg.ids, xy)
        self.b.strips("world/truth/paths", k, t, self.truth_paths.strips(), TRUTH_COLOR, 1.5)
        self.b.scalar("metrics/cardinality/truth", k, t, len(X))
        if self.ospa_cutoff is not None:
            self.b.scalar("metrics/ospa/cutoff", k, t, self.ospa_cutoff)
        if self.single_target and len(xy):
            self.b.translation("follow", k, t, xy[0])

    def tracks(self, msg: Tracks) -> None:
        if msg.send_time:
            self.lag_ms.append(1e3 * (time.time() - msg.send_time))
        n, k, t = msg.sender, msg.k, self._t(msg.k)
        color = self.color(n)
        X = np.asarray(msg.states, float)
        xy = X[:, position_columns(X.shape[1])] if len(X) else np.zeros((0, 2))
        if msg.ids is not None:  # labelled tracks: one colour and label per id, everywhere
            colors, labels = id_color(msg.ids), id_labels(msg.ids)
        else:  # display numbers by association (for the eye, not scored)
            gate = self.labels.setdefault(n, TrackLabels(self.label_gate))
            colors, labels = color, [f"{n}/{i}" for i in gate.assign(xy)]
        self.b.points(f"peers/{n}/tracks", k, t, xy, colors, 5.0, labels=labels)
        tail = self.tails.setdefault(n, deque(maxlen=TAIL))
        tail.append(xy)
        self.b.points(f"peers/{n}/tail", k, t, np.concatenate(list(tail)), color, 1.5)
        self.b.scalar(f"metrics/cardinality/{n}/fused", k, t, len(X))
        if msg.covs is not None and len(X):  # the tracks' own 2-sigma ellipses
            self.b.strips(f"peers/{n}/tracks/ellipses", k, t,
                          ellipses(X, np.asarray(msg.covs, float)), color, 1.0)

    def telemetry(self, msg: Telemetry) -> None:
        n, k, t = msg.sender, msg.k, self._t(msg.k)
        color = self.color(n)
        for name, value in msg.values.items():
            head, _, rest = name.partition("/")
            self.b.scalar(f"metrics/{head}/{n}/{rest}" if rest else f"metrics/{head}/{n}",
                          k, t, value)
        for line in msg.events:
            level, text = ("WARN", line[5:]) if line.startswith("WARN ") else ("INFO", line)
            self.b.text(f"peers/{n}/events", k, t, text, level)
        for name, z in msg.points.items():
            if name == "cells":  # coloured by cell, with the extents of the larger cells
                labels = msg.points.get("cells/labels", np.zeros((len(z), 2)))[:, 0]
                colors, extents, ecolors = cell_marks(z, labels.astype(np.int64))
                self.b.points(f"peers/{n}/cells/points", k, t, z, colors, 2.5)
                self.b.strips(f"peers/{n}/cells/extents", k, t, extents,
                              np.asarray(ecolors, np.uint8).reshape(-1, 3), 1.5)
            elif name == "local/mixture":  # the peer's local estimate (position marginals)
                self.mixture(f"peers/{n}", "local", k, unpack_marginals(z), color)
            elif name != "cells/labels":
                self.b.points(f"peers/{n}/{name}", k, t, z, color,
                              2.0 if name == "local" else 1.0)
        if msg.mixture is not None:
            self.mixture(f"peers/{n}", "fused", k, msg.mixture, color)

    def mixture(self, base: str, which: str, k: int, mix: GaussianMixture, color) -> None:
        """Component means (radius by weight) and 2-sigma ellipses: local dashed and lighter,
        fused solid."""
        t = self._t(k)
        local = which == "local"
        shown = lighter(color) if local else color
        xy = mix.means[:, position_columns(mix.dim)] if len(mix) else np.zeros((0, 2))
        self.b._add(f"{base}/{which}/means", "points", k, t,
                    (north_up(xy), np.broadcast_to(np.asarray(shown, np.uint8), (len(xy), 3)),
                     -2.0, None))
        strips = ellipses(mix.means, mix.covs)
        if local:
            self.b.strips(f"{base}/{which}/ellipses", k, t, dashed(strips), shown, 1.0)
        else:
            self.b.strips(f"{base}/{which}/ellipses", k, t, strips, shown, 1.5)


ROOT_SCANS = "scans"
"""The key chunk of a host's scan bundles (protocol.keys.Keys.scans)."""


class LiveView:
    """The view process: a Zenoh subscription on ``sensornet/<network>/**`` feeding a bounded
    queue (full: dropped, counted), drained by :meth:`run` into a :class:`ViewState`, flushed
    to Rerun every :data:`FLUSH_S` seconds."""

    def __init__(self, network: str, state_factory, rr, rec, connect: Sequence[str] = (),
                 config: str | None = None, say: Callable[[str], None] | None = None,
                 estimates: bool = False) -> None:
        """``estimates``: hear the peers' estimates too (the local marks of peers that send
        no telemetry); by default not: the local estimate rides in each peer's telemetry,
        and every peer would send the view a copy of each of its heaviest messages (+5 %
        of the peers' CPU at seed 004)."""
        self.network = network
        self.estimates = estimates
        self.connect, self.config = list(connect), config
        self.rr, self.rec = rr, rec
        self.batcher = Batcher(rr, rec)
        self.state: ViewState = state_factory(self.batcher)
        self.q: queue.Queue = queue.Queue(maxsize=QUEUE_MAX)
        self.dropped = 0
        self.skipped = 0
        self.flush_s = FLUSH_S
        self.say = say or (lambda s: print(s, file=sys.stderr, flush=True))
        self.stop = threading.Event()
        self._said = (0, 0, 0)
        self._said_at = 0.0
        self.session = None

    def open(self) -> None:
        self.session = open_session((), self.connect, self.config)
        k = Keys(self.network)
        exprs = ([f"{ROOT}/{self.network}/**"] if self.estimates else
                 [k.scan(), k.scans(), k.tracks(), k.truth(), k.ctl(), k.telemetry()])
        self._subs = [self.session.declare_subscriber(e, self._on_sample) for e in exprs]

    def _on_sample(self, sample) -> None:
        try:
            self.q.put_nowait((str(sample.key_expr), sample.payload.to_bytes()))
        except queue.Full:
            self.dropped += 1

    def close(self) -> None:
        for sub in getattr(self, "_subs", []):
            try:
                sub.undeclare()
            except Exception:  # the session is gone already
                pass
        if self.session is not None:
            self.session.close()
            self.session = None

    def drain(self, budget: float) -> int:
        """Handle what waits, for at most ``budget`` seconds; estimates skipped unread while
        more than :data:`BEHIND` messages wait (counted)."""
        end = time.monotonic() + budget
        n = 0
        while time.monotonic() < end:
            try:
                key, payload = self.q.get(timeout=max(0.0, min(0.05, end - time.monotonic())))
            except queue.Empty:
                break
            if "/estimate/" in key and self.q.qsize() > BEHIND:
                self.skipped += 1
                continue
            self.state.receive(key, payload)
            n += 1
        return n

    def flush(self) -> None:
        t0 = time.monotonic()
        self.batcher.map_keep = MAP_KEEP if self.q.qsize() > BEHIND // 4 else None
        self.batcher.flush()
        took = time.monotonic() - t0
        if took > FLUSH_SHARE * self.flush_s and self.flush_s < FLUSH_MAX_S:
            self.flush_s = min(FLUSH_MAX_S, 2 * self.flush_s)
        self.note()

    def note(self, final: bool = False) -> None:
        """One line when the view fell behind (at most every 5 s): what it left out."""
        now = (self.dropped, self.skipped, self.batcher.decimated)
        if now != self._said and (final or time.monotonic() - self._said_at > 5.0):
            self.say(f"view: behind the network: {now[0]} messages dropped on arrival, "
                     f"{now[1]} estimates skipped, {now[2]} map frames decimated (the view's "
                     f"own work; the peers are not affected); flushing every {self.flush_s:g} s")
            self._said, self._said_at = now, time.monotonic()

    def run(self, duration: float | None = None, until_end: bool = False,
            grace: float = 3.0) -> None:
        """Until :attr:`stop`, ``duration`` seconds, or (``until_end``) ``grace`` seconds
        after the world's end message; flushes at the end."""
        t0 = time.monotonic()
        next_flush = t0 + self.flush_s
        ended_at = None
        while not self.stop.is_set():
            now = time.monotonic()
            if duration is not None and now - t0 >= duration:
                break
            if until_end and self.state.ended:
                ended_at = ended_at or now
                if now - ended_at >= grace:
                    break
            self.drain(min(0.2, max(0.0, next_flush - now)))
            if time.monotonic() >= next_flush:
                self.flush()
                next_flush = time.monotonic() + self.flush_s
        self.drain(0.5)
        self.batcher.flush()
        self.note(final=True)


def replay_recordings(state: ViewState, paths: Sequence[Path]) -> int:
    """Rebuild the picture offline from peers' MCAP recordings (``sensornet run --record``:
    what each peer received, and its own tracks), merged in time order; a message heard by
    several peers (a scan, the truth) is drawn once. No telemetry is recorded, so the health
    series stay empty. Returns the messages drawn."""
    merged = []
    for path in paths:
        meta, records = read_recording(Path(path))
        peer, network = meta.get("peer", "?"), meta.get("network", "net")
        for topic, r in records:
            if topic == "receive":
                merged.append((r[0], r[1], r[2]))
            elif topic == "tracks":
                merged.append((r[0], f"{ROOT}/{network}/tracks/{peer}", r[2]))
    merged.sort(key=lambda m: m[0])
    seen: set[bytes] = set()
    drawn = 0
    for _, key, payload in merged:
        digest = hashlib.blake2b(payload, digest_size=16).digest()
        if digest in seen:
            continue
        seen.add(digest)
        state.receive(key, payload)
        drawn += 1
    return drawn


def cpu_seconds() -> float:
    """This process's CPU (user + system) so far."""
    t = os.times()
    return t.user + t.system
