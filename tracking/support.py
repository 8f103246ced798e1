"""Extraction rules for fused tracks: how many fusion inputs hold each extracted track, the rule
that extracts a fused track only once it is supported (issue 33, docs/labelled-tracking.md,
"Fused vs centralised: where the gap is").

The hybrid rule (:func:`tracking.fusion_rules.hybrid_fuse`) keeps a target that only one input
holds, at that input's weight ``omega_i W`` (a miss at one input must not erase a target), so a
component one peer's clutter pushed above the level-2 threshold also stays, and under the
cardinality extraction the inputs' surplus mass turns it into a one-scan false track. The rule
here acts on extraction only (the fused density is unchanged, so the next scan can confirm the
track): a fused track is reported if at least ``min_inputs`` inputs hold a component within the
hybrid rule's association gate of it, or if it was extracted in each of the last ``scans``
scans (the same label), so a target that the other inputs then miss stays reported.

:func:`pooled_weights` acts on extraction too: a young fused track (its label a few scans old)
that several inputs hold, each weakly (LMB peers publishing tentative tracks), weighs its
inputs' existences pooled as independent evidence
(:func:`tracking.fusion_rules.pool_existence`), so it is reported when the centralised filter,
which adds every sensor's evidence each scan, would report it, not a scan or two later when one
peer's own track passes ``r > 0.5``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from sensornet.tracking.fusion_rules import HYBRID_GATE, pool_existence
from sensornet.tracking.gaussian import c_einsum, inv_spd
from sensornet.tracking.label_keys import keys_find, label_keys
from sensornet.tracking.mixture import GaussianMixture


def input_support(means: np.ndarray, inputs: Sequence[GaussianMixture],
                  gate: float = HYBRID_GATE) -> np.ndarray:
    """``(n,)`` int: for each state of ``means (n, d)``, the number of ``inputs`` that hold a
    component ``j`` with ``(x - m_j)' P_j^-1 (x - m_j) <= gate`` (the hybrid rule's test,
    :data:`tracking.fusion_rules.HYBRID_GATE`, by the input component's covariance)."""
    return (input_mass(means, inputs, gate, held=True) > 0).sum(axis=1).astype(np.int64)


def input_mass(means: np.ndarray, inputs: Sequence[GaussianMixture],
               gate: float = HYBRID_GATE, held: bool = False) -> np.ndarray:
    """``(n, len(inputs))``: for each state of ``means (n, d)`` and input, the weight of the
    input's components that went to it: within the gate (:func:`input_support`'s test) and
    nearer to it than to any other state (so a target's mass is not counted again for a
    weak component beside it); ``held``: whether any component is within the gate (1.0 per
    component, nearest or not)."""
    X = np.asarray(means, dtype=float)
    if X.ndim != 2:
        raise ValueError(f"means must be (n, d), got shape {X.shape}")
    n, d = X.shape
    if gate <= 0 or not np.isfinite(gate):
        raise ValueError(f"gate must be positive and finite, got {gate}")
    sizes = np.array([len(D) for D in inputs], dtype=np.int64)
    used = [D for D in inputs if len(D)]
    out = np.zeros((n, len(inputs)))
    if n == 0 or not used:
        return out
    if any(D.dim != d for D in used):
        raise ValueError(f"inputs must have dimension {d} (the states'), got "
                         f"{sorted({D.dim for D in used})}")
    M = np.concatenate([D.means for D in used])  # (N, d)
    Y = inv_spd(np.concatenate([D.covs for D in used]))  # (N, d, d)
    diff = X[:, None, :] - M[None, :, :]  # (n, N, d)
    q = c_einsum("anj,njk,ank->an", diff, Y, diff)  # (n, N)
    w = np.ones(len(M)) if held else np.concatenate([D.weights for D in used])
    ok = q <= gate
    if not held:
        ok &= np.arange(n)[:, None] == q.argmin(axis=0)[None, :]
    starts = np.concatenate(([0], np.cumsum(sizes[sizes > 0])[:-1]))
    out[:, sizes > 0] = np.add.reduceat(np.where(ok, w, 0.0), starts, axis=1)
    return out


