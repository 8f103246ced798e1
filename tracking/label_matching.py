"""Labels across peers: :func:`match_labels` pairs a neighbour's tracks with ours and
:func:`adopt_labels` applies the network rule (earliest birth, then lowest origin, wins).

Split from :mod:`tracking.labels` (issue 37), whose docstring gives the rules.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment
from sensornet.tracking.label_keys import (
    as_labels,
    keys_equal,
    keys_isin,
    label_keys,
    precedes,
    replace_labels,
)


@dataclass(frozen=True)
class LabelMatch:
    """Matched track pairs of two peers: ``own (p, 3)`` and ``nbr (p, 3)`` labels, ``cost
    (p,)`` their squared Mahalanobis distances (each at most the gate); a pair whose cost is
    :data:`RELEASE` is a release (:func:`adopt_labels`)."""

    own: np.ndarray
    nbr: np.ndarray
    cost: np.ndarray

    def __len__(self) -> int:
        return int(self.cost.shape[0])

    def as_dict(self) -> dict[tuple[int, int, int], tuple[int, int, int]]:
        """Neighbour label -> own label, as tuples."""
        return {tuple(b): tuple(a) for a, b in zip(self.own.tolist(), self.nbr.tolist(),
                                                    strict=True)}


def _unique_labels(labels: np.ndarray, what: str) -> None:
    s = labels[np.lexsort(labels.T)]  # rows sorted: a repeat is two equal neighbours
    if (s[1:] == s[:-1]).all(axis=1).any():  # (np.unique on label_keys: 7x the time)
        raise ValueError(f"{what} repeats a label; match tracks (one label each), not components")


def match_labels(own_labels: np.ndarray, own_means: np.ndarray, own_covs: np.ndarray,
                 nbr_labels: np.ndarray, nbr_means: np.ndarray, nbr_covs: np.ndarray,
                 gate: float) -> LabelMatch:
    """Pair a neighbour's tracks with ours: ``linear_sum_assignment`` on ``C_ij =
    (m_i - n_j)^T (P_i + Q_j)^-1 (m_i - n_j)`` (``(a, b)``, built in one stacked solve), pairs
    with ``C_ij > gate`` left unmatched (their cost capped at the gate inside the assignment).

    own_*: ``(a, 3)`` labels, ``(a, d)`` means, ``(a, d, d)`` covs; nbr_*: ``(b, ...)``
    likewise. Labels must be unique on each side (tracks, not components).
    """
    own_means = np.asarray(own_means, dtype=float)
    nbr_means = np.asarray(nbr_means, dtype=float)
    a, b = len(own_means), len(nbr_means)
    own_labels = as_labels(own_labels, a, "own_labels")
    nbr_labels = as_labels(nbr_labels, b, "nbr_labels")
    d = own_means.shape[1] if own_means.ndim == 2 else 0
    own_covs = np.asarray(own_covs, dtype=float)
    nbr_covs = np.asarray(nbr_covs, dtype=float)
    if a and own_covs.shape != (a, d, d):
        raise ValueError(f"own_covs has shape {own_covs.shape}, expected {(a, d, d)}")
    if b and (nbr_means.shape[1] != d or nbr_covs.shape != (b, d, d)):
        raise ValueError(f"nbr_means/nbr_covs have shapes {nbr_means.shape}/{nbr_covs.shape}, "
                         f"expected ({b}, {d})/({b}, {d}, {d})")
    if not gate > 0:
        raise ValueError(f"gate must be positive, got {gate}")
    _unique_labels(own_labels, "own_labels")
    _unique_labels(nbr_labels, "nbr_labels")
    none = np.zeros((0, 3), dtype=np.int64)
    if a == 0 or b == 0:
        return LabelMatch(none, none.copy(), np.zeros(0))
    diff = own_means[:, None, :] - nbr_means[None, :, :]  # (a, b, d)
    # a pair is solved only if it can pass the gate: C_ij >= |diff|^2 / lambda_max(P_i + Q_j)
    # >= |diff|^2 / (tr P_i + tr Q_j), so the rest cost more than the gate (capped to it below,
    # as they would be): the same assignment, one solve per nearby pair instead of all a x b
    trace = np.trace(own_covs, axis1=1, axis2=2)[:, None] + np.trace(nbr_covs, axis1=1, axis2=2)
    near = np.einsum("abi,abi->ab", diff, diff) <= gate * trace
    cost = np.full((a, b), np.inf)
    ii, jj = np.nonzero(near)
    dn = diff[ii, jj]
    cost[ii, jj] = np.einsum("pi,pi->p", dn, np.linalg.solve(own_covs[ii] + nbr_covs[jj],
                                                           dn[..., None])[..., 0])
    rows, cols = linear_sum_assignment(np.minimum(cost, gate))
    ok = cost[rows, cols] <= gate
    rows, cols = rows[ok], cols[ok]
    return LabelMatch(own_labels[rows], nbr_labels[cols], cost[rows, cols])


def adopt_labels(labels: np.ndarray, match: LabelMatch) -> np.ndarray:
    """The network-wide label rule: for every matched pair, components labelled with our label
    take the smaller of the two in ``(birth_scan, origin, index)`` order. ``labels (n, 3)``
    (a whole mixture's or a track list's) -> ``(n, 3)``. A pair whose winning label already
    marks one of our other components is left unchanged (two of our targets would share it).
    The rule picks the same label on both peers, so fusing A into B and B into A agree.

    A *release* pair (cost :data:`RELEASE`, made by ``peers.labelling.label_fused``): our label
    is replaced by the pair's label whatever the order says, unless that label is already ours
    (a label two targets held: ours lost it to the heavier fused component, docs/real-traffic.md
    "The fused LMB's switches")."""
    labels = as_labels(labels)
    if len(match) == 0 or len(labels) == 0:
        return labels
    rel = np.asarray(match.cost) == RELEASE
    if rel.any():
        out = adopt_labels(labels, LabelMatch(match.own[~rel], match.nbr[~rel],
                                              np.asarray(match.cost)[~rel]))
        return _release(out, as_labels(match.own[rel]), as_labels(match.nbr[rel]))
    win = np.where(precedes(match.nbr, match.own)[:, None], match.nbr, match.own)
    change = ~keys_equal(label_keys(win), label_keys(match.own))
    own_keys, win_keys = label_keys(match.own)[change], label_keys(win)[change]
    keys = label_keys(labels)
    clash = keys_isin(win_keys, keys[~keys_isin(keys, own_keys)])
    own_keys, win_keys = own_keys[~clash], win_keys[~clash]
    if own_keys.size == 0:
        return labels
    return replace_labels(labels, match.own[change][~clash], win[change][~clash])


def _release(labels: np.ndarray, own: np.ndarray, new: np.ndarray) -> np.ndarray:
    """``labels (n, 3)`` with each of ``own (r, 3)`` replaced by its ``new (r, 3)`` on every
    row carrying it, except where the new label is already among ``labels``."""
    keys = label_keys(labels)
    ok = ~keys_isin(label_keys(new), keys)
    return replace_labels(labels, own[ok], new[ok])


RELEASE = -1.0
"""The cost that marks a release pair in a :class:`LabelMatch` (real pairs' costs are >= 0)."""


__all__ = ["RELEASE", "LabelMatch", "adopt_labels", "match_labels"]
