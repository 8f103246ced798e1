"""A young fused track is held back while its target's stamp of a scan before may still come
(issue 33, docs/labelled-tracking.md, "One target, two stamps a scan apart").

At Pd 0.9 a peer's first publication of a target often has no neighbour's track beside it, so
its stamp ``(o, s, i)`` moves to ``(o, s + 1, i)`` (peers.labelling.corroborated,
peers.stamp_moves), while a peer that stamped the same ``(o, s, i)`` elsewhere (the same birth
cell, ``tracking.label_keys.cell_index``) keeps it. The earliest stamp wins the label rule at
every peer but spreads one hop a scan, so the peers near the mover first report the target
under the moved stamp and then change its id: in OSPA(2) a second track of the target for the
whole window ("dup"). Traced on 20 peers' training runs: the two labels are never two fused
tracks at once; the first stamp was in the peer's fused density a scan or two before (a small
weight, from a neighbour) and is gone when the moved one comes. Whether it comes back (another
stamper kept it) no peer near the mover can know yet, and reporting the row under it loses
when it does not (tried: Pd 0.99 training runs worse); a scan or two of lateness costs OSPA(2)
less than a switch.

:class:`StampTwins` remembers each young label of a peer's fused density for ``memory`` scans;
an extracted row whose label is at most ``young`` scans old is not reported while a present or
remembered label of the same origin and index, born 1 to ``young`` scans earlier, lies within
``gate`` of it, the two paired by assignment (SciPy ``linear_sum_assignment``; one twin per row
and row per twin) on the squared Mahalanobis distance ``(x - m)' (P + S)^-1 (x - m)`` (the
track-to-track test of Y. Bar-Shalom, "On the track-to-track correlation problem", IEEE TAC
26(2), 1981, without the cross-covariance). The fused density, its labels and the label rule
are unchanged, so every peer applies it alike and the target is reported (under the label that
won) at most ``young`` scans later; a miss at an input never removes a row here.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import linear_sum_assignment
from sensornet.tracking.gaussian import inv_spd
from sensornet.tracking.label_keys import keys_isin, label_keys


def check_hold(gate: float, **scans: tuple[int, int]) -> None:
    """A one-line ValueError for a hold rule's options (this module's and
    :mod:`tracking.held_ids`): each of ``scans`` ``name=(value, least)`` a number of scans at
    least its least, ``gate`` (a squared Mahalanobis distance) positive and finite."""
    bad = {name: (v, least) for name, (v, least) in scans.items() if v < least}
    if bad:
        raise ValueError(" and ".join(f"{n} must be >= {least}" for n, (_, least) in bad.items())
                         + " scans, got " + " and ".join(str(v) for v, _ in bad.values()))
    if not 0 < gate < np.inf:
        raise ValueError(f"gate must be positive and finite, got {gate}")


@dataclass
class StampTwins:
    """A peer's memory of young fused labels and the hold rule of the module docstring. One
    per peer; call :meth:`held` once per scan with the scan's fused density and its extracted
    rows. ``young``: the oldest row (scans since its label's birth scan) held, and the most
    scans its twin may be born earlier; ``memory``: scans a label is remembered after the
    density last held it; ``gate``: the squared Mahalanobis distance of a row and its twin."""

    young: int = 2
    memory: int = 2
    gate: float = 26.0
    labels: np.ndarray = field(default_factory=lambda: np.zeros((0, 3), dtype=np.int64),
                               repr=False)
    seen: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64), repr=False)
    means: np.ndarray | None = field(default=None, repr=False)
    covs: np.ndarray | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        check_hold(self.gate, young=(self.young, 1), memory=(self.memory, 0))

    def held(self, k: int, ids: np.ndarray, states: np.ndarray, covs: np.ndarray,
             labels: np.ndarray, weights: np.ndarray, means: np.ndarray, fcovs: np.ndarray
             ) -> np.ndarray:
        """``(p,) bool``: which of the extracted rows ``ids (p, 3)``, ``states (p, d)``, ``covs
        (p, d, d)`` of scan ``k`` are held back (module docstring), given the fused density's
        ``labels (n, 3)``, ``weights (n,)``, ``means (n, d)``, ``fcovs (n, d, d)``; then
        remembers the density's young labels (a label of several components by its
        heaviest)."""
        ids = np.asarray(ids, dtype=np.int64).reshape(-1, 3)
        labels = np.asarray(labels, dtype=np.int64).reshape(-1, 3)
        w, M, F = (np.asarray(weights, dtype=float), np.asarray(means, dtype=float),
                   np.asarray(fcovs, dtype=float))
        X, P = np.asarray(states, dtype=float), np.asarray(covs, dtype=float)
        p, n, d = len(ids), len(labels), M.shape[-1]
        if not p:  # nothing extracted: only remembered
            X, P = X.reshape(0, d), P.reshape(0, d, d)
        if (X.shape != (p, d) or P.shape != (p, d, d) or w.shape != (n,) or M.shape != (n, d)
                or F.shape != (n, d, d)):
            raise ValueError(f"rows: ids (p, 3), states (p, d), covs (p, d, d); density: labels "
                             f"(n, 3), weights (n,), means (n, d), covs (n, d, d); got "
                             f"{ids.shape}, {X.shape}, {P.shape}, {labels.shape}, {w.shape}, "
                             f"{M.shape}, {F.shape}")
        C_lab, C_m, C_P, seen = self._candidates(k, labels, w, M, F)
        out = np.zeros(p, dtype=bool)
        rows = np.flatnonzero(k - ids[:, 1] <= self.young)
        if len(rows) and len(C_lab):
            j, c = (a.ravel() for a in np.meshgrid(rows, np.arange(len(C_lab)), indexing="ij"))
            gap = ids[j, 1] - C_lab[c, 1]
            ok = ((ids[j, 0] == C_lab[c, 0]) & (ids[j, 2] == C_lab[c, 2]) & (gap >= 1)
                  & (gap <= self.young))
            j, c = j[ok], c[ok]
            if len(j):
                dx = X[j] - C_m[c]
                d2 = np.einsum("nd,nde,ne->n", dx, inv_spd(P[j] + C_P[c]), dx)
                near = np.isfinite(d2) & (d2 <= self.gate)
                j, c, d2 = j[near], c[near], d2[near]
            if len(j):  # one twin per row and one row per twin (two targets, two labels)
                r_, ri = np.unique(j, return_inverse=True)
                c_, ci = np.unique(c, return_inverse=True)
                cost = np.full((len(r_), len(c_)), 2.0 * self.gate)
                cost[ri, ci] = d2
                r, q = linear_sum_assignment(cost)
                out[r_[r[cost[r, q] <= self.gate]]] = True
        # remember the labels young enough to be a twin at the next scan (born at most 2
        # young scans before it), each until memory scans after the density last held it
        keep = (k + 1 - C_lab[:, 1] <= 2 * self.young) & (k + 1 - seen <= self.memory)
        self.labels, self.seen = C_lab[keep], seen[keep]
        self.means, self.covs = C_m[keep], C_P[keep]
        return out

    def _candidates(self, k: int, labels: np.ndarray, weights: np.ndarray, means: np.ndarray,
                    covs: np.ndarray) -> tuple[np.ndarray, ...]:
        """The labels a young row's twin at scan ``k`` may carry, each once, born at most ``2
        young`` scans before ``k``: the density's (a label of several components by its
        heaviest) and the remembered ones it no longer holds, last held at most ``memory``
        scans before ``k``; with their means, covariances and the scan last held."""
        young = np.flatnonzero(k - labels[:, 1] <= 2 * self.young)
        lab = labels[young]
        if len(lab) > 1:  # by label (int columns), heaviest first; then each label's first
            order = np.lexsort((-weights[young], lab[:, 2], lab[:, 1], lab[:, 0]))
            s = lab[order]
            first = np.concatenate(([True], (s[1:] != s[:-1]).any(axis=1)))
            young = young[order[first]]
            lab = labels[young]
        m, P = means[young], covs[young]
        seen = np.full(len(lab), k, dtype=np.int64)
        if len(self.labels):
            old = (k - self.seen <= self.memory) & ~keys_isin(label_keys(self.labels),
                                                              label_keys(labels))
            if old.any():
                lab = np.concatenate([lab, self.labels[old]])
                m = np.concatenate([m, self.means[old]])
                P = np.concatenate([P, self.covs[old]])
                seen = np.concatenate([seen, self.seen[old]])
        return lab, m, P, seen


__all__ = ["StampTwins"]
