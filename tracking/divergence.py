"""Closed-form divergences between Gaussian mixtures (the consistency test of :mod:`peers.trust`).

Cauchy–Schwarz divergence (Kampa, Hasanbelliu & Principe 2011, "Closed-form Cauchy-Schwarz PDF
divergence for mixture of Gaussians", IJCNN; Hoang, Vo, Vo & Mahler 2015 use it between
multi-target densities):

``D_CS(p, q) = -log int p q + 1/2 log int p^2 + 1/2 log int q^2``,

with ``int N(x; m_a, P_a) N(x; m_b, P_b) dx = N(m_a; m_b, P_a + P_b)``, so every term is a sum
over component pairs. It is zero iff ``p`` and ``q`` are proportional, so for intensities it
compares *where* the targets are; how many is compared apart (the masses).
"""

from __future__ import annotations

import functools

import numpy as np
from sensornet.tracking.gaussian import inv_det_spd, log_gaussian
from sensornet.tracking.mixture import GaussianMixture

BLOCK_PAIRS = 1 << 18
"""Component pairs formed at once (262,144: about 30 MB of ``d = 4`` covariance sums): up to
this many pairs in all, one block as before; beyond, rows in blocks of this many pairs, so
memory stays linear in the components whatever a neighbour sends (issue 36: 2.18 GB at
2,000 components in one block)."""


