"""OSPA scoring of a peer's local and fused estimates, with missing output scored as a miss.

Truth is an evaluation side channel. A peer that knows its scenario regenerates the truth
itself (``truth=`` a function of the scan index), so a forged ``Truth`` message cannot change
its score: a message that disagrees is rejected. Without that function, the first truth per scan
counts and a later, different one is rejected as a conflict.

Every accepted scan is expected to produce a local and a fused estimate. One that never comes
(an internal error, a lost scan inside the normal window, the end of the run) is scored at the
cut-off ``c`` (a miss) and stays in the mean, so a peer that stops producing output cannot look
better for it.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from sensornet.peers.scan_results import ScanResults
from sensornet.tracking.metrics import ospa_gospa_parts_many

WHICH = ("local", "fused")
TruthFn = Callable[[int], "np.ndarray | None"]


class ScoreBatch:
    """The scores several peers of one process owe, computed together at the end of a pass
    of their host's loop (:func:`tracking.metrics.ospa_gospa_parts_many`: the same numbers as
    one by one, in fewer NumPy calls). A scorer with a batch hands its scores here; anything
    that reads a score (means, the summary, the end of the run) flushes first."""

    def __init__(self) -> None:
        self.items: list[tuple] = []

    def add(self, scorer: Scorer, which: str, k: int, states: np.ndarray,
            truth: np.ndarray) -> None:
        self.items.append((scorer, which, k, states, truth))

    def flush(self) -> list[Scorer]:
        """Score everything waiting; the scorers served (each once, in order)."""
        items, self.items = self.items, []
        if not items:
            return []
        groups: dict[tuple[float, float], list[tuple]] = {}
        for it in items:
            groups.setdefault((it[0].c, it[0].p), []).append(it)
        for (c, p), group in groups.items():
            pos = [(sc.results.xy(states), sc.results.xy(truth))
                   for sc, _, _, states, truth in group]
            for (sc, which, k, states, truth), (est, true), (value, parts) in zip(
                    group, pos, ospa_gospa_parts_many(pos, c, p), strict=True):
                sc.results.scored_as(k, which, states, truth, est, true, value, parts,
                                     sc._ids(which, k))
                sc._count(which, k, states, truth, value)
        served: dict[int, Scorer] = {}
        for it in items:
            served.setdefault(id(it[0]), it[0])
        return list(served.values())


class Scorer:
    """Mean OSPA of the ``"local"`` and ``"fused"`` estimates of one peer."""

    def __init__(self, cutoff: float, order: float, position_index: tuple[int, int],
                 truth: TruthFn | None = None, window: int = 8) -> None:
        self.c, self.p = float(cutoff), float(order)
        self.pos = list(position_index)
        self.truth_fn = truth
        self.window = window
        self._truth: dict[int, np.ndarray] = {}
        self._truth_ids: dict[int, np.ndarray] = {}
        """True target ids of the truth messages taken, by scan."""
        self._track_ids: dict[tuple[str, int], tuple] = {}
        """(which, k) -> (track ids (n, 3), status (n,)) of outputs not yet in the table."""
        self._waiting: dict[str, dict[int, np.ndarray]] = {w: {} for w in WHICH}
        self._expected: dict[str, set[int]] = {w: set() for w in WHICH}
        self.sums = dict.fromkeys(WHICH, 0.0)
        self.counts = dict.fromkeys(WHICH, 0)
        self.misses = dict.fromkeys(WHICH, 0)
        self.card_sums = dict.fromkeys(WHICH, 0.0)
        """Sums of ``|estimated - true|`` target numbers (a missing output estimates 0)."""
        self.unscored = 0
        """Estimates whose truth never arrived (no truth function, truth messages lost)."""
        self.records: list[dict] = []
        self.results = ScanResults(cutoff, order, position_index)
        """Every scored estimate and miss, row by row (the run's per-scan results table)."""
        self.batch: ScoreBatch | None = None
        """Where scores go to be computed with other peers' (a host's); None: at once."""

    # -- truth ------------------------------------------------------------------------------
    def truth(self, k: int) -> np.ndarray | None:
        if self.truth_fn is not None:
            return self.truth_fn(k)
        return self._truth.get(k)

    def truth_ids(self, k: int) -> np.ndarray | None:
        """The true target ids of scan ``k`` (``(n,)``, rows of :meth:`truth`): the truth
        function's ``ids`` attribute (a function of ``k``, if it has one), else the ids of the
        truth message taken; None if unknown."""
        fn = getattr(self.truth_fn, "ids", None) if self.truth_fn is not None else None
        return fn(k) if fn is not None else self._truth_ids.get(k)

    def _ids(self, which: str, k: int) -> tuple:
        tid, status = self._track_ids.pop((which, k), (None, None))
        return tid, status, self.truth_ids(k)

    def truth_message(self, k: int, states: np.ndarray,
                      ids: np.ndarray | None = None) -> str | None:
        """Take a ``Truth`` message (its target ``ids`` kept for the table); the rejection
        reason, or None if it was used."""
        states = np.asarray(states, float)
        if self.truth_fn is not None:
            mine = self.truth_fn(k)
            if mine is None or mine.shape != states.shape or not np.allclose(mine, states):
                return "truth-mismatch"
            return None
        held = self._truth.get(k)
        if held is not None:
            same = held.shape == states.shape and np.allclose(held, states)
            return None if same else "truth-conflict"
        self._truth[k] = states
        if ids is not None and len(ids) == len(states):
            self._truth_ids[k] = np.asarray(ids, np.int64)
        for which in WHICH:
            if k in self._waiting[which]:
                self._score(which, k, self._waiting[which].pop(k))
        return None

    # -- estimates --------------------------------------------------------------------------
    def expect(self, k: int) -> None:
        """Scan ``k`` was accepted: a local and a fused estimate are due."""
        for which in WHICH:
            self._expected[which].add(k)

    def skipped(self, ks: range) -> None:
        """Scans ``ks`` inside the normal window never arrived: no output for them (misses,
        each at the cut-off and, for the cardinality error, as no target estimated)."""
        card = sum(len(X) for X in map(self.truth, ks) if X is not None)
        for which in WHICH:
            self.misses[which] += len(ks)
            self.card_sums[which] += card
            for k in ks:
                self.results.missed(k, which, self.truth(k), self.truth_ids(k))

    def output(self, which: str, k: int, states: np.ndarray, ids: np.ndarray | None = None,
               status: np.ndarray | None = None) -> None:
        """Score estimate ``which`` of scan ``k``: ``states (n, d)``, with a labelled kind's
        track ``ids (n, 3)`` and ``status (n,)`` for the table (not scored by OSPA)."""
        if k not in self._expected[which]:
            return  # already scored, or not a scan this peer accepted
        self._expected[which].discard(k)
        if ids is not None:
            self._track_ids[(which, k)] = (ids, status)
        if self.truth(k) is not None:
            self._score(which, k, states)
        else:
            self._waiting[which][k] = states

    def advance(self, newest: int) -> None:
        """Scans far behind ``newest`` are settled: missing outputs become misses."""
        self._settle(lambda k: k < newest - self.window)

    def finish(self) -> None:
        """End of the run: every output still missing is a miss."""
        self.flush()
        self._settle(lambda k: True)

    def _settle(self, old: Callable[[int], bool]) -> None:
        for which in WHICH:
            gone = [k for k in self._expected[which] if old(k)]
            for k in gone:
                self._expected[which].discard(k)
                self.misses[which] += 1
                X = self.truth(k)
                self.card_sums[which] += len(X) if X is not None else 0
                self.results.missed(k, which, X, self.truth_ids(k))
                self._track_ids.pop((which, k), None)
                self.records.append({"k": k, "kind": "ospa", "which": which, "value": self.c,
                                     "miss": True})
            late = [k for k in self._waiting[which] if old(k)]
            for k in late:
                del self._waiting[which][k]
                self._track_ids.pop((which, k), None)
                self.unscored += 1
        for k in [k for k in self._truth if old(k)]:
            del self._truth[k]
            self._truth_ids.pop(k, None)

    def _score(self, which: str, k: int, states: np.ndarray) -> None:
        X = self.truth(k)
        if self.batch is not None:
            self.batch.add(self, which, k, states, X)
            return
        self._count(which, k, states, X, self.results.scored(k, which, states, X,
                                                              self._ids(which, k)))

    def flush(self) -> None:
        """Scores handed to a batch are computed now (before anything reads them)."""
        if self.batch is not None:
            self.batch.flush()

    def _count(self, which: str, k: int, states: np.ndarray, X: np.ndarray,
               value: float) -> None:
        self.sums[which] += value
        self.card_sums[which] += abs(len(states) - len(X))
        self.counts[which] += 1
        self.records.append({"k": k, "kind": "ospa", "which": which, "value": value})

    def mean(self, which: str) -> float:
        """Mean OSPA over scored estimates and misses (a miss counts ``c``)."""
        self.flush()
        n = self.counts[which] + self.misses[which]
        return (self.sums[which] + self.c * self.misses[which]) / n if n else float("nan")

    def mean_cardinality_error(self, which: str) -> float:
        """Mean ``|estimated - true|`` target number over the same scans as :meth:`mean` (a
        missing output counts as no target estimated)."""
        self.flush()
        n = self.counts[which] + self.misses[which]
        return self.card_sums[which] / n if n else float("nan")

    def drain_records(self) -> list[dict]:
        out, self.records = self.records, []
        return out