def pooled_weights(mix: GaussianMixture, labels: np.ndarray, k: int, mass: np.ndarray,
                   prior: float, young: int, gate: float = HYBRID_GATE,
                   threshold: float = 0.5, skip: np.ndarray | None = None,
                   keep: np.ndarray | None = None) -> np.ndarray:
    """``(n,)`` the weights of the fused components of ``mix`` for extraction. A component
    whose label ``labels (n, 3)`` is at most ``young`` scans old at scan ``k`` (its second
    column, the birth or first-publication scan) and that two inputs or more hold (``mass
    (n, I)``, :func:`input_mass`) weighs the pooled existence of those inputs' masses
    (:func:`tracking.fusion_rules.pool_existence`, prior ``prior``) if that is larger, unless
    a component heavier than ``threshold``, or a candidate of larger pooled existence, lies
    within ``gate`` of it (``(m_a - m_b)' (P_a + P_b)^-1 (m_a - m_b)``: it would be a second
    track of that target). So weak evidence of a new target at several peers adds up, as in
    the centralised update, while the density stays the fused one. ``skip (n,)`` bool: rows
    never pooled (an AA fusion's copies of a heavier row's target, young only by the fresh
    label they get each scan: peers.labelling.copy_rows). ``keep (n,)`` bool: rows pooled at
    any age (their label was reported the scan before: a track born by pooling is not dropped
    once older than ``young`` while fewer inputs than half the weight hold it), and put first
    in the test for a second track of a target, so a new label beside it cannot take its
    target (issue 34, docs/real-traffic.md "Fused births pooled across radars")."""
    labels = np.asarray(labels, dtype=np.int64).reshape(-1, 3)
    w = mix.weights
    n = len(w)
    if labels.shape[0] != n or mass.shape[0] != n:
        raise ValueError(f"labels and mass must have {n} rows (the mixture's), got "
                         f"{labels.shape[0]} and {mass.shape[0]}")
    if young < 0:
        raise ValueError(f"young must be >= 0, got {young}")
    held = mass > 0
    row, _ = np.nonzero(held)
    pooled = pool_existence(mass[held], row, n, prior)
    kept = np.zeros(n, dtype=bool) if keep is None else np.asarray(keep, bool).reshape(n)
    pick = (held.sum(axis=1) >= 2) & ((k - labels[:, 1] <= young) | kept) & (pooled > w)
    if skip is not None:
        pick &= ~np.asarray(skip, dtype=bool).reshape(n)
    cand = np.flatnonzero(pick)
    strength = np.where(pick, pooled, w)
    other = np.flatnonzero(pick | (w > threshold))  # what a candidate could duplicate
    if len(cand) > 0 and len(other) > 1:
        diff = mix.means[cand][:, None] - mix.means[other][None]  # (c, o, d)
        Y = inv_spd(mix.covs[cand][:, None] + mix.covs[other][None])  # (c, o, d, d)
        q = c_einsum("coj,cojk,cok->co", diff, Y, diff)
        # beside a track above the threshold, a stronger candidate, or an equal one before
        s_c, s_o = strength[cand][:, None], strength[other][None, :]
        k_c, k_o = kept[cand][:, None], kept[other][None, :]
        first = ((w[other] > threshold)[None, :] | (k_o & ~k_c)
                 | ((k_o == k_c) & ((s_o > s_c)
                                    | ((s_o == s_c) & (other[None, :] < cand[:, None])))))
        beside = ((q <= gate) & first).any(axis=1)
        pick[cand[beside]] = False
    return np.where(pick, pooled, w)