def log_overlaps(mixtures: list[GaussianMixture]) -> np.ndarray:
    """``L[i, j] = log int D_i D_j`` for every pair of the (unnormalised) mixtures: ``(n, n)``.

    One matrix of component terms ``log a_a + log b_b + log N(m_a; m_b, P_a + P_b)`` over all
    components, log-sum-exp'ed in blocks (far-apart tight components underflow nothing); an
    empty mixture has ``-inf`` rows and columns. Time is quadratic in the total number of
    components ``C``, memory ``O(C * BLOCK_PAIRS / C)``: bound the components first
    (:mod:`peers.budget`). The term matrix is symmetric, so each unordered pair is made once
    (:func:`pair_terms`; the same numbers to the bit), and where every mixture has at most
    one component it is ``L`` itself.
    """
    n = len(mixtures)
    sizes = [len(D) for D in mixtures]
    L = np.full((n, n), -np.inf)
    C = sum(sizes)
    if C == 0:
        return L
    full = [D for D in mixtures if len(D)]
    w = np.concatenate([D.weights for D in full])
    m = np.concatenate([D.means for D in full])
    P = np.concatenate([D.covs for D in full])
    with np.errstate(divide="ignore"):
        lw = np.log(w)
    if C == len(full) or C * C <= BLOCK_PAIRS:  # one block of terms (or one term each)
        return _reduce_terms(pair_terms(lw, m, P), sizes)
    present = np.flatnonzero(sizes)
    starts = np.r_[0, np.cumsum(np.asarray(sizes)[present])[:-1]]
    out = _blocked(lw, m, P, starts, max(1, BLOCK_PAIRS // C))
    if len(full) == n:
        return out
    L[np.ix_(present, present)] = out
    return L


def log_overlaps_many(groups: list[list[GaussianMixture]]) -> list[np.ndarray]:
    """:func:`log_overlaps` of each group of mixtures (several peers' rounds at once, a peer
    host's trust tests: :mod:`peers.trust_batch`), the same numbers to the bit: the pair
    terms of every group's components in one computation (:func:`pair_terms`' arithmetic is
    per pair, so a pair's term does not depend on the others), then each group's
    log-sum-exps as :func:`log_overlaps` does them. Groups of another dimension than the
    first non-empty one's, or beyond one block (:data:`BLOCK_PAIRS`), on their own."""
    out: list[np.ndarray | None] = [None] * len(groups)
    todo, dim, lens = [], None, []
    for i, mixes in enumerate(groups):
        z = [len(D) for D in mixes]
        C = sum(z)
        d = next((D.means.shape[1] for D, c in zip(mixes, z, strict=True) if c), None)
        if C == 0 or C * C > BLOCK_PAIRS or (dim is not None and d != dim):
            out[i] = log_overlaps(mixes)
            continue
        dim = d
        todo.append((i, C))
        lens.append(z)
    if len(todo) < 2:
        for i, _ in todo:
            out[i] = log_overlaps(groups[i])
        return out
    full = [D for (i, _), z in zip(todo, lens, strict=True)
            for D, c in zip(groups[i], z, strict=True) if c]
    w = np.concatenate([D.weights for D in full])
    m = np.concatenate([D.means for D in full])
    P = np.concatenate([D.covs for D in full])
    with np.errstate(divide="ignore"):
        lw = np.log(w)
    ends = np.cumsum([C for _, C in todo])
    a = np.concatenate([_upper(C)[0] + (e - C) for (_, C), e in zip(todo, ends, strict=True)])
    b = np.concatenate([_upper(C)[1] + (e - C) for (_, C), e in zip(todo, ends, strict=True)])
    inv, det = inv_det_spd((P[a] + P[b])[None])
    g = lw[a] + lw[b] + log_gaussian((m[a] - m[b])[None], inv, det)[0]
    sizes = lens
    present = [[c for c in z if c] for z in sizes]
    one = [len(p) == C for p, (_, C) in zip(present, todo, strict=True)]  # one term each
    many = [n for n, o in enumerate(one) if not o]
    Cs = np.array([C for _, C in todo])
    base = np.r_[0, np.cumsum(Cs * Cs)[:-1]]  # where each group's (C, C) terms start
    pairs = np.array([len(_upper(C)[0]) for C in Cs.tolist()])
    g_of = np.repeat(np.arange(len(todo)), pairs)
    first = (ends - Cs)[g_of]  # the group's first component
    u, v = a - first, b - first
    flat = np.empty(int((Cs * Cs).sum()))
    flat[base[g_of] + u * Cs[g_of] + v] = g
    flat[base[g_of] + v * Cs[g_of] + u] = g
    for n, o in enumerate(one):
        if o:
            C = int(Cs[n])
            out[todo[n][0]] = _reduce_terms(flat[base[n]:base[n] + C * C].reshape(C, C),
                                            sizes[n])
    if many:
        C2 = (Cs * Cs).tolist()
        terms = np.concatenate([flat[base[n]:base[n] + C2[n]] for n in many])
        blocks = _reduce_blocks(terms, [tuple(present[n]) for n in many])
        for n, block in zip(many, blocks, strict=True):
            i = todo[n][0]
            if len(present[n]) == len(sizes[n]):
                out[i] = block
            else:
                idx = np.flatnonzero(sizes[n])
                L = np.full((len(sizes[n]), len(sizes[n])), -np.inf)
                L[np.ix_(idx, idx)] = block
                out[i] = L
    return out


def _reduce_blocks(terms: np.ndarray, sizes: list[tuple[int, ...]]) -> list[np.ndarray]:
    """:func:`_reduce_terms`' log-sum-exps of several groups' pair terms at once, the same
    numbers to the bit. ``terms``: the groups' symmetric ``(C, C)`` term matrices, each
    row-major, one after the other; ``sizes``: each group's non-empty mixtures' sizes
    (``C`` in all). ``np.add.reduceat`` sums each segment as ``a_0 + pairwise(a_1, ...)``
    whatever the array's shape, so the segments of both of :func:`_reduce_terms`'
    reductions (over a block's rows, then its columns) are laid out contiguously in 1-d
    (the terms' symmetry makes a column a row) and reduced in one call each. Returns each
    group's ``(m, m)`` block of its non-empty mixtures."""
    plans = [_block_plan(z) for z in sizes]
    M = np.array([len(z) for z in sizes])
    C = np.array([sum(z) for z in sizes])
    base = np.r_[0, np.cumsum(C * C)[:-1]].tolist()
    off1 = np.r_[0, np.cumsum(M * C)[:-1]].tolist()
    off2 = np.r_[0, np.cumsum(M * M)[:-1]].tolist()
    s1 = np.concatenate([p[0] + o for p, o in zip(plans, base, strict=True)])
    perm = np.concatenate([p[1] + o for p, o in zip(plans, off1, strict=True)])
    s2 = np.concatenate([p[2] + o for p, o in zip(plans, off1, strict=True)])
    eblk = np.concatenate([p[3] + o for p, o in zip(plans, off2, strict=True)])
    top = np.maximum.reduceat(np.maximum.reduceat(terms, s1)[perm], s2)
    safe = np.where(np.isfinite(top), top, 0.0)
    S = np.add.reduceat(np.add.reduceat(np.exp(terms - safe[eblk]), s1)[perm], s2)
    with np.errstate(divide="ignore"):
        out = np.where(np.isfinite(top), safe + np.log(S), -np.inf)
    return [out[o:o + m * m].reshape(m, m) for o, m in zip(off2, M.tolist(), strict=True)]


@functools.lru_cache(maxsize=4096)
def _block_plan(sizes: tuple[int, ...]) -> tuple[np.ndarray, ...]:
    """The index arrays of :func:`_reduce_blocks` for one group of non-empty mixtures of
    ``sizes`` components (``C`` in all, ``m`` mixtures), made once per ``sizes``
    (read-only): the starts of the row sums' segments in its ``(C, C)`` terms (per column
    ``b`` and mixture ``I``: ``b C + start_I``), where row ``(I, b)`` of the ``(m, C)``
    row sums is among them (``b m + I``), the starts of the column sums' segments in those
    (``I C + start_J``) and each term's block (``I m + J``)."""
    m, C = len(sizes), sum(sizes)
    st = np.r_[0, np.cumsum(sizes)[:-1]]
    blk = np.repeat(np.arange(m), sizes)
    out = ((np.arange(C)[:, None] * C + st[None, :]).ravel(),
           (np.arange(C)[None, :] * m + np.arange(m)[:, None]).ravel(),
           (np.arange(m)[:, None] * C + st[None, :]).ravel(),
           (blk[:, None] * m + blk[None, :]).ravel())
    for a in out:
        a.flags.writeable = False
    return out


def _reduce_terms(G: np.ndarray, sizes: list[int]) -> np.ndarray:
    """``L`` (``(n, n)``) from the pair terms ``G`` (``(C, C)``) of mixtures of ``sizes``
    components (``C`` in all, ``C * C`` at most :data:`BLOCK_PAIRS`): :func:`log_overlaps`'
    log-sum-exps over each two mixtures' blocks, the same operations."""
    n = len(sizes)
    C = len(G)
    present = np.flatnonzero(sizes)
    whole = len(present) == n
    if C == len(present):  # one component each: the log-sum-exp of one term is the term
        out = np.where(np.isfinite(G), G, -np.inf)
    else:
        starts = np.r_[0, np.cumsum(np.asarray(sizes)[present])[:-1]]
        blk = np.repeat(np.arange(len(present)), np.asarray(sizes)[present])  # of each one
        top = np.maximum.reduceat(np.maximum.reduceat(G, starts, axis=0), starts, axis=1)
        safe = np.where(np.isfinite(top), top, 0.0)
        S = np.add.reduceat(np.add.reduceat(np.exp(G - safe[blk][:, blk]), starts, axis=0),
                            starts, axis=1)
        with np.errstate(divide="ignore"):
            out = np.where(np.isfinite(top), safe + np.log(S), -np.inf)
    if whole:
        return out
    L = np.full((n, n), -np.inf)
    L[np.ix_(present, present)] = out
    return L


def pair_terms(lw: np.ndarray, m: np.ndarray, P: np.ndarray) -> np.ndarray:
    """``G[a, b] = lw_a + lw_b + log N(m_a; m_b, P_a + P_b)`` of every two components
    (``lw (C,)``, ``m (C, d)``, ``P (C, d, d)``): ``(C, C)``, symmetric, so each unordered
    pair (the diagonal with them) is made once and mirrored: ``P_a + P_b`` is the same sum
    either way, ``m_a - m_b`` its negation (a quadratic form of it the same to the bit), and
    the inverses the closed forms :func:`inv_det_spd` takes for a ``(C, C, d, d)`` stack
    (hence the leading axis of 1)."""
    C = len(lw)
    a, b = _upper(C)
    inv, det = inv_det_spd((P[a] + P[b])[None])
    g = lw[a] + lw[b] + log_gaussian((m[a] - m[b])[None], inv, det)[0]
    G = np.empty((C, C))
    G[a, b] = g
    G[b, a] = g
    return G


@functools.lru_cache(maxsize=64)
def _upper(C: int) -> tuple[np.ndarray, np.ndarray]:
    """``np.triu_indices(C)`` (the diagonal with the pairs), made once per ``C``, read-only."""
    a, b = np.triu_indices(C)
    a.flags.writeable = False
    b.flags.writeable = False
    return a, b


def _blocked(lw: np.ndarray, m: np.ndarray, P: np.ndarray, starts: np.ndarray,
             rows: int) -> np.ndarray:
    """:func:`log_overlaps` of the non-empty mixtures (``starts``: their first components
    in ``lw (C,)``, ``m (C, d)``, ``P (C, d, d)``), ``rows`` components against all at a
    time: per component, the log-sum-exp over each mixture's components ``(C, k)``, then per
    mixture over its rows."""
    C = len(lw)
    R = np.empty((C, len(starts)))
    for a in range(0, C, rows):
        b = min(C, a + rows)
        inv, det = inv_det_spd(P[a:b, None] + P[None, :])
        G = lw[a:b, None] + lw[None, :] + log_gaussian(m[a:b, None] - m[None, :], inv, det)
        R[a:b] = _lse_reduceat(G, starts, axis=1)
    return _lse_reduceat(R, starts, axis=0)


def _lse_reduceat(G: np.ndarray, starts: np.ndarray, axis: int) -> np.ndarray:
    """``log sum exp`` of ``G`` over the segments of ``axis`` beginning at ``starts``
    (``-inf`` where a segment is all ``-inf``)."""
    top = np.maximum.reduceat(G, starts, axis=axis)
    safe = np.where(np.isfinite(top), top, 0.0)
    idx = np.repeat(np.arange(len(starts)), np.diff(np.r_[starts, G.shape[axis]]))
    S = np.add.reduceat(np.exp(G - np.take(safe, idx, axis=axis)), starts, axis=axis)
    with np.errstate(divide="ignore"):
        return np.where(np.isfinite(top), safe + np.log(S), -np.inf)


def cs_from_log_overlaps(lpq: np.ndarray, lpp: np.ndarray, lqq: np.ndarray) -> np.ndarray:
    """``D_CS`` from ``log int pq``, ``log int p^2``, ``log int q^2`` (arrays); ``inf`` where
    ``p`` and ``q`` do not overlap at all, ``nan`` where either is empty."""
    empty = ~np.isfinite(lpp) | ~np.isfinite(lqq)
    with np.errstate(invalid="ignore"):
        out = np.maximum(-lpq + 0.5 * lpp + 0.5 * lqq, 0.0)  # >= 0 (Cauchy-Schwarz)
    return np.where(empty, np.nan, out)


def cs_divergence(p: GaussianMixture, q: GaussianMixture) -> float:
    """The Cauchy–Schwarz divergence of two mixtures (``nan`` if either is empty)."""
    L = log_overlaps([p, q])
    return float(cs_from_log_overlaps(L[0, 1], L[0, 0], L[1, 1]))


__all__ = ["BLOCK_PAIRS", "cs_divergence", "cs_from_log_overlaps", "log_overlaps",
           "log_overlaps_many", "pair_terms"]
