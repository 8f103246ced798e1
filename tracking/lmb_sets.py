"""Labelled Bernoulli sets: an LMB's tracks with their Gaussian mixtures stored flat.

``labels (n, 3)`` int64 ``(origin, birth_scan, index)`` (:mod:`tracking.labels`),
``existence (n,)``; the components of every track in one stack: ``weights (c,)`` (summing to 1
within each track), ``means (c, d)``, ``covs (c, d, d)`` and ``owner (c,)``, the track each
component belongs to, non-decreasing, every track owning at least one. Per-track sums are
``np.add.reduceat`` over :meth:`LabelledBernoulliSet.starts`, so no loop over tracks.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from sensornet.tracking.gaussian import c_einsum, inv_spd
from sensornet.tracking.labels import as_labels, new_labels
from sensornet.tracking.mixture import GaussianMixture


@dataclass(frozen=True)
class LabelledBernoulliSet:
    """The tracks of an LMB (Reuter et al. 2014, eq. 6) with Gaussian-mixture densities.

    labels:    (n, 3) int64 ``(origin, birth_scan, index)``, unique.
    existence: (n,) in [0, 1].
    weights:   (c,) per-track normalised component weights.
    means:     (c, d); covs: (c, d, d).
    owner:     (c,) int64 track index of each component, non-decreasing, covering 0..n-1.
    """

    labels: np.ndarray
    existence: np.ndarray
    weights: np.ndarray
    means: np.ndarray
    covs: np.ndarray
    owner: np.ndarray

    def __post_init__(self) -> None:
        r = np.asarray(self.existence, dtype=float).reshape(-1)
        n = r.shape[0]
        labels = as_labels(self.labels, n, "LabelledBernoulliSet.labels")
        mix = GaussianMixture(self.weights, self.means, self.covs)  # shape checks
        owner = np.asarray(self.owner).reshape(-1)
        if owner.shape[0] != len(mix) or (owner.size and owner.dtype.kind not in "iu"):
            raise ValueError(f"LabelledBernoulliSet.owner has shape {owner.shape}, "
                             f"dtype {owner.dtype}; expected ({len(mix)},) integers")
        owner = owner.astype(np.int64)
        if not (np.isfinite(r).all() and (r >= 0).all() and (r <= 1).all()):
            raise ValueError("LabelledBernoulliSet.existence must be finite and in [0, 1]")
        if (np.diff(owner) < 0).any() or not np.array_equal(np.unique(owner), np.arange(n)):
            raise ValueError("LabelledBernoulliSet.owner must be non-decreasing and give "
                             "every track at least one component")
        for name, value in (("labels", labels), ("existence", r), ("weights", mix.weights),
                            ("means", mix.means), ("covs", mix.covs), ("owner", owner)):
            object.__setattr__(self, name, value)

    @classmethod
    def trusted(cls, labels, existence, weights, means, covs, owner) -> LabelledBernoulliSet:
        """A set from arrays the caller guarantees (no checks: filter hot paths)."""
        s = object.__new__(cls)
        for name, value in (("labels", labels), ("existence", existence), ("weights", weights),
                            ("means", means), ("covs", covs), ("owner", owner)):
            object.__setattr__(s, name, value)
        return s

    @classmethod
    def empty(cls, dim: int) -> LabelledBernoulliSet:
        return cls.trusted(np.zeros((0, 3), np.int64), np.zeros(0), np.zeros(0),
                           np.zeros((0, dim)), np.zeros((0, dim, dim)), np.zeros(0, np.int64))

    @classmethod
    def births(cls, birth: GaussianMixture, origin: int, k: int,
               start: int = 0) -> LabelledBernoulliSet:
        """One Bernoulli per component of ``birth``: ``r = weight``, density that Gaussian,
        labels ``(origin, k, start + i)``."""
        nb = len(birth)
        return cls.trusted(new_labels(origin, k, nb, start), np.clip(birth.weights, 0.0, 1.0),
                           np.ones(nb), birth.means, birth.covs, np.arange(nb, dtype=np.int64))

    @classmethod
    def concatenate(cls, sets: Sequence[LabelledBernoulliSet]) -> LabelledBernoulliSet:
        """The union of several sets' tracks, in order."""
        sets = [s for s in sets if len(s)] or list(sets[:1])
        offsets = np.cumsum([0] + [len(s) for s in sets[:-1]])
        return cls.trusted(np.concatenate([s.labels for s in sets]),
                           np.concatenate([s.existence for s in sets]),
                           np.concatenate([s.weights for s in sets]),
                           np.concatenate([s.means for s in sets]),
                           np.concatenate([s.covs for s in sets]),
                           np.concatenate([s.owner + o for s, o in zip(sets, offsets,
                                                                       strict=True)]))

    def __len__(self) -> int:
        return int(self.existence.shape[0])

    @property
    def dim(self) -> int:
        return int(self.means.shape[1])

    def starts(self) -> np.ndarray:
        """Index of each track's first component ``(n,)``."""
        return np.searchsorted(self.owner, np.arange(len(self)))

    def select(self, index: np.ndarray) -> LabelledBernoulliSet:
        """The tracks picked by a boolean mask or an index array, in that order."""
        index = np.asarray(index)
        if index.dtype == bool and index.shape == (len(self),):  # order kept: no sort
            comp = np.flatnonzero(index[self.owner])
            renumber = np.cumsum(index) - 1
            return LabelledBernoulliSet.trusted(self.labels[index], self.existence[index],
                                                self.weights[comp], self.means[comp],
                                                self.covs[comp], renumber[self.owner[comp]])
        idx = np.arange(len(self))[index]
        new = np.full(len(self), -1, dtype=np.int64)
        new[idx] = np.arange(len(idx))
        comp_owner = new[self.owner]
        comp = np.flatnonzero(comp_owner >= 0)
        comp = comp[np.argsort(comp_owner[comp], kind="stable")]
        return LabelledBernoulliSet.trusted(self.labels[idx], self.existence[idx],
                                            self.weights[comp], self.means[comp],
                                            self.covs[comp], comp_owner[comp])

    def heaviest(self) -> np.ndarray:
        """Index of each track's heaviest component ``(n,)`` (the first on ties)."""
        if len(self) == 0:
            return np.zeros(0, dtype=np.intp)
        order = np.lexsort((-self.weights, self.owner))
        return order[np.searchsorted(self.owner[order], np.arange(len(self)))]

    def moments(self) -> tuple[np.ndarray, np.ndarray]:
        """Each track's mixture collapsed to one Gaussian: means ``(n, d)``, covs ``(n, d, d)``."""
        w, m, P, s = self.weights, self.means, self.covs, self.starts()
        mass = np.add.reduceat(w, s)
        mean = np.add.reduceat(w[:, None] * m, s, axis=0) / mass[:, None]
        diff = m - mean[self.owner]
        spread = P + diff[:, :, None] * diff[:, None, :]
        cov = np.add.reduceat(w[:, None, None] * spread, s, axis=0) / mass[:, None, None]
        return mean, 0.5 * (cov + cov.swapaxes(1, 2))


