"""Fusers behind :class:`peers.contracts.Fuser`: GCI, AA, the single-target IMM fusers, none.

Every fusion formula lives in ``tracking.fusion`` / ``tracking.particles``; these classes only
say which one a peer uses and with what settings.
"""

from __future__ import annotations

from collections import Counter

import numpy as np
from sensornet.peers.contracts import FusionInput
from sensornet.peers.estimators import ImmEstimator, step_imm
from sensornet.tracking.fusion import gci_fuse
from sensornet.tracking.fusion_batch import hybrid_fuse_many
from sensornet.tracking.fusion_rules import aa_fuse, gci_fuse_optimised, hybrid_fuse
from sensornet.tracking.imm import IMMGaussianState, model_posterior
from sensornet.tracking.mixture import GaussianMixture
from sensornet.tracking.particles import (
    GaussianRatio,
    RatioConfig,
    collapse_to_models,
    floored,
    gci_summaries,
)
from sensornet.tracking.reduction import Reducer


def _densities(inp: FusionInput) -> list[GaussianMixture]:
    return [inp.own] + [inp.neighbours[s]["posterior"] for s in sorted(inp.neighbours)]


class GciFuser:
    """Generalized covariance intersection of GM-PHD densities (seed 000 §3), then reduced."""

    kinds = ("posterior",)
    max_rounds = 1 << 30
    product = True
    """A product of the inputs: a suspect neighbour is dropped, not down-weighted."""

    def __init__(self, reducer: Reducer, cardinality: str = "separate",
                 omega: str = "metropolis") -> None:
        self.reducer = reducer
        self.cardinality = cardinality
        self.omega = omega
        self.counts: Counter = Counter()

    def fuse(self, inp: FusionInput) -> GaussianMixture:
        densities = _densities(inp)
        if self.omega in ("det", "chernoff"):
            return gci_fuse_optimised(densities, self.omega, self.reducer, self.cardinality)
        return gci_fuse(densities, list(inp.weights), self.reducer, cardinality=self.cardinality)


class _MixtureFuser:
    """A fuser of GM-PHD densities by one formula of ``tracking.fusion``, then reduced."""

    kinds = ("posterior",)
    max_rounds = 1 << 30
    rule = staticmethod(aa_fuse)

    def __init__(self, reducer: Reducer) -> None:
        self.reducer = reducer
        self.counts: Counter = Counter()

    def fuse(self, inp: FusionInput) -> GaussianMixture:
        return self.rule(_densities(inp), list(inp.weights), self.reducer)


class AaFuser(_MixtureFuser):
    """Arithmetic-average fusion of GM-PHD densities, then reduced."""

    rule = staticmethod(aa_fuse)
    copies = True
    """Its fused density keeps every input's component of a target (at reduced weight) unless
    the reducer merged them, so the labelling releases no label won by two nearby copies
    (peers.labelling.label_fused ``copies``)."""
    label_state: str | None = None
    """Per-label existence at extraction (``lmb.aa_label_existence``; peers.consensus
    ``_tracks``, tracking.fusion_rules.aa_label_density): ``"mean"`` or ``"heaviest"``, the
    state a label's copies are reported at once; None: each row by its own weight."""


class HybridFuser(_MixtureFuser):
    """AA target weights, GCI (covariance-intersection) locations per target, then reduced
    (:func:`tracking.fusion.hybrid_fuse`): robust to neighbours that missed or pruned a target."""

    rule = staticmethod(hybrid_fuse)

    @property
    def batch_key(self) -> tuple:
        """Hybrid fusers with equal reducers compute the same thing (:meth:`fuse_many`)."""
        return ("hybrid", self.reducer)

    def fuse_many(self, inputs: list[FusionInput]) -> list[GaussianMixture]:
        """:meth:`fuse` of each input, stacked (:func:`tracking.fusion_batch.hybrid_fuse_many`:
        the same numbers, one array computation for all)."""
        return hybrid_fuse_many([(_densities(inp), list(inp.weights)) for inp in inputs],
                                self.reducer)