def revisit_weights(w: np.ndarray, labels: np.ndarray, k: int, mass: np.ndarray,
                    omegas: np.ndarray, spans: np.ndarray, held_above: float = 0.5
                    ) -> np.ndarray:
    """``(n,)`` extraction weights of fused tracks whose AA existence ``w (n,)`` (``sum_i
    omega_i r_i``, Li 2022) counts inputs that cannot have confirmed the target yet: a
    rotating radar shows a measurement-born target after its second plot, its first look
    falls within one revisit ``span_i`` (scans) of the target's appearance, so by ``a = k -
    birth scan`` (``labels[:, 1]``) input ``i`` could hold it with probability ``q_i =
    clip(a / span_i - 1, 0, 1)`` (1 where it holds it, ``mass (n, I)`` above ``held_above``:
    its own confirmation, not a tentative Bernoulli of one look; or ``span_i <= 0``). A
    track two inputs or more hold weighs ``min(1, w / sum_i omega_i q_i)``: the AA
    over the inputs that had the data, so a radar not yet looked at twice is no evidence
    against it (issue 34, docs/real-traffic.md "Why the far radars confirm late"). ``spans``
    must come from the shared scenario, not the senders (a member claiming blindness would
    raise the others' tracks)."""
    w = np.asarray(w, dtype=float).reshape(-1)
    labels = np.asarray(labels, dtype=np.int64).reshape(-1, 3)
    mass = np.asarray(mass, dtype=float)
    omegas = np.asarray(omegas, dtype=float).reshape(-1)
    spans = np.asarray(spans, dtype=float).reshape(-1)
    n, I = len(w), len(omegas)
    if labels.shape[0] != n or mass.shape != (n, I) or spans.shape != (I,):
        raise ValueError(f"labels, mass and spans must be ({n}, 3), ({n}, {I}) and ({I},), "
                         f"got {labels.shape}, {mass.shape} and {spans.shape}")
    held = mass > held_above
    age = (k - labels[:, 1]).astype(float)[:, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        q = np.where(spans > 0, np.clip(age / spans - 1.0, 0.0, 1.0), 1.0)
    q = np.where(held, 1.0, q)
    d = q @ omegas
    ok = (held.sum(axis=1) >= 2) & (d > 0)
    return np.where(ok, np.maximum(w, np.minimum(1.0, w / np.where(ok, d, 1.0))), w)


MAJORITY = -1
""":attr:`SupportRule.min_inputs` for more than half of the round's inputs, at least 2."""


@dataclass
class SupportRule:
    """Which extracted fused tracks to report (module docstring): supported by at least
    ``min_inputs`` inputs (:data:`MAJORITY`: more than half of the round's inputs, at least
    2), or extracted (under the same label) in ``scans`` consecutive calls. One per peer; call
    :meth:`keep` once per scan with that scan's extracted tracks.

    Why a majority (docs/labelled-tracking.md, "Fused false tracks need a majority of the
    inputs"): on 20 peers of degree 4 (5 inputs) the false fused tracks that passed 2 were
    one-scan tracks, 14 of 16 traced held by just two inputs (mostly two neighbours whose
    sensors had clutter at a birth point in the same scan); 3 of 5 asks for a third, while
    on 3 peers (3 inputs) it stays 2."""

    min_inputs: int = 2
    scans: int = 2
    _keys: np.ndarray = field(default_factory=lambda: label_keys(np.zeros((0, 3), np.int64)),
                              repr=False)
    _streak: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64), repr=False)

    def __post_init__(self) -> None:
        if self.min_inputs < 1 and self.min_inputs != MAJORITY:
            raise ValueError(f"min_inputs must be at least 1 or {MAJORITY} (a majority), got "
                             f"{self.min_inputs}")
        if self.scans < 1:
            raise ValueError(f"scans must be at least 1, got {self.scans}")

    def needed(self, inputs: int | None) -> int:
        """Inputs that must hold a track when the round had ``inputs`` (own included)."""
        if self.min_inputs != MAJORITY:
            return self.min_inputs
        if inputs is None or inputs < 0:
            raise ValueError(f"a majority rule needs the round's input count, got {inputs!r}")
        return max(2, inputs // 2 + 1)

    def keep(self, labels: np.ndarray, support: np.ndarray, inputs: int | None = None
             ) -> np.ndarray:
        """``(n,)`` bool for the extracted tracks ``labels (n, 3)`` with ``support (n,)``
        (:func:`input_support` over the round's ``inputs`` mixtures, needed by
        :data:`MAJORITY`); remembers each label's run of consecutive extractions."""
        labels = np.asarray(labels, dtype=np.int64).reshape(-1, 3)
        support = np.asarray(support)
        if support.shape != (len(labels),):
            raise ValueError(f"support must be ({len(labels)},), got shape {support.shape}")
        need = self.needed(inputs)
        keys = label_keys(labels)
        by = np.argsort(self._keys)
        seen, pos = (keys_find(self._keys[by], keys) if len(by)
                     else (np.zeros(len(keys), bool), np.zeros(len(keys), np.intp)))
        streak = np.ones(len(keys), dtype=np.int64)
        streak[seen] += self._streak[by[pos[seen]]]
        self._keys, self._streak = keys, streak  # a label twice in a scan: either row's run
        return (support >= need) | (streak >= self.scans)


__all__ = ["MAJORITY", "SupportRule", "input_mass", "input_support", "pooled_weights",
           "revisit_weights"]
