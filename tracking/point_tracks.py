"""Track ids for extracted points: frame-to-frame association of a filter's point estimates.

Kinds whose filter has no labels of its own (the single-target IMM and PDA peers, the
extended-target GM-PHD, flooding's density-peaks clustering) still report tracks with ids
(issue 33 item 2). :class:`PointTracker` gives them: per scan, the extracted positions
``P (n, 2)`` are assigned to the live tracks by SciPy's ``linear_sum_assignment`` (the Hungarian
/ Jonker-Volgenant algorithm) on the Euclidean distance to each track's predicted position
(last position plus an alpha-beta velocity times the scans since, so crossing targets keep
their ids), gated at ``gate``; a point left unassigned starts a track ``(origin, k, i)``
(the label layout of :mod:`tracking.labels`: origin, birth scan, index among the scan's
births ordered by x, then y: peers extracting nearly the same points number them alike). A
track is confirmed after hits in ``m`` of its last ``n`` scans (the classic M-of-N
confirmation logic, Blackman & Popoli 1999, Sec. 6.3) and stays confirmed while it lives; it is
deleted after more than ``max_missed`` scans without a hit. Pure NumPy/SciPy: the tracker
only labels the points, it never moves, adds or drops one.

Arrays: ``t`` live tracks, ``n`` points of a scan; ids ``(n, 3)`` int64, status ``(n,)`` int8
(0 tentative, 1 confirmed: :class:`protocol.messages.Tracks`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment

TENTATIVE, CONFIRMED = 0, 1


@dataclass(frozen=True)
class PointTrackConfig:
    """How a kind's extracted points become tracks (see :class:`PointTracker`)."""

    gate: float = np.inf
    """Largest distance (state position units, e.g. metres) between a track's predicted
    position and a point it takes; ``inf``: any (a single-target kind's one track)."""
    m: int = 1
    """Hits needed among the last :attr:`n` scans to confirm a track."""
    n: int = 1
    """Window of the M-of-N confirmation, in scans (1..62)."""
    max_missed: int = 3
    """A track is deleted after more than this many consecutive scans without a hit."""
    beta: float = 0.5
    """Velocity gain of the alpha-beta predictor (alpha = 1: the position is the point)."""
    fused_origin: int | None = None
    """The origin of the fused tracks' ids: None, the peer's own; an integer (0, the lowest
    origin) where every peer computes the same fused points, so equal points give equal ids
    at every peer (a single-target network's one target, flooding's pooled clustering)."""

    def __post_init__(self) -> None:
        if not (self.gate > 0):
            raise ValueError(f"point-track gate must be > 0, got {self.gate}")
        if not (1 <= self.m <= self.n <= 62):
            raise ValueError(f"M-of-N confirmation needs 1 <= m <= n <= 62, got {self.m} of "
                             f"{self.n}")
        if self.max_missed < 0:
            raise ValueError(f"max_missed must be >= 0, got {self.max_missed}")
        if not (0.0 <= self.beta <= 1.0):
            raise ValueError(f"beta must be in [0, 1], got {self.beta}")