class NoFuser:
    """No fusion: the tracks are the local estimate's."""

    kinds: tuple[str, ...] = ()
    max_rounds = 1

    def __init__(self) -> None:
        self.counts: Counter = Counter()

    def fuse(self, inp: FusionInput) -> GaussianMixture:
        return inp.own


class ImmFuser:
    """Seed-001 fusion for single-target peers (seed 001 eq. 19-21;
    docs/algorithms.md "IMM models and the particle fusion rule").

    A second IMM filter (the *fused* filter) steps with the own radar's return and absorbs the
    neighbours' summaries: ``"gci"`` fuses the normalised summaries and collapses back to one
    Gaussian per own model; ``"ratio"`` multiplies by each neighbour's posterior / prediction
    ratio (inside the particle weights for the IMM-PF, in closed form for the IMM-EKF). The local
    filter never sees the fused density, so what a peer publishes stays its own radar's.
    """

    max_rounds = 1

    def __init__(self, rule: str, local: ImmEstimator, init_mean: np.ndarray,
                 init_cov: np.ndarray, rng: np.random.Generator | None,
                 omega: float | str | None = 0.15, ratio: RatioConfig | None = None) -> None:
        if rule not in ("gci", "ratio"):
            raise ValueError(f"single-target peers fuse by 'gci', 'ratio' or 'none', "
                             f"not {rule!r}")
        self.rule = rule
        self.kinds = ("posterior", "prediction") if rule == "ratio" else ("posterior",)
        self.est = local
        self.rng = rng
        self.omega = omega
        self.ratio = ratio or RatioConfig()
        self.state = (local.pf.initialise(init_mean, init_cov, rng) if local.kind == "imm-pf"
                      else local.ekf.initialise(init_mean, init_cov))
        self.counts: Counter = Counter()

    def model_probabilities(self) -> np.ndarray:
        return np.asarray(self.state.probs, float)

    def fuse(self, inp: FusionInput) -> GaussianMixture:
        est, z = self.est, np.asarray(inp.z, float).reshape(-1, 2)
        senders = sorted(inp.neighbours)
        if len(z) == 0 or not senders:  # predict only, or the own radar alone
            self.state, _ = step_imm(est, self.state, z, self.rng)
        elif self.rule == "gci":
            own, _ = step_imm(est, self.state, z, self.rng)
            fused = gci_summaries(floored(own.summary(), est.cov_floor),
                                  [inp.neighbours[s]["posterior"] for s in senders],
                                  self.omega if len(senders) == 1 else None)
            probs, means, covs = collapse_to_models(fused, est.n_models)
            if np.all(np.isfinite(probs)) and np.all(np.isfinite(covs)):
                self.state = (est.pf.from_gaussians(probs, means, covs, self.rng)
                              if est.kind == "imm-pf" else IMMGaussianState(probs, means, covs))
            else:  # the summaries do not overlap at all: keep the own update, count it
                self.counts["fusion_fallbacks"] += 1
                self.state = own
        else:
            ratios = [GaussianRatio.from_summaries(inp.neighbours[s]["posterior"],
                                                   inp.neighbours[s]["prediction"], self.ratio)
                      for s in senders]
            if est.kind == "imm-pf":
                self.state, _ = step_imm(est, self.state, z, self.rng,
                                         extra_log_lik=lambda X: sum(r.log_eval(X)
                                                                     for r in ratios))
            else:
                own, _ = step_imm(est, self.state, z, self.rng)
                means, covs, log_norm = own.means, own.covs, np.zeros(est.n_models)
                for r in ratios:
                    means, covs, ln = r.apply_gaussian(means, covs)
                    log_norm = log_norm + ln
                self.state = IMMGaussianState(model_posterior(own.probs, log_norm), means, covs)
        return self.state.summary()
