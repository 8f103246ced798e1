"""What the network's messages look like on the live view's map and plots (issue 38):
:class:`ViewState` turns each decoded message (scans and bundles, tracks, truth, estimates,
each peer's :class:`protocol.messages.Telemetry`) into rows of a
:class:`sensornet.view_columns.Batcher`. No I/O of its own: the view process
(:mod:`sensornet.view`) feeds it what it hears, tests feed it messages.

The picture is the one the peers and the world drew themselves before: per-peer colours,
local dashed and fused solid, truth in gold, the health tabs, and a PDA peer's validation
gates with its returns coloured by weight.
"""

from __future__ import annotations

import hashlib
import time
from collections import deque
from collections.abc import Callable, Sequence

import msgpack
import numpy as np

from sensornet.peers.observer import unpack_gate
from sensornet.peers.rerun_layout import cell_marks
from sensornet.peers.rerun_sink import (
    TRUTH_COLOR,
    TrackLabels,
    TruthPaths,
    color_of,
    ellipses,
    lighter,
    position_columns,
)
from sensornet.protocol.bundle import BUNDLE_HEAD, unpack_bundle
from sensornet.protocol.codec import DEFAULT_LIMITS, TRACKS_VERSION, Limits, Rejected, decode
from sensornet.protocol.codec_format import (
    _I8,
    _floats,
    _index,
    _name,
    _positive_definite,
    _time,
    _tri_to_full,
    read_header,
)
from sensornet.protocol.envelope import inner, is_sealed
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
from sensornet.protocol.report_bundle import REPORTS_HEAD, unpack_reports_together
from sensornet.tracking.mixture import GaussianMixture
from sensornet.view_columns import Batcher
from sensornet.view_scans import scans_together

TAIL = 20
"""Scans of each peer's fused tracks kept as its trail."""
ROOT_SCANS = "scans"
"""The key chunk of a host's scan bundles (protocol.keys.Keys.scans)."""
ROOT_TELEMETRIES = "telemetries"
"""The key chunk of a host's telemetry bundles (protocol.keys.Keys.telemetries)."""


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


def tracks_together(payloads: Sequence[bytes],
                    limits: Limits = DEFAULT_LIMITS) -> list[Tracks] | None:
    """Protocol-2 tracks messages of one state dimension and the same optional fields (a
    host's reports carry one per peer a scan) decoded together: each header read alone, then
    each block (states, covariances, ids, existence, status) checked and decoded in one NumPy
    call for all, with the checks of :func:`protocol.codec_messages._tracks_v2` (the
    view's decoding at 50 peers was ~45 us a tracks message, most of it per-call NumPy).
    None when any payload is not such a message or any check fails: the caller then decodes
    each alone, which refuses exactly the bad ones and says why."""
    heads, shape = [], None
    try:
        for p in payloads:
            version, kind, body = read_header(p, limits)
            if kind != "K" or version != TRACKS_VERSION:
                return None
            d, x = body["d"], body["x"]
            if type(d) is not int or not 0 < d <= limits.max_dim or type(x) is not bytes:
                return None
            n, rest = divmod(len(x), 8 * d)
            if rest or n > limits.max_components:
                return None
            here = (d, *(body[f] is None for f in "iceu"))
            if shape is None:
                shape = here
            elif here != shape:
                return None
            heads.append((n, body, _name(body, "s", limits), _index(body, "k"),
                          _index(body, "q"), _time(body)))
        if not heads:
            return []
        d, t = shape[0], shape[0] * (shape[0] + 1) // 2
        counts = np.fromiter((h[0] for h in heads), np.int64, len(heads))
        total = int(counts.sum())
        blocks = {}
        for f, width, absent in zip("iceu", (24, 8 * t, 8, 1), shape[1:], strict=True):
            if not absent:
                if not all(type(h[1][f]) is bytes and len(h[1][f]) == width * h[0]
                           for h in heads):
                    return None
                blocks[f] = b"".join(h[1][f] for h in heads)
        states = _floats(b"".join(h[1]["x"] for h in heads), (total, d))
        ids = covs = existence = status = None
        if "i" in blocks:
            ids = np.frombuffer(blocks["i"], dtype=_I8).reshape(total, 3).astype(np.int64)
            if total and ids.min() < 0:
                return None
        if "c" in blocks:
            covs = _floats(blocks["c"], (total, t)).take(_tri_to_full(d), axis=1).reshape(
                total, d, d)
            if total and not _positive_definite(covs):
                return None
        if "e" in blocks:
            existence = _floats(blocks["e"], (total,))
            if total and (existence.min() < 0.0 or existence.max() > 1.0):
                return None
        if "u" in blocks:
            status = np.frombuffer(blocks["u"], dtype=np.int8).copy()
            if total and not ((status == Tracks.TENTATIVE) | (status == Tracks.CONFIRMED)).all():
                return None
    except (Rejected, ValueError, TypeError, OverflowError, KeyError):
        return None
    out, a = [], 0
    for n, _, sender, k, seq, ts in heads:
        b = a + n
        out.append(Tracks(sender=sender, k=k, states=states[a:b], seq=seq, send_time=ts,
                          ids=None if ids is None else ids[a:b],
                          covs=None if covs is None else covs[a:b],
                          existence=None if existence is None else existence[a:b],
                          status=None if status is None else status[a:b]))
        a = b
    return out


