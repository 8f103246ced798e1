"""Re-identification memory of a labelled GM-PHD peer (issue 33): a re-born target keeps its id.

When every peer loses a target (a few missed detections at Pd 0.9 cut its PHD weight below the
publication threshold) and the filter's birth picks it up again, the new track is stamped with
a new label (:class:`tracking.labels.Publication`), so its id switches. This memory keeps, for
``scans`` scans, the label of each track that went dark after being published ``age`` scans in
a row, and the track's last published state; a label stamped new in that time whose track lies
inside the gate of a lost track's state predicted forward takes the lost label back instead.

The gate is the squared Mahalanobis distance of the pair, ``(m_n - F^dt m_l)^T (P_n + F^dt P_l
F^dt^T + Q_dt)^-1 (m_n - F^dt m_l)`` with ``dt`` the scans since the lost track was last
published (the CV model's multi-step transition, :meth:`tracking.models.ConstantVelocity
.transition`), all (new, lost) pairs in one stacked solve; several candidates are resolved by
SciPy ``linear_sum_assignment`` on the costs capped at the gate (the track-continuation rule
of Panta, Clark & Vo 2009 §IV applied to a gap of a few scans: a "coasted" track, Blackman &
Popoli 1999 §9.3). The returned label is the earliest one of the target, so the network rule
(earliest birth, :func:`tracking.labels.precedes`) spreads it to the peers that did not
re-identify.

**A label stays where its track was** (``jump``, issue 34's handovers on real traffic): a
label that went dark (unpublished for a scan or more) lingers on light remnant components,
whose covariance grows as they coast; when another aircraft passes within their (wide) update
gate, a remnant takes its plots and comes back published on it, with the old label, which is
the earliest on the network and replaces the other aircraft's id at every peer
(docs/real-traffic.md, "The handover traced"). Both a label's return and a re-identification
therefore also need the track within ``jump`` metres of where the label's last published
state, predicted forward, puts it: a chi-square gate alone does not hold a long-coasted,
kilometres-wide prediction (returns 5-16 km from it passed). A return that fails is stamped new
``(origin, k, PUBLISHED_BASE + REJECTED_BASE + i)`` on every component carrying the label, and
is re-identified like any new stamp. The bound is a physical one, not a statistical one
(Blackman & Popoli 1999 §6.2: a maximum-speed or manoeuvre gate beside the Mahalanobis one).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import linear_sum_assignment
from sensornet.tracking.label_keys import keys_equal, keys_find, keys_isin, replace_labels
from sensornet.tracking.labels import PUBLISHED_BASE, as_labels, label_keys, new_labels
from sensornet.tracking.mixture import GaussianMixture
from sensornet.tracking.models import ConstantVelocity

REID_SCANS = 3
"""Looks a lost label is remembered (after the last scan it was published): scans of a sensor
that sees every target every scan; a rotating radar's peer passes ``REID_SCANS x revisit``
scans (``peers.estimators.GmphdEstimator``: a 10 s radar looks once in 5 scans of 2 s)."""
REID_AGE = 3
"""Scans a track must have been published in a row to be remembered when lost (the
confirmation count, tracking.labels.Confirmation ``scans``): a birth or clutter track that is
published for a scan or two and gone is not a target to re-identify."""
REID_GATE = 26.0
"""Squared Mahalanobis gate of a (new track, lost track predicted forward) pair (the fusion's
label gate, peers.labelling.LABEL_GATE)."""
REID_JUMP = 3000.0
"""Metres a label's track may lie from its last published position predicted forward when
the label returns after a dark scan or is re-identified. Chosen on the Paris training hour
(12:00-13:00 UTC, 8 radar peers, docs/real-traffic.md): of 4,250 returns to the same aircraft
99.9 % were within 3.2 km (median 0.2 km), every one of the 35 that returned on another
aircraft 3.5-16 km away."""
REJECTED_BASE = 1 << 20
"""Index offset (above :data:`PUBLISHED_BASE`) of the stamp a rejected return takes, apart
from the publication's stamps of the same scan (small offsets)."""
POSITION = (0, 2)
"""The position entries of the CV state ``[x, vx, y, vy]``."""


