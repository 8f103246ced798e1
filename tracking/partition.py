"""Measurement-set partitioning for extended targets (seed 002; ALGORITHMS.md §7).

A *partition* of a scan ``Z (m, 2)`` is an integer label array ``(m,)``: measurements with the
same label form one *cell* ``W``. The ET-GM-PHD update (:mod:`tracking.etgmphd`) sums over a
small set of partitions; a *partitioner* is any callable ``scan -> list of label arrays``, so
the filter does not care how they were found.

:class:`DistancePartitioner` is Granström, Lundquist & Orguner's distance partitioning (IEEE
TAES 2012, §IV.A): for a threshold ``t``, two measurements share a cell when a chain of
measurements joins them with every link's statistic ``<= t`` (single linkage); one partition
per threshold, thresholds between two chi-square quantiles. The cells at threshold ``t`` are
the connected components of the graph of links ``<= t``, which are the components of the
minimum spanning tree's edges ``<= t``: the partition only changes at MST edge lengths, so
trying those (and the lower quantile) gives the same set of partitions as trying every
pairwise distance (``tests/test_partition.py`` checks it), with ``m - 1`` thresholds instead
of ``m (m - 1) / 2``.

The statistic is ``d^2 / 2`` with ``d^2 = (z_i - z_j)^T R^-1 (z_i - z_j)``: the difference of
two measurements of one target has covariance ``2R``, so ``d^2 / 2`` is chi-square with 2
degrees of freedom (the spec's reading; measured here: adjusted Rand index 0.97 vs 0.82 with
thresholds on ``d^2``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components, minimum_spanning_tree
from scipy.spatial.distance import pdist, squareform
from scipy.stats import chi2

MAX_MEASUREMENTS = 2000
"""Default cap on the scan size a partitioner accepts (pairwise work is O(m^2))."""


class ScanTooLarge(ValueError):
    """A scan larger than a partitioner's cap (the caller counts it and skips the scan)."""


def check_scan(z: np.ndarray, cap: int) -> np.ndarray:
    """``z`` as a float ``(m, 2)`` array; :class:`ScanTooLarge` when ``m > cap``."""
    z = np.asarray(z, dtype=float).reshape(-1, 2)
    if len(z) > cap:
        raise ScanTooLarge(f"scan of {len(z)} measurements exceeds the partition cap {cap}")
    return z


def canonical(labels: np.ndarray) -> np.ndarray:
    """Relabel so cells are numbered 0, 1, ... in order of first appearance (for comparisons)."""
    labels = np.asarray(labels)
    _, first, inv = np.unique(labels, return_index=True, return_inverse=True)
    rank = np.empty(len(first), dtype=int)
    rank[np.argsort(first)] = np.arange(len(first))
    return rank[inv.reshape(-1)]


def mahalanobis_half(z: np.ndarray, sigma: float) -> np.ndarray:
    """Condensed pairwise ``d^2 / 2`` for ``R = sigma^2 I`` (``pdist`` order): ``(m (m-1) / 2,)``.
    """
    return pdist(z, "sqeuclidean") / (2.0 * sigma * sigma)


def components_at(m: int, i: np.ndarray, j: np.ndarray) -> np.ndarray:
    """Labels of the connected components of the graph on ``m`` nodes with edges ``(i, j)``."""
    g = coo_matrix((np.ones(len(i)), (i, j)), shape=(m, m))
    return connected_components(g, directed=False)[1]


@dataclass(frozen=True)
class DistancePartitioner:
    """Distance partitioning (Granström et al. 2012, §IV.A) with MST thresholds."""

    sigma: float = 20.0
    """Measurement noise standard deviation per axis, metres (``R = sigma^2 I``)."""
    p_lower: float = 0.3
    """Lower probability: the smallest threshold is the chi-square(2) quantile at it."""
    p_upper: float = 0.8
    """Upper probability: the largest threshold is the chi-square(2) quantile at it."""
    max_measurements: int = MAX_MEASUREMENTS
    """Larger scans raise :class:`ScanTooLarge` (pairwise work is O(m^2))."""

    def __post_init__(self) -> None:
        if not (0.0 < self.p_lower <= self.p_upper < 1.0):
            raise ValueError(f"distance partition needs 0 < p_lower <= p_upper < 1, got "
                             f"{self.p_lower:g}, {self.p_upper:g}")
        if not self.sigma > 0:
            raise ValueError(f"distance partition needs sigma > 0, got {self.sigma:g}")

    @property
    def bounds(self) -> tuple[float, float]:
        """``(lower, upper)`` thresholds on ``d^2 / 2``."""
        return float(chi2.ppf(self.p_lower, 2)), float(chi2.ppf(self.p_upper, 2))

    def __call__(self, z: np.ndarray) -> list[np.ndarray]:
        """Distinct partitions ``[(m,) labels, ...]`` for thresholds in ``[lower, upper]``."""
        z = check_scan(z, self.max_measurements)
        m = len(z)
        if m <= 1:
            return [np.zeros(m, dtype=int)]
        lo, hi = self.bounds
        d = mahalanobis_half(z, self.sigma)  # (m (m-1) / 2,)
        in_range = (d >= lo) & (d <= hi)
        if not in_range.any():  # no pairwise threshold to try: the lower quantile's partition
            return [self._at(m, d, lo)]
        # MST of the complete graph; zero distances (duplicate points) kept as tiny weights
        D = squareform(np.maximum(d, 1e-300))
        mst = minimum_spanning_tree(D).tocoo()
        w, i, j = mst.data, mst.row, mst.col
        order = np.argsort(w, kind="stable")
        w, i, j = w[order], i[order], j[order]
        thresholds = np.unique(w[(w >= lo) & (w <= hi)])
        out = []
        first_mst = thresholds[0] if len(thresholds) else np.inf
        if np.any(in_range & (d < first_mst)):  # a pairwise threshold before the first MST one
            out.append(components_at(m, i[w <= lo], j[w <= lo]))
        for t in thresholds:
            k = np.searchsorted(w, t, side="right")
            out.append(components_at(m, i[:k], j[:k]))
        return out

    def _at(self, m: int, d: np.ndarray, t: float) -> np.ndarray:
        ii, jj = np.triu_indices(m, 1)
        keep = d <= t
        return components_at(m, ii[keep], jj[keep])


def all_pairs_partitions(z: np.ndarray, sigma: float, lo: float, hi: float) -> list[np.ndarray]:
    """Reference: one partition per pairwise ``d^2 / 2`` in ``[lo, hi]`` (Granström's rule as
    written), deduplicated. O(m^4); for tests."""
    z = np.asarray(z, float).reshape(-1, 2)
    m = len(z)
    d = mahalanobis_half(z, sigma)
    ii, jj = np.triu_indices(m, 1)
    seen, out = set(), []
    for t in np.unique(d[(d >= lo) & (d <= hi)]):
        lab = canonical(components_at(m, ii[d <= t], jj[d <= t]))
        key = lab.tobytes()
        if key not in seen:
            seen.add(key)
            out.append(lab)
    return out


__all__ = [
    "MAX_MEASUREMENTS",
    "DistancePartitioner",
    "ScanTooLarge",
    "all_pairs_partitions",
    "canonical",
    "check_scan",
    "components_at",
]