ID_MARKS_KEEP = 50_000
"""Track ids whose colour and label :class:`IdMarks` keeps (then it starts afresh)."""
PATHS_KEEP = 4_096
"""Tuples of a report's value names whose entities :class:`ViewState` keeps (then it starts
afresh): a report leaves out values that are not finite, so the tuples a peer sends vary."""


class IdMarks:
    """:func:`id_color` and :func:`id_labels` of track ids, each id's made once: at 50 peers
    every peer reports the same targets' ids every scan (~500 a second), each a BLAKE2 hash
    and a label string in Python."""

    def __init__(self) -> None:
        self._marks: dict[tuple[int, int, int], tuple[np.ndarray, str]] = {}

    def __call__(self, ids: np.ndarray) -> tuple[np.ndarray, list[str]]:
        """``(colours (n, 3) uint8, labels)`` of ``ids (n, 3)``, as the two functions give."""
        rows = [tuple(r) for r in np.asarray(ids, dtype=np.int64).reshape(-1, 3).tolist()]
        marks = self._marks
        new = [r for r in dict.fromkeys(rows) if r not in marks]
        if new:
            if len(marks) + len(new) > ID_MARKS_KEEP:  # afresh: this call's ids all made anew
                marks.clear()
                new = list(dict.fromkeys(rows))
            arr = np.array(new, dtype=np.int64).reshape(-1, 3)
            marks.update(zip(new, zip(id_color(arr), id_labels(arr), strict=True), strict=True))
        got = [marks[r] for r in rows]
        colors = np.array([c for c, _ in got], np.uint8).reshape(-1, 3)
        return colors, [label for _, label in got]


