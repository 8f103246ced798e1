"""What a peer tells live views about itself: one compact :class:`protocol.messages.Telemetry`
message per scan on ``telemetry/<peer>`` (issue 38).

A peer logs nothing to Rerun: the view is a process of its own (``sensornet view``) that
subscribes to the network, so whoever watches pays for the watching. The observer only gathers,
per scan, the numbers the Rerun health tabs show (component counts, ages, late and refused
messages, trust statistics, OSPA, latency, compute) from the core's records and outputs, and
publishes them when the peer is idle (:meth:`Observer.flush`): never in the burst that sets the
scan-to-track latency. The put is best effort (congestion control DROP): a slow view never
holds a peer back. The peers of a host send theirs together (:class:`HostReports`: one message
on ``telemetries/<host>`` a pass of the host's loop, once none of its peers has work
waiting, their map marks made in one call). The view hears nothing a peer publishes for
others: each scan's tracks (the bytes put on ``tracks/<peer>``) go to it with the scan's
report (a host's: in the same message; a
peer of its own process: both in one bundle on ``telemetry/<peer>``, one put a flush, not
one for the tracks and one for the report), so a peer's own puts reach the same sessions
whether or not a view listens. Nobody watching,
nothing is gathered: a Zenoh matching listener tells the observer whether any subscriber
hears its key, and until one does every call returns at once.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable

import numpy as np
from sensornet.peers.core import PeerCore, Publish, Record
from sensornet.peers.rerun_layout import position_columns
from sensornet.protocol.bundle import pack_bundles
from sensornet.protocol.codec import encode
from sensornet.protocol.messages import Telemetry
from sensornet.protocol.report_bundle import pack_reports
from sensornet.tracking.mixture import GaussianMixture

PARTICLES_SHOWN = 200
"""Particles of a particle peer sent per scan (a sample: for the eye)."""
POOLED_SHOWN = 400
"""Pooled scan points (flooding) sent per scan, at most (a sample)."""
FUSED_SHOWN = 64
"""Heaviest fused components sent per scan (the view's solid ellipses)."""
GATES_SHOWN = 8
"""Sensors whose PDA gate a peer sends per scan, at most (a telemetry message carries at most
16 point sets)."""
RETURNS_SHOWN = 64
"""Validated returns of one PDA gate sent per scan, at most: the heaviest (seed 003's dense
clutter validates 200-300 a sensor late in a run: 16.8 kB of telemetry a scan with all)."""
KINDS = frozenset({"local", "fusion", "cost", "ospa", "rejected", "scan", "peer", "trust",
                   "trust-event"})
"""Record kinds the report reads (a peer's many ``estimate`` records pass by at once: the
runtime checks the kind before it calls :meth:`Observer.record`)."""
WAIT_SCANS = 2
"""A scan's report waits for its OSPA (the truth comes half a scan after the scans) at most
until the tracks of this many later scans are out."""
PENDING_MAX = 16
"""Scans' reports a hosted peer may hold before its host sends them though it is busy (a host
that is never idle must not gather reports without end)."""


_OUT_OF_SEQUENCE = tuple(f"out_of_sequence/{w}" for w in ("late", "redundant", "too_old",
                                                             "dropped_late"))


def _undeclare(*declared) -> None:
    """Undeclare each Zenoh publisher / listener given (None: never declared)."""
    for d in declared:
        if d is not None:
            try:
                d.undeclare()
            except Exception:  # the session is gone already
                pass


def _put(values: dict, name: str, value) -> None:
    """``values[name] = value`` for a finite scalar (None and NaN left out)."""
    if value is not None:
        v = float(value)
        if math.isfinite(v):  # a scalar: NumPy's ufunc costs ~1 us a call, 35 a scan
            values[name] = v


class Observer:
    """Gathers one peer's per-scan telemetry and publishes it (no-op until :meth:`open`)."""

    def __init__(self, core: PeerCore, scan_period: float = 1.0, telemetry=None) -> None:
        """``telemetry``: the driver's :class:`peers.telemetry.Telemetry` (its cumulative
        fusion compute gives the per-scan ``compute_ms/fusion``)."""
        self.core = core
        self.name = core.name
        self.scan_period = scan_period
        self.telemetry = telemetry
        self._open = False
        self.watched = False
        """Whether a subscriber (a view) hears ``telemetry/<peer>`` now."""
        self._pub = self._listener = None
        self._put = None
        self._pending: dict[int, dict] = {}
        self._tracks_out = 0
        self._fusion_ms = 0.0
        self._cost_names: dict[str, str] = {}
        self._trust_names: dict[str, tuple[str, ...]] = {}
        """Report value names of cost fields and of each neighbour's trust, made once."""
        self.sent = 0
        self.reports: HostReports | None = None
        """A peer host's: reports go there, flushed when the host says (:meth:`flush`)."""
        self.record_put: Callable[[bytes], None] | None = None
        """A recorder's (``run --record``): every telemetry message also goes there, watched or
        not, each peer's own (a hosted one's too), so an offline view draws what a live one
        did (``sensornet view --from-mcap``)."""
        self.wants_flush = False
        """Whether a report may be complete (tracks or an OSPA came since the last flush): the
        driver calls :meth:`flush` only then (a wake-up without it costs nothing here)."""

    @property
    def pending(self) -> int:
        """Scans whose report is gathered and not sent yet."""
        return len(self._pending)

    @property
    def enabled(self) -> bool:
        """Open and watched (or recorded): only then are records gathered and reports made."""
        return self._open and (self.watched or self.record_put is not None)

    def _matching(self, status) -> None:  # Zenoh's thread: a plain flag for the loop's
        self.watched = bool(status.matching)

    # -- transport ------------------------------------------------------------------------
    def open(self, session, keys) -> Observer:
        """Declare the publisher on ``telemetry/<peer>`` of ``session`` (best effort); a
        hosted peer's observer (:class:`HostReports`) has its host's."""
        if self.reports is not None:
            return self
        # heavy optional dependency: zenoh (the sans-I/O core and the twin never load it)
        import zenoh

        self._pub = session.declare_publisher(keys.telemetry(self.name),
                                              congestion_control=zenoh.CongestionControl.DROP)
        self._put = self._pub.put
        try:
            self._listener = self._pub.declare_matching_listener(self._matching)
            self.watched = bool(self._pub.matching_status.matching)
        except Exception:  # no matching status (an older Zenoh): always report
            self.watched = True
        self._open = True
        return self

    def attach(self, put) -> Observer:
        """Publish through ``put(payload)`` instead (tests, other transports): watched."""
        self._put, self._open, self.watched = put, True, True
        return self

    def close(self) -> None:
        _undeclare(self._listener, self._pub)
        self._pub = self._put = self._listener = None
        self._open = False

    # -- gathering ------------------------------------------------------------------------
    def _scan(self, k: int) -> dict:
        g = self._pending.get(k)
        if g is None:
            g = self._pending[k] = {"values": {}, "events": [], "points": {}, "later": [],
                                    "tracks": False}
        return g

    def _set(self, k: int, name: str, value) -> None:
        if value is not None:
            _put(self._scan(k)["values"], name, value)

    def published(self, out: Publish, latency_ms: float | None) -> None:
        """Tracks went out: the report's latency, and their encoded bytes, sent to the view
        with the report (a view that heard ``tracks/<peer>`` itself made every tracks put
        fan out to one more session: the peers paid per message for the watcher)."""
        if out.channel != "tracks" or not self.enabled:  # estimates pass by: channel first
            return
        g = self._scan(out.k)
        g["tracks"] = self.wants_flush = True
        if out.payload:  # the view draws the tracks from the report's put, not tracks/<peer>
            g["tracks_bytes"] = out.payload
        self._tracks_out = max(self._tracks_out, out.k)
        self._set(out.k, "latency_ms", latency_ms)

    def record(self, r: Record, compute_ms: float | None = None) -> None:
        """The scan's report fields from one core record (``local``, ``fusion``: own steps)."""
        if r.kind not in KINDS or not self.enabled:  # most records pass by: kind first
            return
        core, k, v = self.core, r.k, r.values
        if r.kind == "local":
            self._record_local(k, v, compute_ms)
        elif r.kind == "fusion":
            self._record_fusion(k, v)
        elif r.kind == "cost":  # its values named when the report is sent (message)
            self._scan(k)["later"].append(v)
        elif r.kind == "ospa":
            self._set(k, f"ospa/{v['which']}", v["value"])
            if v["which"] == "fused":  # only the fused one completes a report (ready)
                self.wants_flush = True
        elif r.kind == "rejected":
            self._set(k, f"rejected/{v['reason']}", core.rejected[v["reason"]])
        elif r.kind == "scan":  # those refused before decoding, by reason
            for reason, count in core.admission.rejected.items():
                self._set(k, f"rejected/before_decoding/{reason}", count)
        elif r.kind == "peer":
            self._scan(k)["events"].append(f"{v['peer']} {v['what']}")
        elif r.kind == "trust":  # each neighbour's statistic and weight, named in message
            self._scan(k)["later"].append(v)  # (8 records a scan: each named here was 4 us)
        elif r.kind == "trust-event":
            self._scan(k)["events"].append(f"WARN {v['neighbour']} {v['from']} -> {v['to']} "
                                           f"(score {v['score']})")

    def _record_local(self, k: int, v: dict, compute_ms: float | None) -> None:
        """A ``local`` record: component counts, filter time and the own scan's points."""
        core = self.core
        self._set(k, "components/before_level2", v.get("n_components"))
        self._set(k, "components/after_level2", v.get("n_published"))
        self._set(k, "compute_ms/filter", compute_ms)
        mix = core.consensus.last_local
        hooks = core.consensus.hooks
        if isinstance(mix, GaussianMixture):
            self._set(k, "cardinality/local", float(mix.weights.sum()))
            self._scan(k)["points"]["local/mixture"] = mix  # marks made at the flush
        elif mix is not None and hooks.plane is not None:  # raw scans: the own scan
            self._scan(k)["points"]["local"] = np.asarray(hooks.plane(mix),
                                                          float).reshape(-1, 2)
        cells = core.consensus.hooks.partition_view()
        if cells is not None:  # the scan and the cell of each of its points
            z, labels = cells
            g = self._scan(k)["points"]
            g["cells"] = np.asarray(z, float).reshape(-1, 2)
            g["cells/labels"] = np.column_stack([np.asarray(labels, float).reshape(-1),
                                                 np.zeros(len(g["cells"]))])
        particles = core.consensus.hooks.particles()
        if particles is not None:
            p = np.asarray(particles, float).reshape(-1, 2)
            self._scan(k)["points"]["particles"] = p[:: 1 + len(p) // PARTICLES_SHOWN]

    def _record_fusion(self, k: int, v: dict) -> None:
        """A ``fusion`` record: fused counts and ages; once a scan the fused points."""
        core = self.core
        c = core.consensus.nale.counts
        g = self._scan(k)
        # a record comes per round (and flood step), each overriding the last: kept as they
        # are, read once when the report is sent (:meth:`message`)
        g["fusion"] = (v, (c.late, c.redundant, c.too_old, c.dropped_late))
        if v.get("round", 1) <= 1:  # ages are measured in the first round only (the later
            g["ages"] = v.get("ages")  # rounds' records say 0 for every sender): kept from it
        if v.get("round", core.consensus.rounds) < core.consensus.rounds:
            return  # the rest once a scan, at its last round
        fused = core.consensus.last_fused
        hooks = core.consensus.hooks
        if fused is not None and hooks.plane is not None:  # the pooled scans, a sample
            self._set(k, "flooding/scans_held", len(fused))
            # packed when the report is sent (a fusion record comes per round and flood
            # step, each with a new scan set: only the last is sent); its place kept now
            g["points"]["pooled"] = None
            g["pooled"] = (hooks.plane, fused)
        elif isinstance(fused, GaussianMixture):  # as points, as the local (no 4-D mixture);
            self._scan(k)["points"]["fused/mixture"] = fused  # made at the flush (pack_marks)
        view = hooks.pda_view()
        if view is not None:  # the gates and weighted returns: no other message has them
            self._scan(k)["points"].update(pack_gates(view, own=self.name))
        if view is not None and "detector" in view:
            d, threshold = view["detector"]
            self._set(k, "detector/D_L", d)
            self._set(k, "detector/threshold", threshold)
        probs = core.consensus.fuser_hooks.model_probabilities
        if probs is not None:
            names = hooks.model_names
            for i, p in enumerate(probs()):
                self._set(k, f"model_probability/{names[i] if i < len(names) else i}", p)

    # -- publishing -----------------------------------------------------------------------
    def ready(self, force: bool = False) -> list[int]:
        """Scans whose report is complete: tracks out and OSPA scored (or the core scores
        nothing), or :data:`WAIT_SCANS` later tracks out; every one with ``force``."""
        scores = self.core.wants_truth
        newest = max(self._pending, default=0)  # a peer that publishes no tracks: still sent
        return sorted(k for k, g in self._pending.items()
                      if force or k <= max(self._tracks_out, newest - 8) - WAIT_SCANS
                      or (g["tracks"] and (not scores or "ospa/fused" in g["values"])))

    def message(self, k: int) -> Telemetry:
        """Scan ``k``'s report (taken out of the pending ones); its map marks still as the
        mixtures they are made of, until :func:`pack_marks` (a host makes all its peers'
        at once)."""
        g = self._pending.pop(k)
        values, costs, trusts = g["values"], self._cost_names, self._trust_names
        for v in g["later"]:  # trust and cost records, in their order, as record had set them
            j = v.get("neighbour")
            if j is None:  # cost
                for what, value in v.items():
                    if isinstance(value, int | float):
                        name = costs.get(what)
                        if name is None:
                            name = costs[what] = f"cost/{what}"
                        _put(values, name, value)
                continue
            trust = trusts.get(j)
            if trust is None:
                trust = trusts[j] = tuple(f"trust/{j}/{x}" for x in ("statistic", "weight",
                                                                      "withheld"))
            _put(values, trust[0], v["statistic"])
            _put(values, trust[1], v["weight"])
            if "withheld" in v:
                _put(values, trust[2], v["withheld"])
        fusion = g.get("fusion")
        if fusion is not None:  # the scan's last fusion record
            v, counts = fusion
            values = g["values"]
            _put(values, "components/fused", v.get("n_fused"))
            ages = g.get("ages")
            if ages:
                _put(values, "age", max(ages.values()))
            for what, n in zip(_OUT_OF_SEQUENCE, counts, strict=True):
                values[what] = float(n)
        if "pooled" in g:
            plane, fused = g["pooled"]
            p = np.asarray(plane(fused), float).reshape(-1, 2)
            g["points"]["pooled"] = p[:: 1 + len(p) // POOLED_SHOWN]
        if self.telemetry is not None and g["tracks"]:
            total = self.telemetry.compute_ms.get("fusion", 0.0)
            g["values"]["compute_ms/fusion"] = total - self._fusion_ms
            self._fusion_ms = total
        return Telemetry(self.name, k, g["values"], tuple(g["events"]), g["points"],
                         None, send_time=time.time())

    def flush(self, idle: bool, force: bool = False, host: bool = False) -> None:
        """Publish the complete reports once nothing waits (or at the end: every one), each
        after its scan's tracks: a peer of its own process as one bundle (one put), a hosted
        peer's into its host's bundle and only when its host calls (``host``: no peer of the
        host has work waiting) or at the end."""
        if not self.enabled or not self._pending or not (idle or force):
            return
        if self.reports is not None and not (host or force):
            return
        self.wants_flush = False
        done = self.ready(force)
        # the bytes the peer published with each report: no copy, no encoding
        items = [(self.name, self._pending[k].get("tracks_bytes"), self.message(k))
                 for k in done]
        try:
            if self.reports is not None:  # into the host's message, marks made there
                if self.watched:
                    self.reports.items.extend(items)
                if self.record_put is not None:  # recorded as a peer of its own puts it
                    for bundle in _bundles(items):
                        self.record_put(bundle)
            else:  # a peer of its own process: its tracks and reports in one put
                for bundle in _bundles(items):
                    if self.watched:
                        self._put(bundle)
                    if self.record_put is not None:
                        self.record_put(bundle)
            self.sent += len(done)
        except Exception:  # best effort: a view is never worth a peer's error
            pass


class HostReports:
    """The reports of a peer host's observers, sent as one message a pass of the host's loop
    on ``telemetries/<host>`` (:mod:`protocol.report_bundle`: the reports' values and points
    in one block each, their tracks beside them) instead of one put per peer: the host's ten
    or fifty peers make one message a scan, not ten or fifty, and their map marks are made
    in one vectorised call (:func:`pack_marks`) and converted once. The view splits it into
    the reports as if each had come on ``telemetry/<peer>``."""

    def __init__(self, put=None) -> None:
        """``put(payload)``: where bundles go (tests, :meth:`open` declares the publisher)."""
        self._put = put
        self._pub = self._listener = None
        self.observers: list[Observer] = []
        self.items: list[tuple[str, bytes | None, Telemetry]] = []
        """``(peer, its tracks' bytes or None, report)`` gathered since the last send."""
        self.sent = 0

    def add(self, obs: Observer) -> Observer:
        """``obs`` sends its reports here (watched whenever the host's key is)."""
        self.observers.append(obs)
        obs._open, obs.watched = True, self._put is not None
        obs.reports = self
        return obs

    @property
    def watched(self) -> bool:
        """Whether a subscriber (a view) hears the host's key now."""
        return any(obs.watched for obs in self.observers)

    def _matching(self, status) -> None:  # Zenoh's thread: plain flags for the loop's
        for obs in self.observers:
            obs.watched = bool(status.matching)

    def open(self, session, key: str) -> HostReports:
        """Declare the publisher on ``key`` (best effort, as :meth:`Observer.open`)."""
        # heavy optional dependency: zenoh (the sans-I/O core and the twin never load it)
        import zenoh

        self._pub = session.declare_publisher(key,
                                              congestion_control=zenoh.CongestionControl.DROP)
        self._put = self._pub.put
        try:
            self._listener = self._pub.declare_matching_listener(self._matching)
            watched = bool(self._pub.matching_status.matching)
        except Exception:  # no matching status (an older Zenoh): always report
            watched = True
        for obs in self.observers:
            obs.watched = watched
        return self

    def send(self) -> None:
        """The reports gathered since the last call, their marks made together, in one put
        (several past :data:`protocol.bundle.BUNDLE_BYTES`)."""
        if not self.items:
            return
        items, self.items = self.items, []
        try:
            pack_marks([r for _, _, r in items])
            for message in pack_reports(items, time.time()):
                self._put(message)
                self.sent += 1
        except Exception:  # best effort: a view is never worth a host's error
            pass

    def close(self) -> None:
        _undeclare(self._listener, self._pub)
        self._pub = self._listener = None
        for obs in self.observers:
            obs._open = False


def pack_marginals(mix: GaussianMixture) -> np.ndarray:
    """A mixture's position marginals as ``(3 n, 2)`` telemetry points (the local estimate
    rides in :attr:`Telemetry.points`, so a view needs none of the peers' estimates): per
    component ``[mx, my], [Pxx, Pxy], [Pyy, w]``; :func:`unpack_marginals` inverts it."""
    c = position_columns(mix.dim)
    n = len(mix)
    out = np.empty((n, 3, 2))
    out[:, 0] = mix.means[:, c]
    out[:, 1, 0], out[:, 1, 1] = mix.covs[:, c[0], c[0]], mix.covs[:, c[0], c[1]]
    out[:, 2, 0], out[:, 2, 1] = mix.covs[:, c[1], c[1]], mix.weights
    return out.reshape(-1, 2)


def unpack_marginals(points: np.ndarray) -> GaussianMixture:
    """Inverse of :func:`pack_marginals`: a 4-D ``[px, vx, py, vy]`` mixture (velocity
    blocks unit) for drawing."""
    r = np.asarray(points, float).reshape(-1, 3, 2)
    n = len(r)
    means = np.zeros((n, 4))
    means[:, 0], means[:, 2] = r[:, 0, 0], r[:, 0, 1]
    covs = np.tile(np.eye(4), (n, 1, 1))
    covs[:, 0, 0], covs[:, 0, 2], covs[:, 2, 0], covs[:, 2, 2] = (r[:, 1, 0], r[:, 1, 1],
                                                                  r[:, 1, 1], r[:, 2, 0])
    return GaussianMixture.trusted(r[:, 2, 1], means, covs)


def pack_gates(view: dict, own: str = "own") -> dict[str, np.ndarray]:
    """A PDA update's gates (``pda_view()``) as telemetry point sets: per sensor (2-D
    measurements, the first :data:`GATES_SHOWN`; a one-sensor filter's ``"own"`` named
    ``own``) ``pda/<sensor>`` with rows ``zhat``, ``[Sxx, Sxy]``, ``[Syy, gamma]``, then the
    ``m`` validated returns (the :data:`RETURNS_SHOWN` heaviest), then ``[weight, 0]`` per
    return; :func:`unpack_gate` inverts one."""
    out = {}
    for name, v in list(view.get("sensors", {}).items())[:GATES_SHOWN]:
        S = np.asarray(v["S"], float)
        z = np.asarray(v["returns"], float)
        w = np.asarray(v["weights"], float).reshape(-1)
        if S.shape != (2, 2) or len(z) != len(w):  # not a 2-D position gate: not drawn
            continue
        if len(w) > RETURNS_SHOWN:
            keep = np.sort(np.argsort(w)[::-1][:RETURNS_SHOWN])
            z, w = z[keep], w[keep]
        head = [np.asarray(v["zhat"], float).reshape(2), S[0], [S[1, 1], float(v["gamma"])]]
        rows = [np.array(head), z.reshape(-1, 2), np.column_stack([w, np.zeros(len(w))])]
        out[f"pda/{own if name == 'own' else name}"] = np.concatenate(rows)
    return out


def unpack_gate(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, float, np.ndarray,
                                             np.ndarray]:
    """Inverse of one :func:`pack_gates` set: ``zhat (2,)``, ``S (2, 2)``, ``gamma``, the
    returns ``(m, 2)`` and their weights ``(m,)``."""
    r = np.asarray(points, float).reshape(-1, 2)
    if len(r) < 3 or (len(r) - 3) % 2:
        raise ValueError(f"a PDA gate is 3 + 2 m rows, not {len(r)}")
    m, gamma = (len(r) - 3) // 2, float(r[2, 1])
    if not (np.isfinite(gamma) and gamma > 0):
        raise ValueError(f"a PDA gate's gamma must be positive, not {gamma}")
    S = np.array([[r[1, 0], r[1, 1]], [r[1, 1], r[2, 0]]])
    return r[0].copy(), S, gamma, r[3:3 + m], r[3 + m:, 0]


def heaviest_marginals(mix: GaussianMixture, n: int) -> np.ndarray:
    """The ``n`` heaviest components of ``mix``, heaviest first, reduced to what the map
    draws: their position marginals packed as :func:`pack_marginals` packs them, ``(3 m, 2)``
    rows ``[mx, my], [Pxx, Pxy], [Pyy, w]``, each 2x2 block symmetrised and floored at 1e-9 of
    its trace so that it is positive definite (an IMM's 6-D fused covariance need not be);
    one that is not even then is left out. Closed form per 2x2 block (Sylvester: ``a > 0``
    and ``a d - b^2 > 0``), straight from the mixture's arrays: a watched peer does this twice
    a scan, and a 4-D mixture made first and packed after cost it ~3x as much (issue 38)."""
    w = mix.weights
    keep = np.argsort(w, kind="stable")[::-1][:n]  # ties: the later first, as _many
    i, j = position_columns(mix.dim)  # integer indexes below: list ones cost 3x as much
    P = mix.covs
    a, d = P[keep, i, i], P[keep, j, j]
    b = 0.5 * (P[keep, i, j] + P[keep, j, i])
    floor = 1e-9 * np.maximum(a + d, 1e-9)
    a, d = a + floor, d + floor
    out = np.empty((len(keep), 3, 2))
    out[:, 0, 0], out[:, 0, 1] = mix.means[keep, i], mix.means[keep, j]
    out[:, 1, 0], out[:, 1, 1], out[:, 2, 0], out[:, 2, 1] = a, b, d, w[keep]
    good = (a > 0) & (a * d - b * b > 0)
    if not good.all():  # a degenerate one: not drawn
        out = out[good]
    return out.reshape(-1, 2)


def heaviest_marginals_many(mixes: list[GaussianMixture], n: int) -> list[np.ndarray]:
    """:func:`heaviest_marginals` of each mixture, to the bit, in one vectorised pass over
    all their components (those of one dimension together): a host's peers' marks at once,
    not two calls a peer-scan (issue 38). The ``n`` heaviest of each by one stable sort on
    (mixture, weight), then the same closed form on the rows kept."""
    out: list[np.ndarray] = [np.zeros((0, 2))] * len(mixes)
    groups: dict[int, list[int]] = {}
    for t, m in enumerate(mixes):
        groups.setdefault(m.dim, []).append(t)
    for dim, idx in groups.items():
        ms = [mixes[t] for t in idx]
        lens = np.fromiter((len(m.weights) for m in ms), np.intp, len(ms))
        w = np.concatenate([m.weights for m in ms])
        seg = np.repeat(np.arange(len(ms)), lens)
        # ascending by (-mixture, weight), stable, then reversed: mixtures in order, each
        # heaviest first with ties later-first, as argsort(w, stable)[::-1] per mixture
        order = np.lexsort((w, -seg))[::-1]
        start = np.cumsum(lens) - lens
        keep = order[np.arange(len(w)) - start[seg[order]] < n]
        i, j = position_columns(dim)
        P = np.concatenate([m.covs for m in ms])
        M = np.concatenate([m.means for m in ms])
        a, d = P[keep, i, i], P[keep, j, j]
        b = 0.5 * (P[keep, i, j] + P[keep, j, i])
        floor = 1e-9 * np.maximum(a + d, 1e-9)
        a, d = a + floor, d + floor
        rows = np.empty((len(keep), 3, 2))
        rows[:, 0, 0], rows[:, 0, 1] = M[keep, i], M[keep, j]
        rows[:, 1, 0], rows[:, 1, 1], rows[:, 2, 0], rows[:, 2, 1] = a, b, d, w[keep]
        good = (a > 0) & (a * d - b * b > 0)
        flat = rows[good].reshape(-1, 2)
        ends = 3 * np.cumsum(np.bincount(seg[keep][good], minlength=len(ms)))
        for t, e0, e1 in zip(idx, [0, *ends[:-1].tolist()], ends.tolist(), strict=True):
            out[t] = flat[e0:e1]
    return out


def _bundles(items: list[tuple[str, bytes | None, Telemetry]]) -> list[bytes]:
    """A peer's reports and the tracks beside them as the bundles it puts on
    ``telemetry/<peer>`` (:mod:`protocol.bundle`), their map marks made first."""
    pack_marks([r for _, _, r in items])
    entries: list[tuple[str, bytes]] = []
    for name, tracks, r in items:
        if tracks is not None:
            entries.append((name, tracks))
        entries.append((name, encode(r)))
    return pack_bundles(0, entries)


def pack_marks(reports: list[Telemetry]) -> None:
    """Each report's map marks still held as a mixture (``local/mixture``, ``fused/mixture``:
    :meth:`Observer.message`) replaced by its :data:`FUSED_SHOWN` heaviest position
    marginals, all the reports' in one :func:`heaviest_marginals_many` call."""
    held = [(r.points, name) for r in reports for name, z in r.points.items()
            if isinstance(z, GaussianMixture)]
    if held:
        marks = heaviest_marginals_many([p[name] for p, name in held], FUSED_SHOWN)
        for (p, name), z in zip(held, marks, strict=True):
            p[name] = z


def _heaviest(mix: GaussianMixture, n: int) -> GaussianMixture:
    """:func:`heaviest_marginals` as a 4-D ``[px, vx, py, vy]`` mixture (velocity blocks
    unit): the marks the view draws."""
    return unpack_marginals(heaviest_marginals(mix, n))