def reduce_components(tracks: LabelledBernoulliSet, prune: float, merge_threshold: float,
                      max_components: int) -> LabelledBernoulliSet:
    """Each track's mixture pruned, merged and capped, then renormalised (all tracks at once).

    Components below ``prune`` go (each track keeps its heaviest); within a track, the Vo-Ma
    sweep (Vo & Ma 2006, Table II; as :func:`tracking.reduction.merge`) merges into the heaviest
    remaining component every one with ``(m_i - m_j)^T P_i^-1 (m_i - m_j) <= U``; the
    ``max_components`` heaviest are kept. The pairs tested are the same-track pairs only.
    """
    n = len(tracks)
    if n == 0:
        return tracks
    order = np.lexsort((-tracks.weights, tracks.owner))
    w, own = tracks.weights[order], tracks.owner[order]
    first = np.empty(len(w), dtype=bool)  # each track's heaviest
    first[0] = True
    np.not_equal(own[1:], own[:-1], out=first[1:])
    keep = order[(w >= prune) | first]
    w, m, P, own = tracks.weights[keep], tracks.means[keep], tracks.covs[keep], tracks.owner[keep]
    sizes = np.bincount(own, minlength=n)
    if sizes.max() > 1:
        w, m, P, own = _merge_within(w, m, P, own, sizes, merge_threshold)
        order = np.lexsort((-w, own))
        w, m, P, own = w[order], m[order], P[order], own[order]
        sizes = np.bincount(own, minlength=n)
    if sizes.max() > max_components:
        rank = np.arange(len(w)) - (np.cumsum(sizes) - sizes)[own]
        cap = rank < max_components
        w, m, P, own = w[cap], m[cap], P[cap], own[cap]
    total = np.add.reduceat(w, np.searchsorted(own, np.arange(n)))[own]
    # a track whose every weight underflowed to 0 (deleted by its existence in the same step)
    # gets equal weights, not 0/0
    w = np.divide(w, total, out=1.0 / np.bincount(own, minlength=n)[own], where=total > 0)
    return LabelledBernoulliSet.trusted(tracks.labels, tracks.existence, w, m, P, own)