def marginal_marks(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A report's packed position marginals (:func:`peers.observer.pack_marginals`) as what
    the map draws of them: means ``(n, 2)``, and 4-D means and covariances whose position
    entries are the marginals' (all :func:`peers.rerun_layout.ellipses` reads; the rest 0),
    without the :class:`GaussianMixture` :func:`peers.observer.unpack_marginals` makes."""
    r = np.asarray(points, float).reshape(-1, 6)  # [x, y, a, b, d, -] a marginal
    n = len(r)
    ext = np.zeros((n, 7))  # its entries, then a 0 that the other entries take
    ext[:, :6] = r
    return (r[:, :2].reshape(n, 2), ext.take(_MEANS_OF, axis=1),
            ext.take(_COVS_OF, axis=1).reshape(n, 4, 4))


MARGINALS = ("local/mixture", "fused/mixture")
"""A report's point sets that are packed position marginals (:func:`marginal_marks`)."""


def marginal_marks_many(reports: Sequence[Telemetry]) -> list[dict]:
    """Per report, :func:`marginal_marks` of each of its :data:`MARGINALS` sets by name, made
    in one call for all the reports (a host's reports: ~100 sets a scan at 50 peers, each
    ~7 NumPy calls alone); the same values as each set's own. A set not of whole marginals
    (3 points each) is left out: :meth:`ViewState.marginals` counts it."""
    sets = [(i, name, z) for i, r in enumerate(reports) for name, z in r.points.items()
            if name in MARGINALS and not len(z) % 3]
    out: list[dict] = [{} for _ in reports]
    if not sets:
        return out
    xy, means, covs = marginal_marks(np.concatenate([z for _, _, z in sets]))
    a = 0
    for i, name, z in sets:
        b = a + len(z) // 3
        out[i][name] = xy[a:b], means[a:b], covs[a:b]
        a = b
    return out


_MEANS_OF = np.array([0, 6, 1, 6])
"""Columns of a marginal's entries (and a trailing 0) that make its 4-D mean ..."""
_COVS_OF = np.array([2, 6, 3, 6, 6, 6, 6, 6, 3, 6, 4, 6, 6, 6, 6, 6])
"""... and its 4x4 covariance (position entries (0, 0), (0, 2), (2, 0), (2, 2))."""


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
        self.tails: dict[str, tuple[np.ndarray, deque]] = {}
        """Per peer: its trail's points end to end and each scan's count (the newest
        :data:`TAIL` scans): a scan's trail is one concatenation of two arrays, not of 20."""
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
        self.first_report: dict[str, int] = {}
        """Per peer, in the order heard, the scan of its first report drawn (the view says
        whose came once they are in the recording: :meth:`LiveView.flush`)."""
        self._series: dict[str, dict[str, str]] = {}
        """Per peer: report value name -> its entity (made once, not per row)."""
        self._paths: dict[tuple, tuple[str, ...]] = {}
        """Per peer and tuple of report value names: their entities (a peer's reports name
        mostly the same values scan after scan; at most :data:`PATHS_KEEP` tuples kept)."""
        self._lighter: dict[tuple, tuple[int, int, int]] = {}
        self.id_marks = IdMarks()

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
        """Decode and draw one message heard on ``key`` (a bad one is counted, never raised):
        a bundle's entries each as if heard on its own key (a host's scans or reports; a peer
        of its own process sends its tracks and report as one bundle on its report key)."""
        body = inner(payload) if is_sealed(payload) else payload
        base = key.rsplit("/", 2)[0]
        if f"/{ROOT_SCANS}/" in key:
            channel, own = "scan", None
        elif f"/{ROOT_TELEMETRIES}/" in key:  # a host's peers' reports (HostReports)
            if body[:1] == REPORTS_HEAD:  # split (protocol.report_bundle); else a bundle
                self._host_reports(base, body)
                return
            channel, own = "telemetry", None
        elif "/telemetry/" in key and body[:1] == BUNDLE_HEAD:  # one peer's reports
            channel, own = "telemetry", key.rsplit("/", 1)[-1]
        else:
            self._one(key, body)
            return
        try:
            entries = unpack_bundle(body).entries
        except Rejected:
            self.rejected += 1
            return
        if channel == "scan" and len(entries) > 1 and self._scans(base, entries):
            return
        for name, entry in entries:
            if own is not None and name != own:  # a peer's key carries its own reports only
                self.rejected += 1
            else:
                self._one(f"{base}/{channel}/{name}", entry)

    def _scans(self, base: str, entries: list[tuple[str, bytes]]) -> bool:
        """A scan bundle's entries decoded together and drawn as each alone would be
        (:func:`sensornet.view_scans.scans_together`); False (nothing done) when any is not
        a good scan or its key would be read otherwise: the caller then takes each alone."""
        where = f"{base}/scan/"
        if "/estimate/" in where or "/telemetry/" in where:  # _one reads such keys apart
            return False
        scans = scans_together([inner(e) if is_sealed(e) else e for _, e in entries])
        if scans is None:
            return False
        self.handled += len(scans)
        for msg in scans:
            self.scan(msg)
        return True

    def _host_reports(self, base: str, body: bytes) -> None:
        """A host's reports message: its entries each as if heard on the peer's report key,
        its reports drawn as if each had come alone; a refused whole or report counted (the
        reports' checks made together: :func:`protocol.report_bundle.unpack_reports_together`)."""
        try:
            msg = unpack_reports_together(body)
        except Rejected:
            self.rejected += 1
            return
        bodies = [inner(e) if is_sealed(e) else e for _, e in msg.entries]
        together = tracks_together(bodies) if len(bodies) > 1 else None
        if together is None:  # not all tracks alike, or one refused: each alone
            for name, entry in msg.entries:
                self._one(f"{base}/telemetry/{name}", entry)
        for (name, _), tracks in zip(msg.entries if together else (), together or (),
                                     strict=True):
            if tracks.sender != name.rsplit("/", 1)[-1]:  # a peer's entry: its own only
                self.rejected += 1
            else:
                self.handled += 1
                self.tracks(tracks)
        kept = [r for r in msg.reports if not isinstance(r, Rejected)]
        self.rejected += len(msg.reports) - len(kept)
        marks = marginal_marks_many(kept)
        for r, m in zip(kept, marks, strict=True):
            self.handled += 1
            self.telemetry(r, m)

    def _one(self, key: str, payload: bytes) -> None:
        """One message (not a bundle: a bundle inside a bundle is refused)."""
        body = inner(payload) if is_sealed(payload) else payload
        if "/estimate/" in key and later_round(body):  # only a peer's own (round 0) is drawn
            self.skipped += 1
            return
        try:
            msg = decode(body)
        except Rejected:
            self.rejected += 1
            return
        if "/telemetry/" in key and getattr(msg, "sender", None) != key.rsplit("/", 1)[-1]:
            self.rejected += 1  # a peer's report key carries its own reports and tracks only
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
            colors, labels = self.id_marks(msg.ids)
        else:  # display numbers by association (for the eye, not scored)
            gate = self.labels.setdefault(n, TrackLabels(self.label_gate))
            colors, labels = color, [f"{n}/{i}" for i in gate.assign(xy)]
        self.b.points(f"peers/{n}/tracks", k, t, xy, colors, 5.0, labels=labels)
        trail, counts = self.tails.get(n) or (np.zeros((0, 2)), deque())
        drop = counts.popleft() if len(counts) == TAIL else 0
        counts.append(len(xy))
        trail = np.concatenate((trail[drop:], xy))  # a new array: rows already kept are not
        self.tails[n] = trail, counts
        self.b.points(f"peers/{n}/tail", k, t, trail, color, 1.5)
        self.b.scalar(f"metrics/cardinality/{n}/fused", k, t, len(X))
        if msg.covs is not None and len(X):  # the tracks' own 2-sigma ellipses
            self.b.ellipses(f"peers/{n}/tracks/ellipses", k, t, X, np.asarray(msg.covs, float),
                            color, 1.0)

    def telemetry(self, msg: Telemetry, marks: dict | None = None) -> None:
        """A peer's report; ``marks``: its position marginals' :func:`marginal_marks` by
        point-set name, made for many reports at once (:func:`marginal_marks_many`)."""
        n, k, t = msg.sender, msg.k, self._t(msg.k)
        if n not in self.first_report:
            self.first_report[n] = k
        color = self.color(n)
        names = tuple(msg.values)
        paths = self._paths.get((n, names))
        if paths is None:
            if len(self._paths) >= PATHS_KEEP:
                self._paths.clear()
            per = self._series.setdefault(n, {})
            paths = self._paths[n, names] = tuple(per.get(name) or self._series_path(per, n, name)
                                                  for name in names)
        self.b.series(k, t, paths, msg.values.values())
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
            elif name in MARGINALS:  # position marginals
                if marks and name in marks:
                    self._marks(f"peers/{n}", name[:-8], k, *marks[name], color)
                else:
                    self.marginals(f"peers/{n}", name[:-8], k, z, color)
            elif name.startswith("pda/"):  # a PDA peer's validation gate of one sensor
                self.gate(f"peers/{n}/{name}", k, z, color)
            elif name != "cells/labels":
                self.b.points(f"peers/{n}/{name}", k, t, z, color,
                              2.0 if name == "local" else 1.0)
        if msg.mixture is not None:  # a sender of before: the fused one as a mixture
            self.mixture(f"peers/{n}", "fused", k, msg.mixture, color)

    @staticmethod
    def _series_path(paths: dict, peer: str, name: str) -> str:
        """The entity of a report value: ``metrics/<head>/<peer>[/<rest>]`` (kept per peer)."""
        head, _, rest = name.partition("/")
        path = paths[name] = f"metrics/{head}/{peer}/{rest}" if rest else f"metrics/{head}/{peer}"
        return path

    def gate(self, base: str, k: int, points: np.ndarray, color) -> None:
        """One sensor's PDA update (:func:`peers.observer.pack_gates`) as the peers drew it
        before issue 38: the gate, the ``gamma`` ellipse about the predicted measurement in
        the peer's colour (``<base>/gate``), and the validated returns coloured by weight,
        blue 0 to red 1 (``<base>/returns``). A malformed one is counted, not drawn."""
        try:
            zhat, S, gamma, returns, weights = unpack_gate(points)
        except ValueError:
            self.rejected += 1
            return
        t = self._t(k)
        mean = np.zeros((1, 4))
        mean[0, [0, 2]] = zhat
        cov = np.zeros((1, 4, 4))
        cov[0][np.ix_([0, 2], [0, 2])] = S
        self.b.strips(f"{base}/gate", k, t, ellipses(mean, cov, sigma=float(np.sqrt(gamma))),
                      color, 1.5)
        w = np.clip(weights, 0.0, 1.0)
        colors = np.column_stack([255 * w, np.full(len(w), 40.0), 255 * (1 - w)])
        self.b.points(f"{base}/returns", k, t, returns, colors.astype(np.uint8), 3.0)

    def mixture(self, base: str, which: str, k: int, mix: GaussianMixture, color) -> None:
        """Component means (radius by weight) and 2-sigma ellipses: local dashed and lighter,
        fused solid."""
        xy = mix.means[:, position_columns(mix.dim)] if len(mix) else np.zeros((0, 2))
        self._marks(base, which, k, xy, mix.means, mix.covs, color)

    def marginals(self, base: str, which: str, k: int, points: np.ndarray, color) -> None:
        """:meth:`mixture` of a report's packed position marginals (the same marks as of
        :func:`peers.observer.unpack_marginals`' mixture, made without it)."""
        if len(points) % 3:  # 3 points a marginal: a malformed one counted, not drawn
            self.rejected += 1
            return
        xy, means, covs = marginal_marks(points)
        self._marks(base, which, k, xy, means, covs, color)

    def _marks(self, base: str, which: str, k: int, xy: np.ndarray, means: np.ndarray,
               covs: np.ndarray, color) -> None:
        t = self._t(k)
        local = which == "local"
        shown = color
        if local:
            shown = self._lighter.get(color)
            if shown is None:
                shown = self._lighter[color] = lighter(color)
        self.b.points(f"{base}/{which}/means", k, t, xy, shown, 2.0)
        self.b.ellipses(f"{base}/{which}/ellipses", k, t, means, covs, shown,
                        1.0 if local else 1.5, dashed=local)
