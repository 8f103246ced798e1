"""The Rerun view of one peer: what its outputs and records look like on the map and the plots.

Reads only the core's public state (the latest local and fused densities, the estimator's
particles, counters) and the outputs the driver carried out. Drawing the local mixture is
deferred until the scan's tracks are out (:meth:`Observer.flush`): done at once it took CPU from
the neighbours' filter steps in the very burst that sets the scan-to-track latency.
"""

from __future__ import annotations

from collections import deque

import numpy as np
from sensornet.peers.core import PeerCore, Publish, Record
from sensornet.peers.rerun_sink import RerunSink, TrackLabels, color_of, ellipses, position_columns


class Observer:
    """Logs one peer's run to a :class:`~peers.rerun_sink.RerunSink` (no-op when disabled)."""

    def __init__(self, core: PeerCore, sink: RerunSink, color_index: int,
                 scan_period: float, label_gate: float = 100.0) -> None:
        """``label_gate``: metres within which a fused track keeps its display number from
        one scan to the next (:class:`~peers.rerun_sink.TrackLabels`)."""
        self.core = core
        self.name = core.name
        self.sink = sink
        self.color = color_of(color_index)
        self.scan_period = scan_period
        self.tails: deque = deque(maxlen=20)
        self._deferred: list = []
        self.labels = TrackLabels(label_gate)

    @property
    def enabled(self) -> bool:
        return self.sink.enabled

    def _time(self, k: int) -> None:
        self.sink.time(k, k * self.scan_period)

    def published(self, out: Publish, latency_ms: float | None) -> None:
        if not self.enabled or out.channel != "tracks":
            return
        states = out.message.states
        self._time(out.k)
        if latency_ms is not None:
            self.sink.scalar(f"metrics/latency_ms/{self.name}", latency_ms)
        xy = states[:, position_columns(states.shape[1])] if len(states) else np.zeros((0, 2))
        ids = self.labels.assign(xy)
        self.sink.labelled_points(f"peers/{self.name}/tracks", xy, self.color,
                                  [f"{self.name}/{i}" for i in ids], radius=5.0)
        self.tails.append(xy)
        self.sink.points(f"peers/{self.name}/tail", np.concatenate(list(self.tails)),
                         self.color, radius=1.5)
        self.sink.scalar(f"metrics/cardinality/{self.name}/fused", len(states))

    def record(self, r: Record, compute_ms: float | None = None) -> None:
        if not self.enabled:
            return
        n, core = self.name, self.core
        if r.kind == "local":
            self._time(r.k)
            self.sink.scalar(f"metrics/components/{n}/before_level2",
                             r.values.get("n_components"))
            self.sink.scalar(f"metrics/components/{n}/after_level2",
                             r.values.get("n_published"))
            self._defer_local(r.k, compute_ms)
        elif r.kind == "fusion":
            self._time(r.k)
            self.sink.scalar(f"metrics/components/{n}/fused", r.values["n_fused"])
            ages = r.values.get("ages") or {}
            if ages:
                self.sink.scalar(f"metrics/age/{n}", max(ages.values()))
            c = core.consensus.nale.counts
            for what in ("late", "redundant", "too_old", "dropped_late"):
                self.sink.scalar(f"metrics/out_of_sequence/{n}/{what}", getattr(c, what))
            fused = core.consensus.last_fused
            hooks = core.consensus.hooks
            if fused is not None and hooks.plane is not None:  # scans: the pooled points
                self.sink.scalar(f"metrics/flooding/{n}/scans_held", len(fused))
                if r.values["round"] == core.consensus.rounds:  # drawn once, at the end
                    self.sink.points(f"peers/{n}/pooled", hooks.plane(fused), self.color,
                                     radius=1.0)
            elif fused is not None:
                self.sink.mixture(f"peers/{n}/fused", fused, self.color)
            view = hooks.pda_view()
            if view is not None:  # gates, weighted returns, detector
                self._deferred.append(lambda k=r.k, v=view: self._pda(k, v))
            probs = core.consensus.fuser_hooks.model_probabilities
            if probs is not None:
                names = hooks.model_names
                for i, p in enumerate(probs()):
                    label = names[i] if i < len(names) else f"model{i}"
                    self.sink.scalar(f"metrics/model_probability/{n}/{label}", float(p))
        elif r.kind == "cost":
            self._time(r.k)
            for what, value in r.values.items():
                self.sink.scalar(f"metrics/cost/{n}/{what}", value)
        elif r.kind == "ospa":
            self._time(r.k)
            self.sink.scalar(f"metrics/ospa/{n}/{r.values['which']}", r.values["value"])
        elif r.kind == "rejected":
            reason = r.values["reason"]
            self.sink.scalar(f"metrics/rejected/{n}/{reason}", core.rejected[reason])
        elif r.kind == "scan":  # those refused before decoding, by reason, once a scan
            self._time(r.k)
            for reason, count in core.admission.rejected.items():
                self.sink.scalar(f"metrics/rejected/{n}/before_decoding/{reason}", count)
        elif r.kind == "peer":
            self.sink.text(f"peers/{n}/events", f"{r.values['peer']} {r.values['what']}")
        elif r.kind == "trust":  # one plot per peer: each neighbour's statistic and weight
            self._time(r.k)
            j = r.values["neighbour"]
            self.sink.scalar(f"metrics/trust/{n}/{j}/statistic", r.values["statistic"])
            self.sink.scalar(f"metrics/trust/{n}/{j}/weight", r.values["weight"])
            if "withheld" in r.values:  # the withheld-target CUSUM (held above 4.47)
                self.sink.scalar(f"metrics/trust/{n}/{j}/withheld", r.values["withheld"])
        elif r.kind == "trust-event":
            v = r.values
            self.sink.text(f"peers/{n}/events", f"{v['neighbour']} {v['from']} -> {v['to']} "
                           f"(score {v['score']})", level="WARN")

    def _defer_local(self, k: int, compute_ms: float | None) -> None:
        core = self.core
        mix = core.consensus.last_local
        hooks = core.consensus.hooks
        particles = hooks.particles()
        cells = hooks.partition_view()

        def log() -> None:
            self._time(k)
            if mix is not None and hooks.plane is not None:  # scans: the own scan's points
                self.sink.points(f"peers/{self.name}/local", hooks.plane(mix), self.color,
                                 radius=2.0)
            elif mix is not None:
                self.sink.mixture(f"peers/{self.name}/local", mix, self.color)
            if particles is not None:  # a particle cloud
                self.sink.points(f"peers/{self.name}/particles", particles, self.color,
                                 radius=1.0)
            if cells is not None:  # the scan's measurement cells
                self._cells(*cells)
            if compute_ms is not None:
                self.sink.scalar(f"metrics/compute_ms/{self.name}/filter", compute_ms)

        self._deferred.append(log)

    def _cells(self, z: np.ndarray, labels: np.ndarray) -> None:
        """The scan coloured by cell of the most probable partition; one-point cells (the
        clutter the grid method removed, isolated points) grey; 2-sigma extents of the cells
        of 3 or more points."""
        _, inv, counts = np.unique(labels, return_inverse=True, return_counts=True)
        inv = inv.reshape(-1)
        single = counts[inv] == 1
        colors = np.array([color_of(i) for i in range(len(counts))])[inv]
        colors[single] = (128, 128, 128)
        self.sink.points(f"peers/{self.name}/cells/points", z, colors, radius=2.5)
        big = np.flatnonzero(counts >= 3)
        means = np.zeros((len(big), 4))
        covs = np.zeros((len(big), 4, 4))
        for i, c in enumerate(big):
            w = z[inv == c]
            means[i, [0, 2]] = w.mean(axis=0)
            covs[i][np.ix_([0, 2], [0, 2])] = np.cov(w.T)
        strips = ellipses(means, covs)
        self.sink.strips(f"peers/{self.name}/cells/extents", list(strips),
                         [color_of(int(c)) for c in big] if len(big) else None)

    def _pda(self, k: int, view: dict) -> None:
        """A PDA update: each sensor's gate (its ``gamma`` ellipse about the predicted
        measurement), the validated returns coloured by weight (blue 0 to red 1), and the
        detector statistic ``D_L`` beside its threshold."""
        self._time(k)
        n = self.name
        for s, v in view["sensors"].items():
            mean = np.zeros((1, 4))
            mean[0, [0, 2]] = v["zhat"]
            cov = np.zeros((1, 4, 4))
            cov[0][np.ix_([0, 2], [0, 2])] = v["S"]
            gate = ellipses(mean, cov, sigma=float(np.sqrt(v["gamma"])))
            self.sink.strips(f"peers/{n}/pda/{s}/gate", list(gate), self.color)
            w = np.clip(np.asarray(v["weights"], float), 0.0, 1.0)
            colors = np.stack([255 * w, 40 + 0 * w, 255 * (1 - w)], axis=1).astype(np.uint8)
            self.sink.points(f"peers/{n}/pda/{s}/returns", v["returns"], colors, radius=3.0)
        if "detector" in view:
            d, threshold = view["detector"]
            self.sink.scalar(f"metrics/detector/{n}/D_L", d)
            self.sink.scalar(f"metrics/detector/{n}/threshold", threshold)

    def flush(self, idle: bool, force: bool = False) -> None:
        """Run the deferred drawing once nothing waits (or there is a backlog, or at the end)."""
        if not self._deferred or not (force or idle or len(self._deferred) > 10):
            return
        pending, self._deferred = self._deferred, []
        for log in pending:
            log()
