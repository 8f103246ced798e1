"""The input masses behind many peers' fused tracks at once: a peer host's last consensus
rounds fused in one pass (:class:`peers.batching.FusionBatch`) extract their tracks with
:func:`tracking.support.input_mass` (pooled existence of young tracks) and
:func:`tracking.support.input_support` (the support rule) of every fused row against the
round's inputs; here both for all the pass's peers in one computation.

Why: each is ~25 small NumPy calls per peer and scan (about 4 % of an LMB peer-scan on the
50-peer twin, docs/labelled-tracking.md "50 peers: labelled and watched"). The numbers are each
peer's own to the bit (tests/test_tracks_batch.py): every (row, input component) pair's
quadratic form is the same element-wise arithmetic (``c_einsum`` over pairs; its sums do not
depend on the stack), the inverses the same calls per peer size (:func:`_inverses`: LAPACK for
a peer's stack of at most 200 4x4 matrices, the closed form beyond, as
:func:`tracking.gaussian.inv_spd` chooses per call), each sum over an input's components the
same ``add.reduceat`` segment in the same order. A peer whose problem this cannot take
(another dimension, non-finite numbers) is left to its own computation.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from sensornet.tracking.fusion_rules import HYBRID_GATE
from sensornet.tracking.gaussian import _generic_inverse, _lapack_inv, c_einsum, inv_spd
from sensornet.tracking.mixture import GaussianMixture

Problem = tuple[np.ndarray, Sequence[GaussianMixture]]
"""``(means (n, d), inputs)``: the fused rows and the round's input mixtures."""


def _inverses(covs: list[np.ndarray]) -> list[np.ndarray] | None:
    """``inv_spd`` of each stack in ``covs``, the same numbers: the stacks ``inv_spd`` would
    give LAPACK go through one LAPACK call (each matrix its own factorisation), the others
    through ``inv_spd`` itself; None if LAPACK refused one (singular or not finite)."""
    lapack = [i for i, c in enumerate(covs) if _generic_inverse(c) and c.dtype == np.float64]
    out: list[np.ndarray | None] = [None] * len(covs)
    if lapack:
        stacked = np.concatenate([covs[i] for i in lapack])
        inv = _lapack_inv(stacked)
        if inv is None:
            return None
        inv = 0.5 * (inv + np.swapaxes(inv, -1, -2))
        at = 0
        for i in lapack:
            out[i] = inv[at:at + len(covs[i])]
            at += len(covs[i])
    for i, c in enumerate(covs):
        if out[i] is None:
            out[i] = inv_spd(c)
    return out


def masses_many(problems: Sequence[Problem], gate: float = HYBRID_GATE
                ) -> list[tuple[np.ndarray, np.ndarray] | None]:
    """For each problem ``(means, inputs)``: ``input_mass(means, inputs, gate)`` and
    ``input_support(means, inputs, gate)`` (``(n, I)`` float, ``(n,)`` int64), or None where
    the problem is left to its own computation (module docstring)."""
    out: list[tuple[np.ndarray, np.ndarray] | None] = [None] * len(problems)
    take = []
    for i, (X, inputs) in enumerate(problems):
        X = np.asarray(X)
        used = [D for D in inputs if len(D)]
        if (X.ndim != 2 or not len(X) or not used or any(D.dim != X.shape[1] for D in used)
                or not np.isfinite(X).all()):
            continue
        take.append((i, X, inputs, used))
    if not take or not 0 < gate < np.inf:
        return out
    invs = _inverses([np.concatenate([D.covs for D in used]) for *_, used in take])
    if invs is None:
        return out
    n = np.array([len(X) for _, X, _, _ in take])
    N = np.array([sum(len(D) for D in used) for *_, used in take])
    X = np.concatenate([X for _, X, _, _ in take])
    M = np.concatenate([np.concatenate([D.means for D in used]) for *_, used in take])
    Y = np.concatenate(invs)
    w = np.concatenate([np.concatenate([D.weights for D in used]) for *_, used in take])
    # pairs (problem, row, component), row-major within a problem, as each problem's (n, N)
    c = n * N
    cs = np.cumsum(c) - c
    pp = np.repeat(np.arange(len(take)), c)
    q_in = np.arange(int(c.sum())) - cs[pp]
    Np = N[pp]
    row = (np.cumsum(n) - n)[pp] + q_in // Np  # global fused row
    comp = (np.cumsum(N) - N)[pp] + q_in % Np  # global input component
    diff = X[row] - M[comp]
    q = c_einsum("pj,pjk,pk->p", diff, Y[comp], diff)
    if np.isnan(q).any():  # argmin's NaN rule: left to each peer's own
        return out
    ok = q <= gate
    # the nearest row of each component (argmin over the problem's rows: the first minimum)
    by = np.lexsort((row, comp))  # component-major
    seg = np.flatnonzero(np.r_[True, comp[by][1:] != comp[by][:-1]])
    qmin = np.minimum.reduceat(q[by], seg)
    first = np.minimum.reduceat(np.where(q[by] == np.repeat(qmin, np.diff(np.r_[seg, len(by)])),
                                         row[by], np.iinfo(np.int64).max), seg)
    near = np.empty(int(N.sum()), dtype=np.int64)
    near[comp[by][seg]] = first
    mass_v = np.where(ok & (row == near[comp]), w[comp], 0.0)
    held_v = np.where(ok, 1.0, 0.0)
    # each (row, input) a run of the pair order: the inputs' components are consecutive
    sizes = [np.array([len(D) for D in inputs], dtype=np.int64) for _, _, inputs, _ in take]
    inp_of = np.concatenate([np.repeat(np.arange(len(s))[s > 0], s[s > 0]) for s in sizes])
    runs = np.flatnonzero(np.r_[True, (row[1:] != row[:-1]) | (inp_of[comp][1:]
                                                               != inp_of[comp][:-1])])
    mass_r = np.add.reduceat(mass_v, runs)
    held_r = np.add.reduceat(held_v, runs)
    r_row, r_inp = row[runs], inp_of[comp[runs]]
    at_row = np.cumsum(n) - n
    ends = np.searchsorted(r_row, at_row + n)
    start = 0
    for t, (i, _, inputs, _) in enumerate(take):
        sl = slice(start, ends[t])
        start = ends[t]
        mass = np.zeros((n[t], len(inputs)))
        held = np.zeros((n[t], len(inputs)))
        mass[r_row[sl] - at_row[t], r_inp[sl]] = mass_r[sl]
        held[r_row[sl] - at_row[t], r_inp[sl]] = held_r[sl]
        out[i] = (mass, (held > 0).sum(axis=1).astype(np.int64))
    return out


def rows_support(support: np.ndarray, means: np.ndarray, states: np.ndarray
                 ) -> np.ndarray | None:
    """``(p,)`` the support of ``states (p, d)`` that are rows of ``means (n, d)`` (a fused
    density's extracted tracks), from ``support (n,)`` per row (:func:`masses_many`): a state's
    support depends only on its values, so any equal row gives it. None if a state is no row
    (then compute it)."""
    if not len(states):
        return np.zeros(0, dtype=np.int64)
    eq = (states[:, None, :] == means[None, :, :]).all(axis=2)
    if not eq.any(axis=1).all():
        return None
    return support[eq.argmax(axis=1)]


__all__ = ["masses_many", "rows_support"]