def _tracks(labels: np.ndarray, mix: GaussianMixture, on: np.ndarray
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The published labels (unique, sorted by key) with the heaviest published component's
    mean and covariance: ``(t, 3)``, ``(t, d)``, ``(t, d, d)``."""
    rows = on.nonzero()[0]
    if len(rows) > 1:  # (one published component, the usual case: itself)
        sub = labels[rows]
        keys = label_keys(sub)
        order = np.lexsort((-mix.weights[rows], *_columns(sub)))
        first = np.ones(len(order), dtype=bool)
        first[1:] = ~keys_equal(keys[order[1:]], keys[order[:-1]])
        rows = rows[order[first]]
    return labels[rows], mix.means[rows], mix.covs[rows]


def _columns(labels: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The columns of ``labels (n, 3)`` as :func:`numpy.lexsort` keys, last one first: a
    lexsort on them orders rows as :func:`label_keys` sort (by origin, birth, index), without
    NumPy's Python compare of structured keys."""
    return labels[:, 2], labels[:, 1], labels[:, 0]


def _key_order(labels: np.ndarray) -> np.ndarray:
    """``np.argsort(label_keys(labels))`` for labels each once (stable: the same order)."""
    return np.lexsort(_columns(labels))


@dataclass
class Reidentification:
    """The memory of one peer (see the module docstring). ``origin`` is the peer's label
    origin: a label ``(origin, k, PUBLISHED_BASE + i)`` seen at scan ``k`` is one stamped new
    by :class:`tracking.labels.Publication` at that scan, the only ones re-identified."""

    motion: ConstantVelocity
    origin: int
    shared: int | None = None
    """The origin of labels all peers make alike (``Publication.shared``): a label ``(shared,
    k, PUBLISHED_BASE + i)`` seen at scan ``k`` was stamped new too; None: none."""
    scans: int = REID_SCANS
    gate: float = REID_GATE
    age: int = REID_AGE
    jump: float | None = REID_JUMP
    """Metres (module docstring, :data:`REID_JUMP`); None: no bound (the gate alone)."""
    _on: tuple = field(default=None, init=False, repr=False)
    """The last scan's published tracks: (scan, labels, means, covs, scans published in a
    row, the labels' keys)."""
    _lost: tuple = field(default=None, init=False, repr=False)
    """Lost tracks: (labels (l, 3), last published scan (l,), means, covs)."""
    _last: tuple = field(default=None, init=False, repr=False)
    """Each label still carried by a component: (labels (s, 3) sorted by key, their keys, the
    scan it was last published (s,), its mean then (s, d))."""

    def __post_init__(self) -> None:
        if self.jump is not None and not self.jump > 0:
            raise ValueError(f"Reidentification.jump must be positive or None, got {self.jump}")

    def apply(self, labels: np.ndarray, mix: GaussianMixture, threshold: float,
              k: int) -> np.ndarray:
        """The labels of ``mix`` at scan ``k`` (after :meth:`Publication.stamp`), a track
        stamped new at ``k`` that gates a lost track relabelled with the lost label (every
        component carrying it); remembers what is published (weight above ``threshold``)."""
        labels = as_labels(labels, len(mix))
        on = mix.weights > threshold
        lab, m, P = _tracks(labels, mix, on)
        mine = lab[:, 0] == self.origin
        if self.shared is not None:
            mine |= lab[:, 0] == self.shared
        new = mine & (lab[:, 1] == k) & (lab[:, 2] >= PUBLISHED_BASE)
        if self._unchanged(lab, new, k):
            return self._same_tracks(labels, lab, m, P, k)
        if self.jump is not None and self._last is not None and not new.all():
            labels, lab, new = self._returns(labels, lab, m, P, new, k)
        if new.any():
            self._forget(lab, m[~new], P[~new], k)
            if self._lost is not None and len(self._lost[0]):
                labels, lab = self._match(labels, lab, m, P, new, k)
        else:  # nothing stamped new (the usual case): every track is one of the others
            self._forget(lab, m, P, k)
        own = label_keys(lab)
        if self.jump is not None:
            self._remember(labels, lab, own, m, k)
        run = np.ones(len(lab), dtype=np.int64)
        if self._on is not None and self._on[0] == k - 1 and len(lab) and len(self._on[1]):
            keys0, run0 = self._on[5], self._on[4]
            if len(keys0) > 1:  # (one track, the usual case: sorted as it is)
                by = _key_order(self._on[1])
                keys0, run0 = keys0[by], run0[by]
            was, pos = keys_find(keys0, own)
            run[was] += run0[pos[was]]
        self._on = (int(k), lab, m, P, run, own)
        return labels

    def _unchanged(self, lab: np.ndarray, new: np.ndarray, k: int) -> bool:
        """Whether the published labels ``lab`` (sorted by key, :func:`_tracks`) are the
        last scan's, none stamped new: :meth:`_same_tracks` applies."""
        on0 = self._on
        return (on0 is not None and on0[0] == k - 1 and lab.shape == on0[1].shape
                and not new.any() and np.array_equal(lab, on0[1]))

    def _same_tracks(self, labels: np.ndarray, lab: np.ndarray, m: np.ndarray,
                     P: np.ndarray, k: int) -> np.ndarray:
        """:meth:`apply` when the published labels ``lab`` are the last scan's, none stamped
        new (the usual scan of a 50-peer network; issue 33): nothing returns (each label was
        published at ``k - 1``), no track is lost, so :meth:`_returns`, the lost set's
        update when it is empty and the run's key lookup are skipped, and with no dark label
        remembered the last-published memory is the published tracks as they are (sorted
        already); the same labels and memory as the general path, to the bit
        (tests/test_reid_fast_paths.py)."""
        if self._lost is None or len(self._lost[0]):  # (empty: _forget keeps it as it is)
            self._forget(lab, m, P, k)
        own = label_keys(lab)
        if self.jump is not None and len(self._last[0]) == len(lab):  # no dark label held:
            self._last = (lab, own, np.full(len(lab), k), m)  # the published ones (sorted)
        elif self.jump is not None:
            self._remember(labels, lab, own, m, k)
        self._on = (int(k), lab, m, P, self._on[4] + 1, own)
        return labels

    @staticmethod
    def same_many(reids: list[Reidentification], labels: list[np.ndarray],
                  mixes: list[GaussianMixture], thresholds: list[float],
                  ks: list[int]) -> list[tuple | None]:
        """:meth:`apply` of many peers' steps at once where it takes :meth:`_same_tracks`
        and that changes only the memory of the tracks (the usual scan: the published labels
        the last scan's, none stamped new; the lost set and dark labels kept as
        :meth:`_forget` and :meth:`_remember` keep them): per problem the memory ``(_on,
        _last, _lost)`` apply leaves (the same arrays' values), for :meth:`take_same`; None
        where apply must run. The published tracks of every problem
        (:func:`_tracks`) come from one sort keyed by the problem first (issues 33/38)."""
        P = len(reids)
        out: list[tuple | None] = [None] * P
        if not P:
            return out
        w = np.concatenate([mx.weights for mx in mixes])
        n = np.array([len(mx) for mx in mixes], dtype=np.int64)
        prob = np.repeat(np.arange(P), n)
        starts = np.concatenate(([0], np.cumsum(n)))
        lab = np.concatenate(labels).astype(np.int64, copy=False)
        rows = np.flatnonzero(w > np.asarray(thresholds, dtype=float)[prob])
        pr, sub = prob[rows], lab[rows]
        order = np.lexsort((-w[rows], sub[:, 2], sub[:, 1], sub[:, 0], pr))
        s, sp = sub[order], pr[order]
        first = np.ones(len(rows), dtype=bool)
        first[1:] = (s[1:] != s[:-1]).any(axis=1) | (sp[1:] != sp[:-1])
        rows, tp = rows[order[first]], sp[first]
        means = np.concatenate([mx.means for mx in mixes])[rows]
        covs = np.concatenate([mx.covs for mx in mixes])[rows]
        tl = lab[rows]
        cut = np.searchsorted(tp, np.arange(P + 1))
        for i, r in enumerate(reids):
            on0, k = r._on, int(ks[i])
            a, b = cut[i], cut[i + 1]
            li = tl[a:b]
            if on0 is None or on0[0] != k - 1 or li.shape != on0[1].shape:
                continue
            mine = li[:, 0] == r.origin
            if r.shared is not None:
                mine |= li[:, 0] == r.shared
            if (mine & (li[:, 1] == k) & (li[:, 2] >= PUBLISHED_BASE)).any():
                continue
            if not np.array_equal(li, on0[1]):
                continue
            own = label_keys(li)
            m, C = means[a:b], covs[a:b]
            if r.jump is None:
                last = r._last
            elif len(r._last[0]) == len(li):  # no dark label held: the published ones
                last = (li, own, np.full(len(li), k), m)
            else:  # dark labels held: those still carried kept (_remember)
                last = r._remembered(lab[starts[i]:starts[i + 1]], li, own, m, k)
            lost = r._lost  # _forget's: none of the last scan's tracks lost (the same ones
            if lost is None:  # published), an empty set of their shapes, or old ones dropped
                none = np.zeros(len(on0[1]), dtype=bool)
                lost = (on0[1][none], np.full(0, on0[0]), on0[2][none], on0[3][none])
            elif len(lost[0]):
                keep = (k - lost[1] <= r.scans) & ~keys_isin(label_keys(lost[0]), own)
                lost = tuple(x[keep] for x in lost)
            out[i] = ((k, li, m, C, on0[4] + 1, own), last, lost)
        return out

    def take_same(self, state: tuple) -> None:
        """:meth:`apply` where :meth:`same_many` prepared its memory ``state``."""
        self._on, self._last, self._lost = state

    def _returns(self, labels, lab, m, P, new, k):
        """Published tracks (not stamped new) more than ``jump`` from their label's last
        published position predicted to ``k`` (means ``m``, covariances ``P``), where the label
        was dark at the last scan, or published then and the track now gates a track of the
        last scan whose label is gone (a merge took that track's label): stamped new (on every
        component carrying the label) and marked ``new``."""
        L, keys, K, M = self._last
        if not len(keys) or not len(lab):  # nothing published yet (or left): nothing returns
            return labels, lab, new
        own = label_keys(lab)
        found, pos = keys_find(keys, own)
        known = ~new & found
        rows = np.flatnonzero(known)
        if not len(rows):
            return labels, lab, new
        gone = None
        if self._on is not None and self._on[0] == k - 1:
            k0, lab0, m0, P0, _, keys0 = self._on
            gone = np.flatnonzero(~keys_isin(keys0, own))
            if not len(gone):  # no track of the last scan lost its label: only labels dark
                rows = rows[K[pos[rows]] < k - 1]  # then may return far (the usual case:
                if not len(rows):                  # none, and no distance to compute)
                    return labels, lab, new
        far = self._distance(m[rows], K[pos[rows]], M[pos[rows]], k, pairs=False) > self.jump
        rows = rows[far]
        if len(rows) and gone is not None and len(gone):
            took = (self._costs(m[rows], P[rows], lab0[gone], np.full(len(gone), k0),
                                m0[gone], P0[gone], k) <= self.gate).any(axis=1)
            rows = rows[(K[pos[rows]] < k - 1) | took]
        if not len(rows):
            return labels, lab, new
        stamp = new_labels(self.origin, k, len(rows), PUBLISHED_BASE + REJECTED_BASE)
        labels = replace_labels(labels, lab[rows], stamp)
        lab = lab.copy()
        lab[rows] = stamp
        new = new.copy()
        new[rows] = True
        return labels, lab, new

    def _remember(self, labels: np.ndarray, lab: np.ndarray, own: np.ndarray, m: np.ndarray,
                  k: int) -> None:
        """The last published scan and mean of each label: the published ones ``lab`` (their
        keys ``own``), ``m`` at ``k``; the others as before while a component of ``labels``
        still carries them."""
        self._last = self._remembered(labels, lab, own, m, k)

    def _remembered(self, labels: np.ndarray, lab: np.ndarray, own: np.ndarray,
                    m: np.ndarray, k: int) -> tuple:
        """The memory :meth:`_remember` leaves (without setting it: :meth:`same_many`)."""
        L, K, M = lab, np.full(len(lab), k), m
        if self._last is not None:
            L0, keys, K0, M0 = self._last
            keep = keys_isin(keys, label_keys(labels)) & ~keys_isin(keys, own)
            if keep.any():
                L, K, M = (np.concatenate(x) for x in ((L, L0[keep]), (K, K0[keep]),
                                                       (M, M0[keep])))
        if len(L) > 1:
            by = _key_order(L)
            L, K, M = L[by], K[by], M[by]
        return L, label_keys(L), K, M

    def _transitions(self, gaps: np.ndarray, which: int = 2) -> list[np.ndarray]:
        """The CV transitions ``F (l, d, d)`` and (``which`` 2) ``Q (l, d, d)`` over ``gaps
        (l,)`` scans (l > 0), as contiguous stacks of :meth:`ConstantVelocity.transition`'s;
        one gap for all (the usual case: every track last published the scan before) without
        np.unique."""
        if (gaps == gaps[0]).all():
            FQ = self.motion.transition(int(gaps[0]))
            return [np.repeat(a[None], len(gaps), axis=0) for a in FQ[:which]]
        steps, inv = np.unique(gaps, return_inverse=True)
        FQ = [self.motion.transition(int(s)) for s in steps]  # <= scans + 1 distinct gaps
        return [np.stack([fq[i] for fq in FQ])[inv] for i in range(which)]

    def _distance(self, m, K, M, k, pairs=True) -> np.ndarray:
        """Metres from tracks' positions ``m (n, d)`` to means ``M (l, d)`` last published at
        scans ``K (l,)`` predicted to ``k`` (CV): ``(n, l)``, or ``(n,)`` row by row if not
        ``pairs``."""
        (F,) = self._transitions(k - K, which=1)
        mp = np.einsum("lij,lj->li", F, M)[:, POSITION]
        x = m[:, POSITION]
        d = x[:, None, :] - mp[None] if pairs else x - mp
        return np.sqrt(np.einsum("...i,...i->...", d, d))

    def _forget(self, lab: np.ndarray, m: np.ndarray, P: np.ndarray, k: int) -> None:
        """Move the last scan's published tracks that are not published now into the lost
        set, unless a track published now and not stamped new (``m``, ``P``) gates one: its
        label was replaced (the network rule), not its track lost. Drop lost tracks published
        again or older than ``scans``."""
        parts = [] if self._lost is None else [self._lost]
        if self._on is not None:
            k0, lab0, m0, P0, run0, keys0 = self._on
            gone = run0 >= self.age
            if gone.any():
                gone &= ~keys_isin(keys0, label_keys(lab))
            if gone.any() and len(m):
                g = np.flatnonzero(gone)
                gone[g[(self._costs(m, P, lab0[g], np.full(len(g), k0), m0[g], P0[g], k)
                        <= self.gate).any(axis=0)]] = False
            if gone.any():
                parts.append((lab0[gone], np.full(int(gone.sum()), k0), m0[gone], P0[gone]))
            elif self._lost is None:  # nothing lost yet: an empty set of the tracks' shapes
                parts.append((lab0[gone], np.full(0, k0), m0[gone], P0[gone]))
        if not parts:
            return
        if not any(len(part[0]) for part in parts):  # nothing lost (the usual case)
            self._lost = parts[-1]
            return
        L, K, M, C = (np.concatenate(x) for x in zip(*parts, strict=True))
        keep = (k - K <= self.scans) & ~keys_isin(label_keys(L), label_keys(lab))
        self._lost = (L[keep], K[keep], M[keep], C[keep])

    def _costs(self, m, P, L, K, M, C, k) -> np.ndarray:
        """Squared Mahalanobis distances ``(n, l)`` of tracks ``m (n, d)``, ``P (n, d, d)`` at
        scan ``k`` to lost tracks (last published at scans ``K (l,)``, ``M``, ``C``)
        predicted to ``k``, in one stacked solve."""
        F, Q = self._transitions(k - K)
        mp = np.einsum("lij,lj->li", F, M)
        Pp = F @ C @ F.swapaxes(1, 2) + Q
        diff = m[:, None, :] - mp[None, :, :]  # (n, l, d)
        S = P[:, None] + Pp[None, :]
        return np.einsum("nli,nli->nl", diff, np.linalg.solve(S, diff[..., None])[..., 0])

    def _match(self, labels, lab, m, P, new, k):
        L, K, M, C = self._lost
        ni = np.flatnonzero(new)
        cost = self._costs(m[ni], P[ni], L, K, M, C, k)
        if self.jump is not None:
            cost[self._distance(m[ni], K, M, k) > self.jump] = np.inf
        r, c = linear_sum_assignment(np.minimum(cost, self.gate))
        ok = cost[r, c] <= self.gate
        r, c = r[ok], c[ok]
        if not len(r):
            return labels, lab
        back = L[c]
        labels = replace_labels(labels, lab[ni[r]], back)
        lab = lab.copy()
        lab[ni[r]] = back
        gone = np.ones(len(L), dtype=bool)
        gone[c] = False
        self._lost = (L[gone], K[gone], M[gone], C[gone])
        return labels, lab


__all__ = ["REID_GATE", "REID_JUMP", "REID_SCANS", "Reidentification"]