class PointTracker:
    """Ids for one stream of extracted points (one peer's local or fused tracks).

    State per live track (``t`` rows): ``ids (t, 3)``, last position ``pos (t, 2)``, velocity
    per scan ``vel (t, 2)``, scan of the last hit ``seen (t,)``, hits so far ``hits (t,)``, the
    hit bits of the last ``n`` scans ``window (t,)`` (bit 0: the last update) and
    ``confirmed (t,)``."""

    def __init__(self, origin: int, config: PointTrackConfig | None = None) -> None:
        if origin < 0:
            raise ValueError(f"origin must be a non-negative integer, got {origin}")
        self.origin = int(origin)
        self.cfg = config or PointTrackConfig()
        self.ids = np.zeros((0, 3), dtype=np.int64)
        self.pos = np.zeros((0, 2))
        self.vel = np.zeros((0, 2))
        self.seen = np.zeros(0, dtype=np.int64)
        self.hits = np.zeros(0, dtype=np.int64)
        self.window = np.zeros(0, dtype=np.int64)
        self.confirmed = np.zeros(0, dtype=bool)
        self.k: int | None = None
        """The scan of the last update."""
        self.deleted = 0
        """Tracks deleted so far (more than ``max_missed`` scans without a hit)."""

    def update(self, k: int, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The ids ``(n, 3)`` and status ``(n,)`` of scan ``k``'s points ``(n, 2)``, in their
        order; scans must increase (a skipped scan counts as a miss of every track)."""
        P = np.asarray(points, dtype=float).reshape(-1, 2)
        k = int(k)
        if self.k is not None and k <= self.k:
            raise ValueError(f"point tracker: scan {k} after scan {self.k}")
        if not np.isfinite(P).all():
            raise ValueError("point tracker: a point is not finite")
        cfg = self.cfg
        gap = 1 if self.k is None else k - self.k
        self._drop_stale(k)
        dt = (k - self.seen).astype(float)  # (t,) scans since each track's last hit
        pred = self.pos + self.vel * dt[:, None]
        ti, pi = self._assign(pred, P)
        # window bits shift by the scans elapsed; a hit sets bit 0
        mask = (1 << cfg.n) - 1
        self.window = (self.window << min(gap, cfg.n)) & mask
        self.window[ti] |= 1
        first = self.hits[ti] == 1  # one hit, no velocity yet: the first difference
        step = (P[pi] - self.pos[ti]) / dt[ti, None]
        self.vel[ti] = np.where(first[:, None], step,
                                self.vel[ti] + cfg.beta * (P[pi] - pred[ti]) / dt[ti, None])
        self.pos[ti], self.seen[ti] = P[pi], k
        self.hits[ti] += 1
        # unassigned points: new tracks, (origin, k, i) in order of x then y, so peers that
        # extract nearly the same points number their births alike whatever the points' order
        free = np.ones(len(P), dtype=bool)
        free[pi] = False
        new = np.flatnonzero(free)  # ascending, as setdiff1d gave: one mask, no sort
        if len(new):  # most scans bear nothing: their arrays stay as they are
            new = new[np.lexsort((P[new, 1], P[new, 0]))]
            born = np.empty((len(new), 3), dtype=np.int64)
            born[:, 0], born[:, 1], born[:, 2] = self.origin, k, np.arange(len(new))
            self.ids = np.concatenate([self.ids, born])
            self.pos = np.concatenate([self.pos, P[new]])
            self.vel = np.concatenate([self.vel, np.zeros((len(new), 2))])
            self.seen = np.concatenate([self.seen, np.full(len(new), k, dtype=np.int64)])
            self.hits = np.concatenate([self.hits, np.ones(len(new), dtype=np.int64)])
            self.window = np.concatenate([self.window, np.ones(len(new), dtype=np.int64)])
            self.confirmed = np.concatenate([self.confirmed, np.zeros(len(new), dtype=bool)])
        self.confirmed |= _popcount(self.window) >= cfg.m
        self.k = k
        row = np.empty(len(P), dtype=np.int64)  # each point's track row
        row[pi] = ti
        row[new] = len(self.ids) - len(new) + np.arange(len(new))
        return self.ids[row].copy(), self.confirmed[row].astype(np.int8)

    def _drop_stale(self, k: int) -> None:
        """Delete the tracks whose last hit is more than ``max_missed`` scans before the
        scan before ``k`` (they would have missed ``k - 1 - seen`` scans by now)."""
        keep = (k - 1 - self.seen) <= self.cfg.max_missed
        if keep.all():  # the usual scan: nothing to delete, no copies
            return
        self.deleted += int((~keep).sum())
        for name in ("ids", "pos", "vel", "seen", "hits", "window", "confirmed"):
            setattr(self, name, getattr(self, name)[keep])

    def _assign(self, pred: np.ndarray, P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Rows of tracks and points paired: least total distance among pairs within the gate
        (most pairs first), as :func:`tracking.track_metrics.clear_match` does."""
        if len(pred) == 0 or len(P) == 0:
            return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
        D = np.linalg.norm(pred[:, None, :] - P[None, :, :], axis=-1)  # (t, n)
        ok = D <= self.cfg.gate
        if not ok.any():
            return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
        big = 2 * min(D.shape) * (D[ok].max() + 1) + 1  # any pair in the gate beats it
        r, c = linear_sum_assignment(np.where(ok, D, big))
        good = ok[r, c]
        return r[good].astype(np.int64), c[good].astype(np.int64)


def _popcount(x: np.ndarray) -> np.ndarray:
    """Set bits of each non-negative int64 (``(t,)`` -> ``(t,)``)."""
    b = x.astype(np.uint64).view(np.uint8).reshape(len(x), 8)
    return np.unpackbits(b, axis=1).sum(axis=1)
