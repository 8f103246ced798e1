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
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import linear_sum_assignment
from sensornet.tracking.labels import PUBLISHED_BASE, as_labels, label_keys
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


def _tracks(labels: np.ndarray, mix: GaussianMixture, on: np.ndarray
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The published labels (unique, sorted by key) with the heaviest published component's
    mean and covariance: ``(t, 3)``, ``(t, d)``, ``(t, d, d)``."""
    idx = np.flatnonzero(on)
    keys = label_keys(labels[idx])
    order = np.lexsort((-mix.weights[idx], keys))
    first = np.ones(len(order), dtype=bool)
    first[1:] = keys[order[1:]] != keys[order[:-1]]
    rows = idx[order[first]]
    return labels[rows], mix.means[rows], mix.covs[rows]


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
    _on: tuple = field(default=None, init=False, repr=False)
    """The last scan's published tracks: (scan, labels, means, covs, scans published in a
    row)."""
    _lost: tuple = field(default=None, init=False, repr=False)
    """Lost tracks: (labels (l, 3), last published scan (l,), means, covs)."""

    def apply(self, labels: np.ndarray, mix: GaussianMixture, threshold: float,
              k: int) -> np.ndarray:
        """The labels of ``mix`` at scan ``k`` (after :meth:`Publication.stamp`), a track
        stamped new at ``k`` that gates a lost track relabelled with the lost label (every
        component carrying it); remembers what is published (weight above ``threshold``)."""
        labels = as_labels(labels, len(mix))
        on = mix.weights > threshold
        lab, m, P = _tracks(labels, mix, on)
        mine = np.isin(lab[:, 0], [o for o in (self.origin, self.shared) if o is not None])
        new = mine & (lab[:, 1] == k) & (lab[:, 2] >= PUBLISHED_BASE)
        self._forget(lab, m[~new], P[~new], k)
        if self._lost is not None and len(self._lost[0]) and new.any():
            labels, lab = self._match(labels, lab, m, P, new, k)
        run = np.ones(len(lab), dtype=np.int64)
        if self._on is not None and self._on[0] == k - 1 and len(lab) and len(self._on[1]):
            k0 = label_keys(self._on[1])
            by = np.argsort(k0)
            keys = label_keys(lab)
            pos = np.searchsorted(k0[by], keys).clip(max=len(k0) - 1)
            was = k0[by][pos] == keys
            run[was] += self._on[4][by][pos[was]]
        self._on = (int(k), lab, m, P, run)
        return labels

    def _forget(self, lab: np.ndarray, m: np.ndarray, P: np.ndarray, k: int) -> None:
        """Move the last scan's published tracks that are not published now into the lost
        set, unless a track published now and not stamped new (``m``, ``P``) gates one: its
        label was replaced (the network rule), not its track lost. Drop lost tracks published
        again or older than ``scans``."""
        parts = [] if self._lost is None else [self._lost]
        if self._on is not None:
            k0, lab0, m0, P0, run0 = self._on
            gone = ~np.isin(label_keys(lab0), label_keys(lab)) & (run0 >= self.age)
            if gone.any() and len(m):
                g = np.flatnonzero(gone)
                gone[g[(self._costs(m, P, lab0[g], np.full(len(g), k0), m0[g], P0[g], k)
                        <= self.gate).any(axis=0)]] = False
            parts.append((lab0[gone], np.full(int(gone.sum()), k0), m0[gone], P0[gone]))
        if not parts:
            return
        L, K, M, C = (np.concatenate(x) for x in zip(*parts, strict=True))
        keep = (k - K <= self.scans) & ~np.isin(label_keys(L), label_keys(lab))
        self._lost = (L[keep], K[keep], M[keep], C[keep])

    def _costs(self, m, P, L, K, M, C, k) -> np.ndarray:
        """Squared Mahalanobis distances ``(n, l)`` of tracks ``m (n, d)``, ``P (n, d, d)`` at
        scan ``k`` to lost tracks (last published at scans ``K (l,)``, ``M``, ``C``)
        predicted to ``k``, in one stacked solve."""
        steps, inv = np.unique(k - K, return_inverse=True)
        FQ = [self.motion.transition(int(s)) for s in steps]  # <= scans + 1 distinct gaps
        F = np.stack([f for f, _ in FQ])[inv]
        Q = np.stack([q for _, q in FQ])[inv]
        mp = np.einsum("lij,lj->li", F, M)
        Pp = F @ C @ F.swapaxes(1, 2) + Q
        diff = m[:, None, :] - mp[None, :, :]  # (n, l, d)
        S = P[:, None] + Pp[None, :]
        return np.einsum("nli,nli->nl", diff, np.linalg.solve(S, diff[..., None])[..., 0])

    def _match(self, labels, lab, m, P, new, k):
        L, K, M, C = self._lost
        ni = np.flatnonzero(new)
        cost = self._costs(m[ni], P[ni], L, K, M, C, k)
        r, c = linear_sum_assignment(np.minimum(cost, self.gate))
        ok = cost[r, c] <= self.gate
        r, c = r[ok], c[ok]
        if not len(r):
            return labels, lab
        old, back = label_keys(lab[ni[r]]), L[c]
        keys = label_keys(labels)
        by = np.argsort(old)
        pos = np.searchsorted(old[by], keys).clip(max=len(old) - 1)
        hit = old[by][pos] == keys
        labels = labels.copy()
        labels[hit] = back[by][pos[hit]]
        lab = lab.copy()
        lab[ni[r]] = back
        gone = np.ones(len(L), dtype=bool)
        gone[c] = False
        self._lost = (L[gone], K[gone], M[gone], C[gone])
        return labels, lab


__all__ = ["REID_GATE", "REID_SCANS", "Reidentification"]