PAIRS_DENSE = 64
""":func:`_merge_within` finds a scan's same-track pairs in a dense ``(c, c)`` mask up to this
many components (fewer NumPy calls), beyond it from the track sizes (memory ``O(pairs)``)."""


def _merge_within(w, m, P, own, sizes, threshold):
    """The Vo-Ma sweep in every track at once; components sorted by (owner, -weight). The
    pairs (centre, member) are every same-track pair, centre first, sorted by (centre, member)
    whichever way they are found."""
    c = len(w)
    idx = np.arange(c)
    if c <= PAIRS_DENSE:
        centre, member = np.nonzero((own[:, None] == own) & (idx[:, None] < idx))
    else:
        rank = idx - (np.cumsum(sizes) - sizes)[own]
        counts = sizes[own] - rank - 1  # later (lighter) components of the same track
        centre = np.repeat(idx, counts)
        member = centre + 1 + np.arange(centre.size) - np.repeat(np.cumsum(counts) - counts,
                                                                  counts)
    diff = m[member] - m[centre]
    close = c_einsum("gi,gij,gj->g", diff, inv_spd(P[member]), diff) <= threshold
    if not close.any():
        return w, m, P, own
    W, mean, WP, centres = merge_close(w, m, P, member[close], centre[close])
    cov = WP[centres] / W[centres, None, None]
    return W[centres], mean[centres], 0.5 * (cov + cov.swapaxes(1, 2)), own[centres]


def merge_close(w: np.ndarray, m: np.ndarray, P: np.ndarray, member: np.ndarray,
                centre: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Each close pair's member merged into its centre (a greedy sweep, centres heaviest
    first, pairs sorted (centre, member); a taken component joins no other): per root the
    weight ``W (c,)``, mean ``(c, d)`` and the unnormalised moment sum ``WP (c, d, d)``, and
    the roots ``centres``. Shared by one track set's reduction and a host's stacked one."""
    c = len(w)
    root = np.arange(c)
    taken = np.zeros(c, dtype=bool)
    for i, j in zip(member.tolist(), centre.tolist(), strict=True):
        if taken[j] or taken[i]:
            continue
        root[i] = j
        taken[i] = True
    W = np.bincount(root, w, minlength=c)
    centres = np.flatnonzero(root == np.arange(c))
    Wm = np.zeros_like(m)
    np.add.at(Wm, root, w[:, None] * m)
    mean = Wm / np.where(W > 0, W, 1.0)[:, None]
    diff = m - mean[root]
    WP = np.zeros_like(P)
    np.add.at(WP, root, w[:, None, None] * (P + diff[:, :, None] * diff[:, None, :]))
    return W, mean, WP, centres


__all__ = ["LabelledBernoulliSet", "merge_close", "reduce_components"]
