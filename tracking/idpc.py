"""Clustering a pooled measurement set into target positions (seed 004; docs/seed004.md).

After measurement flooding every peer holds the scans of ``S`` sensors; targets show as dense
groups of about ``S Pd`` points, clutter as a sparse scatter. Two clusterers turn the pooled
points ``(n, 2)`` (metres, Cartesian) into position estimates (cluster centres) whose count is
the target number:

- :func:`idpc`: improved density-peaks clustering (seed 004). Local density
  ``rho_i = #{j != i : |z_i - z_j| <= d_c}``; target points ``rho_i > zeta S``; repeatedly the
  densest unclaimed target point seeds a cluster of the unclaimed target points within
  ``L d_c``; clusters whose balls ``(seed, L d_c)`` intersect are merged; a cluster of more
  than ``split_factor`` times the expected size ``S Pd`` is split with k-means into
  ``round(size / (S Pd))`` parts.
- :func:`ftc`: the FTC baseline, DBSCAN (scikit-learn, ``eps = d_c``,
  ``min_samples = floor(zeta S) + 2``, the same density rule with the point itself counted) then
  the same k-means split of oversized clusters.

:func:`polar_to_cartesian` projects range-bearing points first.

Array code throughout: the densities are one k-d tree count (``scipy.spatial.cKDTree``), a
cluster is one distance computation over the points; the only Python loop is over clusters (a
handful per scan), never over point pairs.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.cluster.vq import kmeans2
from scipy.spatial import cKDTree


@dataclass(frozen=True)
class ClusterParams:
    """IDPC / FTC parameters (seed 004; defaults are the reference's ``d_c = 25 m``)."""

    cutoff: float = 25.0
    """``d_c``: the local-density radius in metres (also DBSCAN's ``eps``)."""
    zeta: float = 0.3
    """``zeta`` in [0.2, 0.4]: a point is a target point when ``rho > zeta S``."""
    radius_factor: float = 1.25
    """``L`` in [1, 1.5]: a cluster takes the points within ``L d_c`` of its seed."""
    split_factor: float = 1.6
    """A cluster of more than ``split_factor S Pd`` points is split with k-means (our reading
    of "much larger than the expected size"); it then gets ``round(size / (S Pd))`` parts."""
    detection_probability: float = 0.95
    """``Pd``: the expected cluster size is ``S Pd``."""


@dataclass(frozen=True)
class Clusters:
    """The outcome of one clustering call."""

    centres: np.ndarray
    """``(k, 2)`` cluster centres (the position estimates); ``k`` is the target number."""
    labels: np.ndarray
    """``(n,)`` cluster index per input point, ``-1`` for points in no cluster (clutter)."""

    @property
    def count(self) -> int:
        """The estimated number of targets."""
        return len(self.centres)


def polar_to_cartesian(z: np.ndarray, position: tuple[float, float] = (0.0, 0.0)) -> np.ndarray:
    """Range-bearing ``z (n, 2) = [r, theta]`` seen from ``position`` to ``(n, 2)`` plane points.

    ``x = sx + r cos(theta)``, ``y = sy + r sin(theta)`` (bearing as ``atan2(dy, dx)``, §1).
    """
    z = np.asarray(z, dtype=float).reshape(-1, 2)
    r, th = z[:, 0], z[:, 1]
    return np.column_stack((position[0] + r * np.cos(th), position[1] + r * np.sin(th)))


def local_density(points: np.ndarray, cutoff: float) -> np.ndarray:
    """``rho (n,)``: the other points within ``cutoff`` of each point.

    The close pairs come from one k-d tree query (``scipy.spatial.cKDTree.query_pairs``), each
    counted for both of its points.
    """
    n = len(points)
    pairs = cKDTree(points).query_pairs(cutoff, output_type="ndarray")  # (p, 2), i < j
    return np.bincount(pairs[:, 0], minlength=n) + np.bincount(pairs[:, 1], minlength=n)


def idpc(points: np.ndarray, n_sensors: int, params: ClusterParams = ClusterParams(),
         rng: np.random.Generator | None = None) -> Clusters:
    """Improved density-peaks clustering of the pooled points ``(n, 2)`` of ``n_sensors`` scans.

    ``rng`` seeds the k-means split (only drawn from when a cluster is oversized).
    """
    points = np.asarray(points, dtype=float).reshape(-1, 2)
    n = len(points)
    labels = np.full(n, -1, dtype=np.intp)
    if n == 0 or n_sensors <= 0:
        return Clusters(np.zeros((0, 2)), labels)
    rho = local_density(points, params.cutoff)
    target = rho > params.zeta * n_sensors
    order = np.flatnonzero(target)
    order = order[np.argsort(-rho[order], kind="stable")]  # densest first
    radius2 = (params.radius_factor * params.cutoff) ** 2
    free = target.copy()
    seeds: list[int] = []
    for i in order:
        if not free[i]:
            continue
        d2 = np.einsum("ij,ij->i", points - points[i], points - points[i])
        members = free & (d2 <= radius2)
        labels[members] = len(seeds)
        free &= ~members
        seeds.append(int(i))
    if not seeds:
        return Clusters(np.zeros((0, 2)), labels)
    # Merge clusters whose balls (seed, L d_c) intersect: connected components of the seeds
    # closer than 2 L d_c.
    sp = points[np.asarray(seeds)]
    touching = ((sp[:, None, :] - sp[None, :, :]) ** 2).sum(axis=-1) < 4.0 * radius2
    comp = _components(touching)
    hit = labels >= 0
    labels[hit] = comp[labels[hit]]
    return _split_oversized(points, labels, n_sensors, params, rng)


def _components(adjacent: np.ndarray) -> np.ndarray:
    """Connected-component labels ``0..c-1`` of a small symmetric boolean ``(k, k)`` graph.

    Transitive closure by repeated boolean squaring (``log2 k`` products of ``k x k``: cheaper
    than ``scipy.sparse.csgraph`` for the few seeds of a scan); a component is named by its
    smallest member.
    """
    reach = adjacent | np.eye(len(adjacent), dtype=bool)
    while True:
        nxt = (reach.astype(np.int32) @ reach.astype(np.int32)) > 0
        if np.array_equal(nxt, reach):
            break
        reach = nxt
    first = reach.argmax(axis=1)  # smallest index each seed reaches
    _, comp = np.unique(first, return_inverse=True)
    return comp


BASELINE_HINT = "the FTC baseline needs scikit-learn: pip install 'sensornet[baselines]'"


class MissingBaseline(ModuleNotFoundError):
    """An optional baseline's library is not installed (the message says what to install)."""


def dbscan_class():
    """scikit-learn's DBSCAN (an optional dependency: only the FTC baseline uses it), or a
    one-line :class:`MissingBaseline` saying what to install."""
    try:
        from sklearn.cluster import DBSCAN  # heavy optional dependency: sklearn
    except ImportError:
        raise MissingBaseline(BASELINE_HINT) from None
    return DBSCAN


def ftc(points: np.ndarray, n_sensors: int, params: ClusterParams = ClusterParams(),
        rng: np.random.Generator | None = None) -> Clusters:
    """FTC baseline: scikit-learn DBSCAN (``eps = d_c``), then the k-means split of :func:`idpc`."""
    DBSCAN = dbscan_class()

    points = np.asarray(points, dtype=float).reshape(-1, 2)
    if len(points) == 0 or n_sensors <= 0:
        return Clusters(np.zeros((0, 2)), np.full(len(points), -1, dtype=np.intp))
    min_samples = int(np.floor(params.zeta * n_sensors)) + 2  # rho > zeta S, self included
    labels = DBSCAN(eps=params.cutoff, min_samples=min_samples).fit_predict(points)
    return _split_oversized(points, labels.astype(np.intp), n_sensors, params, rng)


def _split_oversized(points: np.ndarray, labels: np.ndarray, n_sensors: int,
                     params: ClusterParams, rng: np.random.Generator | None) -> Clusters:
    """Centres of the labelled clusters; a cluster above ``split_factor S Pd`` points is split
    with k-means (``scipy.cluster.vq.kmeans2``, k-means++ start) into ``round(size / S Pd)``."""
    expected = max(n_sensors * params.detection_probability, 1.0)
    hit = labels >= 0
    k = int(labels.max()) + 1 if hit.any() else 0
    sizes = np.bincount(labels[hit], minlength=k)
    sums = np.zeros((k, 2))
    np.add.at(sums, labels[hit], points[hit])
    centres = [sums / np.maximum(sizes, 1)[:, None]]
    out = labels.copy()
    big = np.flatnonzero(sizes > params.split_factor * expected)
    if len(big):
        keep = np.ones(k, dtype=bool)
        keep[big] = False
        relabel = np.full(k, -1, dtype=np.intp)
        relabel[keep] = np.arange(keep.sum())
        out[hit] = relabel[labels[hit]]
        centres = [centres[0][keep]]
        nxt = int(keep.sum())
        seed = rng if rng is not None else np.random.default_rng(0)
        for c in big:
            idx = np.flatnonzero(labels == c)
            parts = max(2, int(np.rint(sizes[c] / expected)))
            cent, lab = kmeans2(points[idx], parts, minit="++", seed=seed)
            used = np.unique(lab)  # k-means may leave a part empty
            remap = np.full(parts, -1, dtype=np.intp)
            remap[used] = nxt + np.arange(len(used))
            out[idx] = remap[lab]
            centres.append(cent[used])
            nxt += len(used)
    return Clusters(np.concatenate(centres).reshape(-1, 2), out)


__all__ = ["BASELINE_HINT", "ClusterParams", "Clusters", "MissingBaseline", "dbscan_class", "ftc",
           "idpc", "local_density", "polar_to_cartesian"]
