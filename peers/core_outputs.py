"""What a :class:`peers.core.PeerCore` hands its driver: publications (encoded, their bytes
counted), per-scan cost records, the records its parts drained, and the scoring kept off the
path from a scan to its published tracks."""

from __future__ import annotations

from collections import Counter

from sensornet.peers.consensus import Consensus
from sensornet.peers.core_types import Output, Publish, Record
from sensornet.peers.scoring import Scorer
from sensornet.protocol.codec import encode
from sensornet.protocol.messages import Estimate, Forward, Returns, Tracks

_ESTIMATES = (Estimate, Forward, Returns)
"""The messages published as estimates (a tuple: ``A | B | C`` built a union per message)."""


class CoreOutputs:
    """The output side of :class:`peers.core.PeerCore` (its base: subclasses such as the lying
    core override :meth:`_wrap`)."""

    consensus: Consensus
    estimator: object
    scorer: Scorer
    sent_bytes: Counter
    _cost_mark: tuple[int, int, int]
    _pending_fused: list[Tracks]
    _pending_local: list[int]

    def _wrap(self, messages: list) -> list[Output]:
        out: list[Output] = []
        for m in messages:
            if isinstance(m, _ESTIMATES):
                out.append(Publish("estimate", m.k, encode(m), m))
                self.sent_bytes["estimate"] += len(out[-1].payload)
            elif isinstance(m, Tracks):
                ids = self.consensus.hooks.point_tracks  # a kind without labels: point ids
                m = m if ids is None or self.consensus.labelled else ids.tracks(m)
                out.append(Publish("tracks", m.k, encode(m), m))
                self.sent_bytes["tracks"] += len(out[-1].payload)
                out.append(self._scan_cost(m.k))
                self._pending_fused.append(m)  # scored after publishing
        return out

    def _scan_cost(self, k: int) -> Record:
        """What this scan's estimates or forwards cost (published since the last tracks)."""
        st = self.consensus.stats
        now = (st.tuples_out, st.tuples_to_neighbours, self.sent_bytes["estimate"])
        d = [a - b for a, b in zip(now, self._cost_mark, strict=True)]
        self._cost_mark = now
        fan = len(self.consensus.alive)
        return Record("cost", k, {"tuples": d[1], "tuples_published": d[0],
                                  "bytes": d[2] * fan, "bytes_published": d[2]})

    def _score_deferred(self) -> None:
        """Score the fused tracks published since the last call, then extract and score the
        local estimate: both kept off the path from scan to published tracks."""
        for m in self._pending_fused:
            self.scorer.output("fused", m.k, m.states, m.ids, m.status)
        self._pending_fused.clear()
        c = self.consensus
        while self._pending_local:
            k = self._pending_local.pop()
            if k == c.last_k and c.last_local is not None:
                t = c.local_tracks()  # a labelled kind's: the same states, with ids
                if t is None:
                    states = self.estimator.extract(c.last_local)
                    ids = c.hooks.point_tracks  # a kind without labels: point ids
                    self.scorer.output("local", k, states,
                                       *(() if ids is None else ids.local_ids(k, states)))
                else:
                    self.scorer.output("local", k, t.states, t.ids, t.status)
        self._pending_local.clear()

    def _records(self) -> list[Output]:
        recs = self.consensus.drain_records() + self.scorer.drain_records()
        return [Record(r.pop("kind"), r.pop("k"), r) for r in recs]
