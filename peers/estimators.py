"""Local estimators behind :class:`peers.contracts.LocalEstimator`: GM-PHD, IMM-PF, IMM-EKF."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from sensornet.peers.contracts import LocalOutput
from sensornet.peers.gmphd_own_times import WIDE_SD, check_filter, step_at_own_times
from sensornet.peers.labelling import take_moves
from sensornet.peers.lmb_own_times import OwnTimes
from sensornet.peers.stamp_moves import MovingStamps
from sensornet.peers.step_atomic import atomic
from sensornet.tracking.gmphd import GMPHDFilter
from sensornet.tracking.gmphd_batch import correct_parents, step_many
from sensornet.tracking.imm import IMMEKF, IMMParams, radar_log_likelihood
from sensornet.tracking.label_confirmation import stamp_known_many
from sensornet.tracking.labels import (
    SHARED_ORIGIN,
    Confirmation,
    ExtractedTracks,
    LabelledMixture,
    LabelMatch,
    Publication,
    adopt_labels,
    as_labels,
    extract_tracks,
    new_labels,
    split_duplicates,
    step_labels_many,
)
from sensornet.tracking.mixture import GaussianMixture
from sensornet.tracking.models import RangeBearing
from sensornet.tracking.particles import IMMParticleFilter, ParticleParams, RatioConfig, floored
from sensornet.tracking.reidentify import REID_SCANS, Reidentification


@dataclass(frozen=True)
class SingleTargetConfig:
    """Filter and fusion settings of a single-target peer (defaults: the seed-001 study's)."""

    imm: IMMParams = field(default_factory=IMMParams)
    """Models, Markov matrix, initial model probabilities."""
    particle: ParticleParams = field(default_factory=ParticleParams)
    """Particles per model and regularisation jitter (IMM-PF)."""
    ratio: RatioConfig = field(default_factory=RatioConfig)
    """Particle fusion rule: ratio on position only, clipped (docs/seed001.md)."""
    gci_omega: float | str | None = 0.15
    """GCI weight of the other peer: a number, None (0.5), or "det" (minimum fused determinant,
    chosen per scan). The fusing filter's own density already carries the fused history
    (feedback), so the other peer's single-radar estimate gets much less than half; 0.15 was
    tuned on geometry A's runs 10000.. (never evaluated): docs/seed001.md, "Choosing the GCI
    weight"."""
    cov_floor: float = 1e-6
    """Added to summary covariance diagonals before GCI/ratio (CV acceleration variance 0)."""


@dataclass(frozen=True)
class _Ready:
    """A prepared step's label stage (:meth:`GmphdEstimator._prepare_labels`): the prior's
    labels, scan and birth count it assumed, the posterior labels; the publication threshold,
    the stamp's memory where nothing is stamped (None: stamp runs) and the memory it was
    computed from; re-identification's memory where it only keeps the same tracks (None:
    apply runs) and the memory it was computed from."""

    prior: np.ndarray
    k: int
    births: int
    labels: np.ndarray
    pub_at: float
    known: tuple | None
    pub_keys: np.ndarray
    pub_last: np.ndarray
    same: tuple | None
    reid_on: tuple | None
    reid_lost: tuple | None
    reid_last: tuple | None


class GmphdEstimator:
    """A GM-PHD filter on one sensor (seed 000); publishes the level-2 pruned posterior.

    With an ``origin`` (this peer's label origin: :func:`peers.labelling.origin_of`) its
    components carry labels beside the mixture (tracking.labels: Panta, Clark & Vo 2009 tag
    propagation, then Panta's duplicate rule) and what it publishes carries them: the labels
    only gather rows by the indices the filter's own steps return, so every number is what the
    unlabelled filter computes. ``origin=None``: no labels (``labels`` stays None).

    ``shared_births``: the filter's birth components are the same at every peer (fixed birth
    points), so a birth is labelled ``(SHARED_ORIGIN, k, i)`` as every peer labels it, not with
    this peer's origin (which must then differ from :data:`tracking.label_keys.SHARED_ORIGIN`);
    peers that start a target's track from the same birth component agree on its id at once."""

    kinds = ("posterior",)
    position_index = (0, 2)

    def __init__(self, filt: GMPHDFilter, level2: bool = True,
                 level2_threshold: float = 0.5, origin: int | None = None,
                 shared_births: bool = False, revisit: int = 1,
                 corroborate_scans: int = 1, own_times: OwnTimes | None = None) -> None:
        if own_times is not None:
            check_filter(filt)
        self.own_times = own_times
        """Plots with ages (:meth:`plot_ages`) taken at their own times within the tick
        (:mod:`peers.gmphd_own_times`); None: every plot at the tick."""
        self.wide_sd: float | None = WIDE_SD
        """At its own times, components wider than this (m of position sd) are dropped before
        each slice's correction (:data:`peers.gmphd_own_times.WIDE_SD`); None: kept."""
        self._ages: np.ndarray | None = None
        self.filter = filt
        self.reducer = filt.reducer
        self.level2 = level2
        self.level2_threshold = level2_threshold
        self.mix = filt.initial()
        self.dim = self.mix.dim
        if origin is not None and (not isinstance(origin, int | np.integer) or origin < 0):
            raise ValueError(f"origin must be a non-negative integer, got {origin!r}")
        if shared_births and origin == SHARED_ORIGIN:
            raise ValueError(f"origin {origin} is the shared births' (SHARED_ORIGIN): with "
                             f"shared_births own origins start at {SHARED_ORIGIN + 1}")
        self.origin = None if origin is None else int(origin)
        """The first column of this peer's own labels (splits, fusion); None: unlabelled."""
        self.birth_origin = SHARED_ORIGIN if shared_births else self.origin
        """The first column of the labels of this peer's births."""
        self.labels = None if origin is None else np.zeros((0, 3), dtype=np.int64)
        """``(n, 3)`` int64, one label per component of :attr:`mix` (None: unlabelled)."""
        shared = SHARED_ORIGIN if shared_births else None
        self.publication = None if origin is None else Publication(self.origin, shared=shared,
                                                                   revisit=revisit)
        """Which labels have been on the network: an own label is stamped ``(origin, k,
        PUBLISHED_BASE + i)`` when first published (a shared birth ``(SHARED_ORIGIN, k,
        PUBLISHED_BASE + i)``), any label again when it returns after a long gap
        (tracking.labels.Publication; the gap counted in looks of ``revisit`` scans: a rotating
        radar's rotation)."""
        self.reid = (None if origin is None
                     else Reidentification(filt.motion, self.origin, shared=shared,
                                           scans=REID_SCANS * revisit))
        """A re-born track takes its lost label back (tracking.reidentify), remembered for
        :data:`tracking.reidentify.REID_SCANS` looks of ``revisit`` scans (a 10 s radar sees a
        target once in 5 scans of 2 s: 3 scans ended the memory before its next look)."""
        self.moving = None if origin is None else MovingStamps(corroborate_scans)
        """Own labels an uncorroborated stamp moved a scan later, offered to move again while
        within ``corroborate_scans`` scans of their first stamp (peers.stamp_moves)."""
        self._stamped = np.zeros((0, 3), dtype=np.int64)
        """The last step's stamps and moving labels (:meth:`fresh_stamps`)."""
        self.k = 0
        """The scan of the last step (births are stamped with it)."""
        self._next_k: int | None = None
        self._prepared: tuple | None = None
        """``(prior, steps, z, posterior, parents, labels)`` from :meth:`prepare_many`;
        ``labels``: None or a :class:`_Ready`."""
        self.prepared_hits = 0
        """Steps that used a prepared posterior (for the summary and tests)."""
        self.prepared_label_hits = 0
        """Steps that used prepared posterior labels (:meth:`_prepare_labels`; tests)."""
        self.prepared_stamp_hits = 0
        """Steps whose stamp was prepared with nothing to stamp (tracking.label_confirmation
        .stamp_known_many; tests)."""
        self.prepared_reid_hits = 0
        """Steps whose re-identification was prepared (Reidentification.same_many; tests)."""

    @staticmethod
    def prepare_many(estimators: Sequence[GmphdEstimator], steps: Sequence[int],
                     scans: Sequence[np.ndarray]) -> None:
        """The next step of each estimator (``steps`` ahead, with scan ``z``) computed for
        all at once (:func:`tracking.gmphd_batch.step_many`: a peer host's co-hosted peers);
        each :meth:`step` then takes its result if it is asked exactly that step from the same
        prior (anything else, and it computes its own: a prepared step never changes what a
        step gives, only where its arithmetic is done). The parents of each posterior
        component come along, so a labelled estimator's labels follow without a second step."""
        tick = [i for i, e in enumerate(estimators) if e.own_times is None]
        if len(tick) < len(estimators):  # plots at their own times: each steps on its own
            estimators = [estimators[i] for i in tick]  # (a prepared tick step would
            steps = [steps[i] for i in tick]            # move its filter's pending births)
            scans = [scans[i] for i in tick]
        if not estimators:
            return
        posts = step_many([e.filter for e in estimators], [e.mix for e in estimators],
                          steps, scans, parents=True)  # raises before any is touched
        for e, s, z, (post, par) in zip(estimators, steps, scans, posts, strict=True):
            e._prepared = (e.mix, int(s), z, post, par, None)
        GmphdEstimator._prepare_labels(estimators, steps, posts)

    @staticmethod
    def _prepare_labels(estimators: Sequence[GmphdEstimator], steps: Sequence[int],
                        posts: list) -> None:
        """The posterior labels of the prepared steps of the labelled ``estimators`` (what
        :meth:`_step_labels` gives), all in one :func:`tracking.labels.step_labels_many`,
        for the scan ``k + steps``; kept beside the posterior with the prior's labels, that
        scan and the birth count, and taken only if the step is that one (:meth:`step`).
        Their stamps and re-identification too where these only keep their memory (the usual
        scan: :func:`tracking.label_confirmation.stamp_known_many`,
        :meth:`tracking.reidentify.Reidentification.same_many`), taken only if that memory is
        still the one they were computed from."""
        use = [i for i, e in enumerate(estimators) if e.labels is not None]
        if len(use) < 2:  # one peer: its own step is as cheap
            return
        es = [estimators[i] for i in use]
        ks = [e.k + int(steps[i]) for e, i in zip(es, use, strict=True)]
        nbs = [0 if e.filter.birth is None else len(e.filter.birth) for e in es]
        try:
            out = step_labels_many([e.labels for e in es], [posts[i][1] for i in use],
                                   [posts[i][0].weights for i in use], nbs,
                                   [e.birth_origin for e in es], [e.origin for e in es], ks,
                                   [e.filter.extraction_threshold for e in es])
        except Exception:  # noqa: BLE001 - not prepared: each step labels its own
            return
        pub_at = [e.level2_threshold if e.level2 else e.filter.extraction_threshold for e in es]
        try:
            known = stamp_known_many([e.publication for e in es], out,
                                     [posts[i][0].weights for i in use], pub_at, ks)
            same = Reidentification.same_many([e.reid for e in es], out,
                                              [posts[i][0] for i in use], pub_at, ks)
        except Exception:  # noqa: BLE001 - each step stamps and re-identifies its own
            known = same = [None] * len(es)
        for e, k, nb, lab, at, kn, sm in zip(es, ks, nbs, out, pub_at, known, same,
                                              strict=True):
            pb, rd = e.publication, e.reid
            e._prepared = e._prepared[:5] + (_Ready(e.labels, k, nb, lab, at, kn, pb._keys,
                                                    pb._last, sm, rd._on, rd._lost,
                                                    rd._last),)

    def begin_scan(self, k: int) -> None:
        """The scan index of the next :meth:`step` (a consensus calls it first; without it
        the index counts the steps)."""
        self._next_k = int(k)

    def atomic_parts(self) -> tuple:
        """What a step or relabel may change (:func:`peers.step_atomic.atomic`): the
        estimator (mixture, labels, scan), its filter (a measurement-birth filter's pending
        births and scan: sim.world.birth.MeasurementBirthGMPHD) and its label bookkeeping."""
        return self, self.filter, self.publication, self.reid, self.moving

    def atomic_streams(self) -> tuple:
        return ()

    @atomic
    def step(self, steps: int, z: np.ndarray) -> LocalOutput:
        """Predict ``steps`` scans, correct with ``z``; the labels and their bookkeeping
        follow. All or nothing: if it raises, the estimator is as before (peers.step_atomic)."""
        prep, self._prepared = self._prepared, None
        k = self.k + steps if self._next_k is None else self._next_k
        self._next_k = None
        par, ready, own = None, None, self._own_times_step(z, k)
        if own is not None:
            post = own[0]
        elif (prep is not None and prep[0] is self.mix and prep[1] == steps
                and (prep[2] is z or np.array_equal(prep[2], z))):
            post, par, ready = prep[3], prep[4], prep[5]
            self.prepared_hits += 1
        elif self.labels is None:
            post = self.filter.correct(self.filter.predict(self.mix, steps), [z])
        else:
            post, par = correct_parents(self.filter, self.filter.predict(self.mix, steps), [z])
        if self.labels is not None:
            pub_at = self.level2_threshold if self.level2 else self.filter.extraction_threshold
            if own is not None:
                self.labels = own[1]
            elif (ready is not None and ready.prior is self.labels and ready.k == k
                    and ready.births == (0 if self.filter.birth is None
                                         else len(self.filter.birth))):
                self.labels = ready.labels  # the prepared labels: _step_labels' to the bit
                self.prepared_label_hits += 1
            else:
                self.labels, ready = self._step_labels(post, par, k), None
            pb, rd = self.publication, self.reid
            if (ready is not None and ready.known is not None and ready.pub_keys is pb._keys
                    and ready.pub_last is pb._last and ready.pub_at == pub_at):
                pb.take_known(ready.known, k)  # nothing to stamp: stamp's memory, prepared
                self.prepared_stamp_hits += 1
                if (ready.same is not None and ready.reid_on is rd._on
                        and ready.reid_lost is rd._lost and ready.reid_last is rd._last):
                    rd.take_same(ready.same)  # the same tracks: apply's memory, prepared
                    self.prepared_reid_hits += 1
                else:
                    self.labels = rd.apply(self.labels, post, pub_at, k)
            else:
                self.labels = pb.stamp(self.labels, post.weights, pub_at, k)
                self.labels = rd.apply(self.labels, post, pub_at, k)
            on = post.weights > pub_at
            self.labels, anew = self.moving.returning(self.labels, on, self.origin, k)
            self.publication.adopt(anew)
            again = self.moving.offer(k, self.labels[on])
            self._stamped = (np.concatenate([self.publication.stamped, anew, again])
                             if len(anew) or len(again) else self.publication.stamped)
        self.mix, self.k = post, k
        keep = (self.mix.weights > self.level2_threshold if self.level2 and len(self.mix)
                else None)
        pub = self.mix.select(keep) if keep is not None else self.mix
        labels = None
        if self.labels is not None:
            labels = {"posterior": self.labels[keep] if keep is not None else self.labels}
        return LocalOutput(self.mix, {"posterior": pub},
                           {"n_components": len(self.mix), "n_published": len(pub)},
                           labels=labels, density_labels=self.labels)

    def plot_ages(self, ages: np.ndarray | None) -> None:
        """The ages ``(m,)`` of the next step's plots (s before the scan's time), or None."""
        self._ages = ages

    def _own_times_step(self, z: np.ndarray, k: int) -> tuple | None:
        """``(posterior, labels)`` of scan ``k``'s plots taken at their own times
        (:mod:`peers.gmphd_own_times`) if :attr:`own_times` is on and the scan came with ages;
        else None (the tick step)."""
        ages, self._ages = self._ages, None
        if self.own_times is None or ages is None:
            return None
        return step_at_own_times(self.filter, self.mix, self.labels, z, ages,
                                 self.k * self.own_times.T, k, self.own_times, self.origin,
                                 self.birth_origin, self.wide_sd)

    def _step_labels(self, post: GaussianMixture, parents: np.ndarray, k: int) -> np.ndarray:
        """Labels of the posterior: each component its parent's (survivors keep theirs,
        births get ``(birth_origin, k, i)``), then the duplicate rule (tracking.labels)."""
        f = self.filter
        nb = 0 if f.birth is None else len(f.birth)
        pred = np.concatenate((self.labels, new_labels(self.birth_origin, k, nb)))
        lm = LabelledMixture(post, pred[parents])
        return split_duplicates(lm, f.extraction_threshold, self.origin, k, nb).labels

    def predict(self, mix: GaussianMixture, steps: int) -> GaussianMixture:
        """NALE multi-step prediction (births added once), seed 000 §3.2. Components keep
        their order (births are appended), so a neighbour's labels still fit its rows."""
        return self.filter.predict(mix, steps) if steps > 0 else mix

    def extract(self, mix: GaussianMixture) -> np.ndarray:
        return self.filter.extract(mix)

    def extract_tracks(self, mix: GaussianMixture, labels: np.ndarray,
                       confirmation: Confirmation | None = None) -> ExtractedTracks:
        """:meth:`extract`'s states (the same rows) with their labels, covariances,
        existence (weight clipped to 1) and status (tracking.labels.extract_tracks)."""
        return extract_tracks(LabelledMixture(mix, labels), self.filter.extraction_threshold,
                              self.filter.extraction, confirmation)

    @atomic
    def adopt(self, fused: GaussianMixture) -> None:
        self.mix = fused
        if self.labels is not None:  # until adopt_labels: one fresh label per component
            self.labels = new_labels(self.origin, self.k, len(fused), 1 << 40)

    def adopt_labels(self, labels: np.ndarray) -> None:
        """The labels of the fused density :meth:`adopt` took (feedback)."""
        if self.labels is not None:
            self.labels = as_labels(labels, len(self.mix), "adopted labels")

    def fresh_stamps(self) -> np.ndarray | None:
        """The labels ``(b, 3)`` the last step stamped at first publication
        (tracking.labels.Publication.stamped) and those an earlier move left uncorroborated that
        may move again (:attr:`moving`); None: no labels."""
        return None if self.publication is None else self._stamped

    @atomic
    def relabel(self, match: LabelMatch) -> None:
        """Take the network's labels for our own (tracking.labels.adopt_labels: each matched
        own label becomes the winner of the fusion it went into, on every component that
        carries it). All or nothing, as :meth:`step`."""
        if self.labels is not None:
            moved = match.nbr
            before = self.labels
            self.labels, match = take_moves(self.labels, match, self._stamped)
            self.moving.note(before, self.labels, self.k)
            self.labels = adopt_labels(self.labels, match)
            self.publication.adopt(moved)


class ImmEstimator:
    """A seed-001 single-target IMM filter (particle ``"imm-pf"`` or EKF ``"imm-ekf"``) on one
    radar; publishes its posterior summary (one Gaussian per model, 6-D) and, for the particle
    ratio rule, its predicted summary (``"prediction"``)."""

    dim = 6
    position_index = (0, 3)

    def __init__(self, kind: str, imm: IMMParams, particle: ParticleParams,
                 sensor: RangeBearing, init_mean: np.ndarray, init_cov: np.ndarray,
                 rng: np.random.Generator | None, cov_floor: float = 1e-6,
                 with_prediction: bool = False) -> None:
        if kind not in ("imm-pf", "imm-ekf"):
            raise ValueError(f"unknown single-target filter {kind!r}; "
                             f"expected 'imm-pf' or 'imm-ekf'")
        self.kind = kind
        self.sensor = sensor
        self.cov_floor = cov_floor
        self.rng = rng
        self.kinds = ("posterior", "prediction") if with_prediction else ("posterior",)
        self.n_models = len(imm.initial_probs)
        self.model_names = tuple(imm.model_names)
        if kind == "imm-pf":
            self.pf = IMMParticleFilter(imm, particle)
            self.state = self.pf.initialise(init_mean, init_cov, rng)
        else:
            self.ekf = IMMEKF(imm)
            self.state = self.ekf.initialise(init_mean, init_cov)

    def step(self, steps: int, z: np.ndarray) -> LocalOutput:
        z = np.asarray(z, float).reshape(-1, 2)
        self.state, pred = step_imm(self, self.state, z, self.rng)
        floor = self.cov_floor
        pub = {"posterior": floored(self.state.summary(), floor)}
        if "prediction" in self.kinds:
            pub["prediction"] = floored(pred, floor)
        return LocalOutput(self.state.summary(), pub,
                           {"n_components": self.n_models, "n_published": self.n_models})

    def predict(self, mix: GaussianMixture, steps: int) -> GaussianMixture:
        return mix  # single-target peers fuse only estimates of the same scan

    def extract(self, mix: GaussianMixture) -> np.ndarray:
        """The IMM output combination ``sum_j mu_j x_j`` (seed 001 eq. 18) as one row."""
        return (mix.weights @ mix.means)[None, :]

    def adopt(self, fused: GaussianMixture) -> None:
        """The published estimate stays this radar's own (no double counting): nothing."""

    def particles(self, limit: int = 600) -> np.ndarray | None:
        """Up to ``limit`` particle positions ``(n, 2)`` for display (IMM-PF only)."""
        if self.kind != "imm-pf":
            return None
        X = self.state.particles.reshape(-1, 6)[:, list(self.position_index)]
        return X[:: max(1, len(X) // limit)]


def step_imm(est: ImmEstimator, state, z: np.ndarray, rng, extra_log_lik=None):
    """One IMM step of ``state`` with the first return of ``z`` (predict only if none):
    ``(posterior state, predicted summary)``. Shared by the local filter and the fusers."""
    if est.kind == "imm-pf":
        pf = est.pf
        if len(z) == 0:
            pred = pf.predict(state, rng)
            return pf.from_gaussians(pred.probs, *pred.moments, rng), pred.summary()
        z0 = z[0]
        post, pred = pf.step(state, lambda X: radar_log_likelihood(est.sensor, z0, X), rng,
                             extra_log_lik=extra_log_lik)
        return post, pred.summary()
    pred_state = est.ekf.predict(state)
    if len(z) == 0:
        return pred_state, pred_state.summary()
    return est.ekf.update(pred_state, z[0], est.sensor), pred_state.summary()
