"""Single-target peers (seed 001): an IMM particle filter or IMM-EKF behind the peer interface.

Same inputs and outputs as :class:`peers.logic.PeerLogic` (``on_scan``, ``on_estimate``,
``on_deadline``, ``on_truth``, ...), so the Zenoh runtime and the twin drive it unchanged.
Per scan ``k``:

1. the *local* filter steps with the own radar's measurement and publishes its posterior
   summary (one Gaussian per model, 6-D) and, for the particle fusion rule, its predicted
   summary (``kind = "prediction"``);
2. when every live neighbour's scan-``k`` summaries are in (or at the deadline), the *fused*
   filter steps with the own measurement and fuses (ALGORITHMS.md §6, seed 001 eq. 19–21):
   ``"gci"``: GCI of the normalised summaries, collapsed back to one Gaussian per own model;
   ``"ratio"``: particle weights times each neighbour's posterior / prediction ratio; its
   estimate is published as the tracks. The local filter never sees fused information, so
   what a peer publishes is its own radar's estimate (no double counting).

A neighbour summary stamped with another scan is counted late and not used (the ratio rule
needs a matching posterior/prediction pair).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from peers.logic import PeerBase, PeerOptions, PeerStats
from protocol.messages import Estimate, Scan, Tracks
from tracking.imm import (
    IMMEKF,
    IMMGaussianState,
    IMMParams,
    model_posterior,
    radar_log_likelihood,
)
from tracking.mixture import GaussianMixture
from tracking.models import RangeBearing
from tracking.nale import NaleBuffer
from tracking.particles import (
    GaussianRatio,
    IMMParticleFilter,
    ParticleParams,
    RatioConfig,
    collapse_to_models,
    floored,
    gci_summaries,
)

FILTER_KINDS = ("imm-pf", "imm-ekf")


@dataclass(frozen=True)
class SingleTargetConfig:
    """Filter and fusion settings of a single-target peer (defaults: the seed-001 study's)."""

    imm: IMMParams = field(default_factory=IMMParams)
    """Models, Markov matrix, initial model probabilities."""
    particle: ParticleParams = field(default_factory=ParticleParams)
    """Particles per model and regularisation jitter (IMM-PF)."""
    ratio: RatioConfig = field(default_factory=RatioConfig)
    """Particle fusion rule: ratio on position only, clipped (docs/seed001.md)."""
    gci_omega: float | str | None = 0.3
    """GCI weight of the other peer: a number, None (0.5), or "det" (minimum fused determinant,
    chosen per scan). 0.3: the fusing filter's own density already carries the fused history
    (feedback), so the other peer's single-radar estimate gets less than half; picked on runs
    0-3 of geometry A (0.3: 2.32 m, 0.4: 2.43 m, 0.5: 2.59 m, 0.6: 2.82 m, "det": 4.3 m)."""
    cov_floor: float = 1e-6
    """Added to summary covariance diagonals before GCI/ratio (CV acceleration variance 0)."""


class SingleTargetPeer(PeerBase):
    """A seed-001 peer; the filter is ``"imm-pf"`` or ``"imm-ekf"``."""

    position_index = (0, 3)
    """Columns of (px, py) in the 6-D state ``[px, vx, ax, py, vy, ay]``."""

    def __init__(self, options: PeerOptions, kind: str, sensor: RangeBearing,
                 init_mean: np.ndarray, init_cov: np.ndarray, rng: np.random.Generator,
                 config: SingleTargetConfig | None = None) -> None:
        if kind not in FILTER_KINDS:
            raise ValueError(f"unknown single-target filter {kind!r}; expected {FILTER_KINDS}")
        if options.fusion not in ("gci", "ratio", "none"):
            raise ValueError(f"single-target peers fuse by 'gci', 'ratio' or 'none', "
                             f"not {options.fusion!r}")
        self.o = options
        self.kind = kind
        self.sensor = sensor
        self.cfg = config or SingleTargetConfig()
        self.M = len(self.cfg.imm.initial_probs)
        self.rng_local, self.rng_fused = rng.spawn(2)
        if kind == "imm-pf":
            self.pf = IMMParticleFilter(self.cfg.imm, self.cfg.particle)
            self.local = self.pf.initialise(init_mean, init_cov, self.rng_local)
            self.fused = self.pf.initialise(init_mean, init_cov, self.rng_fused)
        else:
            self.ekf = IMMEKF(self.cfg.imm)
            self.local = self.ekf.initialise(init_mean, init_cov)
            self.fused = self.ekf.initialise(init_mean, init_cov)
        self.last_k = 0
        self.alive: set[str] = set(options.neighbours)
        self.nale = NaleBuffer(max_age=0, policy="drop-late")  # counts only
        self.stats = PeerStats()
        self.records: list[dict] = []
        self._inbox: dict[tuple[int, str], dict[str, GaussianMixture]] = {}
        self._pending: tuple[int, np.ndarray] | None = None  # (k, z) awaiting fusion
        self._truth: dict[int, np.ndarray] = {}
        self._est: dict[str, dict[int, np.ndarray]] = {"local": {}, "fused": {}}
        self.err_sums = {"local": 0.0, "fused": 0.0}
        self.err_counts = {"local": 0, "fused": 0}
        self._seq = 0
        self._last_fused_summary: GaussianMixture | None = None

    # -- peer interface -------------------------------------------------------------------
    @property
    def mix(self) -> GaussianMixture:
        """The local posterior summary (what is published)."""
        return self.local.summary()

    def busy(self) -> bool:
        return self._pending is not None

    def particles(self, limit: int = 600) -> np.ndarray | None:
        """Up to ``limit`` local particle positions ``(n, 2)`` for display (PF only)."""
        if self.kind != "imm-pf":
            return None
        X = self.local.particles.reshape(-1, 6)[:, list(self.position_index)]
        step = max(1, len(X) // limit)
        return X[::step]

    def model_probabilities(self) -> dict[str, float]:
        return dict(zip(self.cfg.imm.model_names, map(float, self.fused.probs), strict=True))

    def _ll(self, z: np.ndarray):
        return lambda X: radar_log_likelihood(self.sensor, z, X)

    def _estimate(self, k: int, mix: GaussianMixture, kind: str, now: float) -> Estimate:
        self._seq += 1
        self.stats.estimates_out += 1
        self.stats.tuples_out += len(mix) * (1 + 6 + 21)
        return Estimate(self.o.name, k, mix, seq=self._seq, send_time=now, pruning=1, kind=kind)

    def on_scan(self, scan: Scan, now: float) -> list:
        if scan.k <= self.last_k:
            self.stats.stale_scans += 1
            return []
        out: list = []
        if self._pending is not None:
            out += self._fuse(now, forced=True)
        z = np.asarray(scan.z, float).reshape(-1, 2)
        self.stats.scans += 1
        self.last_k = scan.k
        floor = self.cfg.cov_floor
        if len(z) == 0:  # no detection: predict only (the summaries still go out)
            pred_mix = self._predict_local()
        elif self.kind == "imm-pf":
            self.local, pred = self.pf.step(self.local, self._ll(z[0]), self.rng_local)
            pred_mix = pred.summary()
        else:
            pred_state = self.ekf.predict(self.local)
            self.local = self.ekf.update(pred_state, z[0], self.sensor)
            pred_mix = pred_state.summary()
        self._est["local"][scan.k] = self.local.estimate
        self._score(scan.k)
        self._record(scan.k, "local", n_components=self.M, n_published=self.M)
        self._pending = (scan.k, z[0] if len(z) else None)
        if self.o.fusion != "none" and self.o.neighbours:
            out.append(self._estimate(scan.k, floored(self.local.summary(), floor),
                                      "posterior", now))
            if self.o.fusion == "ratio":
                out.append(self._estimate(scan.k, floored(pred_mix, floor), "prediction", now))
        out += self._advance(now)
        return out

    def _predict_local(self) -> GaussianMixture:
        if self.kind == "imm-pf":
            pred = self.pf.predict(self.local, self.rng_local)
            self.local = self.pf.from_gaussians(pred.probs, *pred.moments, self.rng_local)
            return pred.summary()
        self.local = self.ekf.predict(self.local)
        return self.local.summary()

    def score_local(self) -> None:
        """Scoring happens in ``on_scan`` (cheap for one target)."""

    def on_estimate(self, est: Estimate, now: float) -> list:
        if not self._from_neighbour(est):
            return []
        if est.mixture.dim != 6:
            self.stats.incompatible += 1
            return []
        current = self._pending[0] if self._pending is not None else self.last_k + 1
        if est.k < current:
            self.nale.counts.dropped_late += 1
            return []
        self._inbox.setdefault((est.k, est.kind), {})[est.sender] = est.mixture
        return self._advance(now)

    def on_deadline(self, k: int, now: float) -> list:
        if self._pending is None or self._pending[0] != k:
            return []
        return self._fuse(now, forced=True)

    def current_fused(self) -> GaussianMixture | None:
        return self._last_fused_summary

    def mean_ospa(self, kind: str) -> float:
        """Mean position error (m) of the ``"local"`` or ``"fused"`` estimates, cut at the OSPA
        cut-off (for one target and one estimate this is the OSPA distance)."""
        n = self.err_counts[kind]
        return self.err_sums[kind] / n if n else float("nan")

    # -- fusion ---------------------------------------------------------------------------
    def _needed(self) -> tuple[str, ...]:
        return ("posterior", "prediction") if self.o.fusion == "ratio" else ("posterior",)

    def _advance(self, now: float) -> list:
        if self._pending is None:
            return []
        k = self._pending[0]
        if self.o.fusion == "none" or not self.o.neighbours or all(
                n in self._inbox.get((k, kind), {}) for n in self.alive
                for kind in self._needed()):
            return self._fuse(now, forced=False)
        return []

    def _fuse(self, now: float, forced: bool) -> list:
        k, z = self._pending
        self._pending = None
        if forced:
            self.stats.deadline_fusions += 1
        posts = self._inbox.pop((k, "posterior"), {})
        preds = self._inbox.pop((k, "prediction"), {})
        for key in [key for key in self._inbox if key[0] <= k]:
            del self._inbox[key]
        senders = sorted(s for s in posts if self.o.fusion != "ratio" or s in preds)
        floor = self.cfg.cov_floor
        if z is None:  # no own measurement this scan: the fused filter only predicts
            if self.kind == "imm-pf":
                p = self.pf.predict(self.fused, self.rng_fused)
                self.fused = self.pf.from_gaussians(p.probs, *p.moments, self.rng_fused)
            else:
                self.fused = self.ekf.predict(self.fused)
        elif self.o.fusion == "gci" and senders:
            own = self._step_fused(z)
            fused = gci_summaries(floored(own.summary(), floor), [posts[s] for s in senders],
                                  self.cfg.gci_omega if len(senders) == 1 else None)
            probs, means, covs = collapse_to_models(fused, self.M)
            if np.all(np.isfinite(probs)) and np.all(np.isfinite(covs)):
                self.fused = (self.pf.from_gaussians(probs, means, covs, self.rng_fused)
                              if self.kind == "imm-pf"
                              else IMMGaussianState(probs, means, covs))
            else:  # the summaries do not overlap at all: keep the own update, count it
                self.stats.fusion_fallbacks += 1
                self.fused = own
        elif self.o.fusion == "ratio" and senders:
            ratios = [GaussianRatio.from_summaries(posts[s], preds[s], self.cfg.ratio)
                      for s in senders]
            if self.kind == "imm-pf":
                self.fused, _ = self.pf.step(
                    self.fused, self._ll(z), self.rng_fused,
                    extra_log_lik=lambda X: sum(r.log_eval(X) for r in ratios))
            else:
                own = self._step_fused(z)
                means, covs, log_norm = own.means, own.covs, np.zeros(self.M)
                for r in ratios:
                    means, covs, ln = r.apply_gaussian(means, covs)
                    log_norm = log_norm + ln
                self.fused = IMMGaussianState(model_posterior(own.probs, log_norm), means, covs)
        else:
            self.fused = self._step_fused(z)
        self.stats.fusions += 1
        self.stats.fused_inputs += len(senders)
        for s in senders:
            self.stats.last_fused_from[s] = k
        self._last_fused_summary = self.fused.summary()
        self._record(k, "fusion", round=1, n_inputs=len(senders), n_fused=self.M,
                     ages={s: 0 for s in senders})
        self._record(k, "models", **self.model_probabilities())
        self._est["fused"][k] = self.fused.estimate
        self._score(k)
        self.stats.tracks_out += 1
        self._seq += 1
        return [Tracks(self.o.name, k, self.fused.estimate[None, :], seq=self._seq,
                       send_time=now)]

    def _step_fused(self, z: np.ndarray):
        if self.kind == "imm-pf":
            state, _ = self.pf.step(self.fused, self._ll(z), self.rng_fused)
            return state
        return self.ekf.update(self.ekf.predict(self.fused), z, self.sensor)

    # -- bookkeeping ----------------------------------------------------------------------
    def _record(self, k: int, kind: str, **values) -> None:
        self.records.append({"k": k, "kind": kind, **values})

    def _score(self, k: int) -> None:
        X = self._truth.get(k)
        if X is None or len(X) == 0:
            return
        i, j = self.position_index
        for kind, est in self._est.items():
            x = est.pop(k, None)
            if x is None:
                continue
            err = float(np.hypot(x[i] - X[0, i], x[j] - X[0, j]))
            value = min(err, self.o.ospa_cutoff)
            self.err_sums[kind] += value
            self.err_counts[kind] += 1
            self._record(k, "ospa", which=kind, value=value)
        for old in [kk for kk in self._truth if kk < k - 5]:
            del self._truth[old]

