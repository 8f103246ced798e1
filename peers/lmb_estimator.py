"""A labelled multi-Bernoulli (LMB) filter behind :class:`peers.contracts.LocalEstimator`.

The peer runs :class:`tracking.lmb.LmbFilter` (Reuter, Vo, Vo & Dietmayer 2014) on its own
scans and publishes the LMB's first moment, its PHD ``D(x) = sum_i r_i p_i(x)`` (Reuter eq. 6
integrated over the other targets): one Gaussian per track component, weight ``r_i w_ik``, each
row beside its track's label. So the mixture fusers (hybrid, GCI, AA) fuse it unchanged, as they
fuse a GM-PHD's intensity, and the labelling pipeline (:mod:`peers.labelling`) gives the fused
components network-wide ids from those labels.

What the LMB keeps to itself: its tracks' existence and per-track mixtures, the confirmation
counts and the adaptive births waiting for the next scan. The local tracks are extracted by the
LMB's own rule (``r >= extraction_threshold``, each by its heaviest component, its confirmed
status from the filter's counts); a fused (or any other) mixture by the GM-PHD's rule with the
scenario's extraction settings (:func:`tracking.gmphd.extract_index`), as a GM-PHD peer does.

Co-hosted LMB peers' steps are computed together (:meth:`LmbEstimator.prepare_many`,
:func:`tracking.lmb_batch.step_many`; :mod:`peers.batching`), each taken only if it is the very
step the peer makes, so the numbers are its own step's to the bit.
Arrays: ``c`` components, ``n`` tracks, ``d`` state dimension; labels ``(., 3)`` int64.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from sensornet.peers.contracts import LocalOutput
from sensornet.peers.labelling import take_moves
from sensornet.peers.lmb_own_times import OwnTimes, step_at_own_times
from sensornet.peers.step_atomic import atomic
from sensornet.tracking.gmphd import extract_index
from sensornet.tracking.gmphd import predict as gm_predict
from sensornet.tracking.label_confirmation import stamp_shared
from sensornet.tracking.label_keys import keys_equal, keys_find, keys_isin
from sensornet.tracking.labels import (
    Confirmation,
    ExtractedTracks,
    LabelledMixture,
    LabelMatch,
    adopt_labels,
    as_labels,
    extract_tracks,
    label_keys,
    new_labels,
)
from sensornet.tracking.lmb import EDGE_FLAG, LmbFilter, LmbState
from sensornet.tracking.lmb_batch import step_many
from sensornet.tracking.lmb_sets import LabelledBernoulliSet
from sensornet.tracking.mixture import GaussianMixture
from sensornet.tracking.reduction import Reducer

ADOPTED_BASE = 1 << 40
PUBLISHED_BASE = 1 << 36
"""Index offset of the label an own track takes when it is first published
(``(origin, k, PUBLISHED_BASE + i)``: :meth:`LmbEstimator.step`), apart from births (small),
fusions' fresh labels (``1 << 32``) and adopted ones (:data:`ADOPTED_BASE`)."""
"""Index offset of the labels an unlabelled adopted (feedback) density's tracks get, apart from
births (small indices) and fusions' fresh labels (``peers.labelling.FRESH_BASE``)."""


def phd_mixture(state: LmbState) -> tuple[GaussianMixture, np.ndarray]:
    """The LMB's PHD as a mixture ``(c,)`` (weights ``r_owner w``, the tracks' own means and
    covariances, in component order) and each component's track label ``(c, 3)``."""
    t = state.tracks
    mix = GaussianMixture.trusted(t.existence[t.owner] * t.weights, t.means, t.covs)
    return mix, t.labels[t.owner]


def lmb_from_mixture(mix: GaussianMixture, labels: np.ndarray | None, origin: int,
                     k: int) -> LabelledBernoulliSet:
    """A (fused) PHD mixture back as an LMB (feedback): one track per distinct label, ``r`` its
    components' total weight clipped to 1, its density those components renormalised; without
    labels every component its own track, labelled ``(origin, k, ADOPTED_BASE + i)``."""
    n = len(mix)
    if labels is None:
        labels = new_labels(origin, k, n, ADOPTED_BASE)
    labels = as_labels(labels, n, "adopted labels")
    if n == 0:
        return LabelledBernoulliSet.empty(mix.dim)
    _, first, owner = np.unique(label_keys(labels), return_index=True, return_inverse=True)
    order = np.argsort(owner, kind="stable")
    owner = owner[order].astype(np.int64)
    w = mix.weights[order]
    mass = np.bincount(owner, w)
    rel = np.divide(w, mass[owner], out=np.full(n, 1.0), where=mass[owner] > 0)
    rel = rel / np.bincount(owner, rel)[owner]
    return LabelledBernoulliSet.trusted(labels[first], np.clip(mass, 0.0, 1.0), rel,
                                        mix.means[order], mix.covs[order], owner)


class LmbEstimator:
    """An LMB filter on one sensor; publishes its PHD mixture with the tracks' labels.

    ``reducer``: the scenario's GM-PHD reducer, used only to bound what neighbours send
    (:class:`peers.budget.EstimateBudget` reads ``reducer`` and ``level2``) and by the fuser.
    ``publish_threshold``: tracks with ``r`` at most this are not published (the LMB form of
    level-2 pruning: per track, so a track's mixture goes out whole; None publishes every
    track). ``level2`` is False so that receivers do not prune our rows by component weight,
    which would cut parts of a track's mixture. ``extraction_threshold`` and ``extraction``:
    the GM-PHD rule for fused mixtures. ``origin``: this peer's label origin
    (:func:`peers.labelling.origin_of`); None: unlabelled output (the filter still labels its
    tracks, with origin 0)."""

    kinds = ("posterior",)
    position_index = (0, 2)
    level2 = False

    def __init__(self, filt: LmbFilter, reducer: Reducer | None = None,
                 publish_threshold: float | None = 0.5, extraction_threshold: float = 0.5,
                 extraction: str = "cardinality", origin: int | None = None,
                 tentative_threshold: float | None = None, tentative_scans: int = 2,
                 republish_gap: int | None = None, tentative_gap: int | None = None,
                 corroborate_scans: int = 1,
                 own_times: OwnTimes | None = None, adopt_states: int = 0) -> None:
        if origin is not None and (not isinstance(origin, int | np.integer) or origin < 0):
            raise ValueError(f"origin must be a non-negative integer, got {origin!r}")
        if publish_threshold is not None and not 0.0 <= publish_threshold <= 1.0:
            raise ValueError(f"publish_threshold must be in [0, 1], got {publish_threshold}")
        if tentative_threshold is not None and not 0.0 <= tentative_threshold <= 1.0:
            raise ValueError(f"tentative_threshold must be in [0, 1], got {tentative_threshold}")
        if tentative_scans < 0:
            raise ValueError(f"tentative_scans must be >= 0, got {tentative_scans}")
        if corroborate_scans < 1:
            raise ValueError(f"corroborate_scans must be >= 1, got {corroborate_scans}")
        if (isinstance(adopt_states, bool) or not isinstance(adopt_states, int | np.integer)
                or adopt_states < 0):  # a bool is an int to Python, not a scan count
            raise ValueError(f"adopt_states must be a non-negative integer, got {adopt_states!r}")
        for name, gap in (("republish_gap", republish_gap), ("tentative_gap", tentative_gap)):
            if gap is not None and gap < 0:
                raise ValueError(f"{name} must be >= 0 or None, got {gap}")
        if origin is not None and filt.origin != origin:
            raise ValueError(f"the filter's origin {filt.origin} is not the estimator's {origin}")
        extract_index(GaussianMixture.empty(filt.motion.dim), extraction_threshold,
                      extraction)  # ValueError naming a bad rule now, not at the first scan
        self.filter = filt
        self.reducer = reducer
        self.publish_threshold = publish_threshold
        self.tentative_threshold = tentative_threshold
        """Young tracks (label scan at most :attr:`tentative_scans` back) are published from
        this existence on, so a fusion can pool weak evidence of a new target
        (tracking.support.pooled_weights); None: only above ``publish_threshold``."""
        self.tentative_scans = tentative_scans
        self.republish_gap = republish_gap
        """A published label that returns after more than this many scans unpublished is
        stamped anew (tracking.label_confirmation.Publication's rule for GM-PHD peers); None:
        a label keeps its stamp while its track lives."""
        self.tentative_gap = tentative_gap
        """The same for a label only ever published as tentative (``r`` at most the
        publication threshold); None: :attr:`republish_gap`."""
        self.corroborate_scans = corroborate_scans
        """Scans after its first publication in which a label no neighbour's track corroborates
        (peers.labelling.corroborated) moves a scan later, each scan (:meth:`fresh_stamps`); 1:
        only in the scan of its first publication, as GM-PHD peers' labels."""
        self.extraction_threshold = extraction_threshold
        self.extraction = extraction
        self.adopt_states = int(adopt_states)
        """Feedback of states only (:meth:`_take_states`): 0, the whole fused density
        (:meth:`_take_adopted`); n, only the fused states of our tracks whose label is more
        than n scans old."""
        self.relabel_on_feedback = self.adopt_states > 0
        """Whether the consensus still relabels our tracks under feedback (we keep them)."""
        self.own_times = own_times
        """Plots with ages (:meth:`plot_ages`) taken at their own times within the tick
        (:mod:`peers.lmb_own_times`); None: every plot at the tick."""
        self._ages: np.ndarray | None = None
        self.origin = None if origin is None else int(origin)
        """Label origin; None: the output carries no labels (the consensus then adds none)."""
        self.state = filt.initial()
        self._gap_filter: LmbFilter | None = None
        """:meth:`filter_for`'s filter for a step after a gap (built at the first gap)."""
        self.dim = filt.motion.dim
        self.k = 0
        """The scan of the last step."""
        self._next_k: int | None = None
        self._prepared: tuple | None = None
        """``(prior state, k, z, filter, posterior state, Generator state)`` from
        :meth:`prepare_many`."""
        self.prepared_hits = 0
        """Steps that took a prepared posterior (for the summary and tests)."""
        self._last: tuple[GaussianMixture, LmbState] | None = None
        """The last step's PHD mixture (its ``density``) and the state it came from."""
        self._adopted: GaussianMixture | None = None
        self._adopted_labels: np.ndarray | None = None
        self._unpublished = np.zeros(0, dtype=bool)
        """``(n,)`` the tracks of the last step that were not published (kept on feedback)."""
        self._stamped = np.zeros((0, 3), dtype=np.int64)
        """The labels the last step stamped at first publication (:meth:`fresh_stamps`)."""
        self._moving = np.zeros((0, 3), dtype=np.int64)
        """``(m, 3)`` own labels the last relabel moved a scan later (uncorroborated stamps)."""
        self._moving_first = np.zeros(0, dtype=np.int64)
        """``(m,)`` the scan each was first stamped (before any move)."""
        self._published = label_keys(np.zeros((0, 3), dtype=np.int64))
        """Sorted keys of the labels of our tracks that have been on the network (published by
        us, or taken from it)."""
        self._last_pub = np.zeros(0, dtype=np.int64)
        """``(len(_published),)`` the scan each was last published (or taken)."""
        self._strong = np.zeros(0, dtype=bool)
        """``(len(_published),)`` whether each was published above the threshold (or taken
        from a label that was)."""

    # -- the contract ---------------------------------------------------------------------
    @staticmethod
    def prepare_many(estimators: list[LmbEstimator], steps: list[int],
                     scans: list[np.ndarray]) -> None:
        """The next filter step of each estimator (``steps`` ahead, scan ``z``) computed for all
        at once (:func:`tracking.lmb_batch.step_many`: a peer host's co-hosted peers); each
        :meth:`step` takes its result only if it makes exactly that step from the same state
        with the same filter (else it computes its own: a prepared step never changes what a
        step gives, only where its arithmetic is done). Fed-back states (``adopt_states``) are
        taken first, as the step would. Not prepared: an estimator with a whole adopted density
        to take first, or whose plots may come with ages (:attr:`own_times`)."""
        for e in estimators:  # states only (adopt_states): taken now, as the step would first
            if e._adopted is not None and e.adopt_states:
                e._take_states()
        todo = [(e, e.k + int(s), z) for e, s, z in zip(estimators, steps, scans, strict=True)
                if e._adopted is None and e.own_times is None and int(s) >= 1]
        for e in estimators:
            e._prepared = None
        if not todo:
            return
        filters = [e.filter_for(k) for e, k, _ in todo]
        got = step_many(filters, [e.state for e, *_ in todo], [z for *_, z in todo],
                        [k for _, k, _ in todo])  # raises before any estimator is touched
        for (e, k, z), f, r in zip(todo, filters, got, strict=True):
            if r is not None:
                e._prepared = (e.state, k, z, f, r[0], r[1])

    def _filter_step(self, k: int, z: np.ndarray) -> LmbState:
        """The filter's step to scan ``k`` with ``z``: the prepared one if it is this very
        step (same state, scan index, filter and plots), else computed here."""
        prep, self._prepared = self._prepared, None
        filt = self.filter_for(k)
        if (prep is not None and prep[0] is self.state and prep[1] == k and prep[3] is filt
                and (prep[2] is z or np.array_equal(prep[2], z))):
            filt._rng.bit_generator.state = prep[5]  # as after its own draws
            self.prepared_hits += 1
            return prep[4]
        return filt.step(self.state, z, k)

    def begin_scan(self, k: int) -> None:
        """The scan index of the next :meth:`step` (births are stamped with it)."""
        self._next_k = int(k)

    def plot_ages(self, ages: np.ndarray | None) -> None:
        """The ages ``(m,)`` of the next step's plots (s before the scan's time), or None."""
        self._ages = ages

    def atomic_parts(self) -> tuple:
        """What a step or relabel may change (:func:`peers.step_atomic.atomic`): the
        estimator's attributes (state, scan, publication memory, moving stamps)."""
        return (self,)

    def atomic_streams(self) -> tuple:
        """The Gibbs draws' Generators (the filter's; the gap filter's once built)."""
        gap = self._gap_filter
        return self.filter._rng, None if gap is None else gap._rng

    @atomic
    def step(self, steps: int, z: np.ndarray) -> LocalOutput:
        """Predict ``steps`` scans ahead, correct with ``z (m, dz)``; publish the PHD. With
        :attr:`own_times` and the plots' ages: each plot at its own time within the tick.
        All or nothing: if it raises, the estimator (its Gibbs stream too) is as before."""
        if steps < 1:
            raise ValueError(f"steps must be at least 1, got {steps}")
        k = self.k + steps if self._next_k is None else self._next_k
        self._next_k = None
        ages, self._ages = self._ages, None
        if self._adopted is not None:
            self._take_states() if self.adopt_states else self._take_adopted()
        if self.own_times is not None and ages is not None:
            self.state = step_at_own_times(self.filter_for(k), self.state, z, ages, k,
                                           self.own_times)
        else:
            self.state = self._filter_step(k, z)
        self.k = k
        pub = None
        if self.origin is not None and self.publish_threshold is not None:
            pub = self._stamp_first_publication(k)
        mix, labels = phd_mixture(self.state)
        self._last = (mix, self.state)
        t = self.state.tracks
        if self.publish_threshold is None:
            pub, pub_labels = mix, labels
            self._unpublished = np.zeros(len(t), dtype=bool)
        else:
            self._unpublished = ~(self._publishing(k) if pub is None else pub)
            keep = ~self._unpublished[t.owner]
            pub, pub_labels = mix.select(keep), labels[keep]
        labelled = self.origin is not None
        info = {"n_components": len(mix), "n_published": len(pub), "n_tracks": len(t),
                "n_pending_births": len(self.state.pending)}
        return LocalOutput(mix, {"posterior": pub}, info,
                           labels={"posterior": pub_labels} if labelled else None,
                           density_labels=labels if labelled else None)

    def predict(self, mix: GaussianMixture, steps: int) -> GaussianMixture:
        """A neighbour's density ``steps`` scans ahead: survivors ``Ps^steps w``, ``F m``,
        ``F P F^T + Q`` (tracking.gmphd.predict), no births (an LMB posterior holds none), so
        the rows keep their order and a neighbour's labels still fit them."""
        if steps <= 0:
            return mix
        f = self.filter
        return gm_predict(mix, f.motion, f.survival_probability, None, steps)

    def extract(self, mix: GaussianMixture) -> np.ndarray:
        """States ``(p, d)``: the LMB's tracks for its own last density, the GM-PHD rule for
        any other mixture."""
        own = self._own(mix)
        if own is not None:
            return self.filter.extract(own).states
        return mix.means[extract_index(mix, self.extraction_threshold, self.extraction)]

    def extract_tracks(self, mix: GaussianMixture, labels: np.ndarray,
                       confirmation: Confirmation | None = None) -> ExtractedTracks:
        """:meth:`extract`'s states with ids, covariances, existence and status. Our own
        density: each extracted track's ids are ``labels`` at its heaviest component's row
        (the labels given, which a relabel may have changed), existence ``r``, status the
        filter's confirmation; any other: :func:`tracking.labels.extract_tracks`."""
        own = self._own(mix)
        if own is None:
            return extract_tracks(LabelledMixture(mix, labels), self.extraction_threshold,
                                  self.extraction, confirmation)
        labels = as_labels(labels, len(mix), "labels")
        idx, rows = self.filter.extract_rows(own)  # the tracks and rows extract() reports
        t = own.tracks
        status = (own.hits[idx] >= self.filter.confirm_scans).astype(np.int8)
        return ExtractedTracks(t.means[rows], labels[rows], t.covs[rows], t.existence[idx],
                               status)

    def adopt(self, fused: GaussianMixture) -> None:
        """Feedback (``network.feedback``; the consensus calls this only then): the fused PHD
        becomes the next prior, as an LMB (:func:`lmb_from_mixture`) built at the next step
        with the labels :meth:`adopt_labels` gives (else fresh ones), beside our unpublished
        tracks. Without feedback the
        LMB keeps its own tracks and only takes the network's labels (:meth:`relabel`)."""
        self._adopted, self._adopted_labels = fused, None

    def adopt_labels(self, labels: np.ndarray) -> None:
        """The labels of the fused density :meth:`adopt` took."""
        if self._adopted is not None:
            self._adopted_labels = as_labels(labels, len(self._adopted), "adopted labels")

    @atomic
    def relabel(self, match: LabelMatch) -> None:
        """The network rule (tracking.labels.adopt_labels): each own track label the fusion
        paired with an earlier one takes the winner, unless another own track holds it."""
        t = self.state.tracks
        if self.origin is None or len(t) == 0 or len(match) == 0:
            return
        moved, match = take_moves(t.labels, match, self._stamped)
        self._note_moves(t.labels, moved)
        new = adopt_labels(moved, match)
        was, last, strong = self._lookup(label_keys(t.labels))
        self._remember(np.concatenate([self._published, label_keys(new[was])]),
                       np.concatenate([self._last_pub, last[was]]),
                       np.concatenate([self._strong, strong[was]]))
        self.state = LmbState(LabelledBernoulliSet.trusted(new, t.existence, t.weights,
                                                           t.means, t.covs, t.owner),
                              self.state.hits, self.state.k, self.state.pending)

    # -- helpers --------------------------------------------------------------------------
    def _publishing(self, k: int) -> np.ndarray:
        """``(n,)`` the tracks published at scan ``k``: ``r`` above the publication threshold,
        or a young track's above :attr:`tentative_threshold`."""
        t = self.state.tracks
        out = t.existence > self.publish_threshold
        if self.tentative_threshold is not None:
            out |= ((t.existence > self.tentative_threshold)
                    & (k - t.labels[:, 1] <= self.tentative_scans))
        return out

    def filter_for(self, k: int) -> LmbFilter:
        """The filter of the step to scan ``k``: :attr:`filter`, or after a gap (scans left
        out while the peer caught up, or lost) the same filter with LBP instead of Gibbs on
        loopy clusters beyond exact (``scalable="lbp"``). Over a gap of ``s`` scans tracks and
        pending births spread by ``s`` scans of motion, so clusters grow: on the 50-peer
        scenario's scans one peer stepping every 5th scan took 12-19 ms per step (mean; p99
        51-113) with Gibbs, 1.0 (p99 1.6) with LBP, OSPA equal (``python
        benchmarks/bench_fifty.py --gaps``); a host of LMB peers that fell behind then paid
        more per scan the further behind it was, and did not catch up."""
        f = self.filter
        if (self.state.k < 0 or k - self.state.k <= 1 or f.method != "auto"
                or f.scalable == "lbp"):
            return f
        if self._gap_filter is None:
            self._gap_filter = dataclasses.replace(f, scalable="lbp")
        return self._gap_filter

    def _stamp_first_publication(self, k: int) -> np.ndarray | None:
        """An own-born track published for the first time takes the label ``(origin, k,
        PUBLISHED_BASE + i)``: the network rule's "earliest birth" then means earliest on the
        network, so a track that sat unpublished below the threshold while a neighbour's track
        of the same target already carried the target's id cannot take that id over (the one
        fused identity switch per peer of the seed-000 twin: a track born at scan 20 published at
        24 beat the id a neighbour had published at 22). A birth labelled alike at every peer
        (``filter.shared_origin``) is stamped ``(shared, k, PUBLISHED_BASE + i)`` instead, as
        other peers stamp it (tracking.label_confirmation.stamp_shared), or own if taken. A
        label back after more than :attr:`republish_gap` (:attr:`tentative_gap` if it was only
        ever tentative) scans unpublished is stamped anew (own), so a track that went dark
        (nobody relays its label) cannot return with an early label later than the settle
        wait allows (docs/labelled-tracking.md, issue 33). Returns :meth:`_publishing`'s mask
        (None without tracks): a stamp keeps a published track published (its label's scan
        becomes ``k`` or ``k + 1``, young), so the step need not compute it again."""
        t = self.state.tracks
        self._stamped = t.labels[:0]
        moving = self._still_moving(k)
        if len(t) == 0:
            return None
        keys = label_keys(t.labels)
        was, last, strong = self._lookup(keys)
        pub = self._publishing(k)
        high = t.existence > self.publish_threshold
        weak = self.republish_gap if self.tentative_gap is None else self.tentative_gap
        back = was & pub & (k - last > np.where(strong, self._gap(self.republish_gap),
                                                self._gap(weak)) + 1)
        fresh = pub & ~was & (t.labels[:, 2] < PUBLISHED_BASE)
        new = (fresh & (t.labels[:, 0] == self.origin)) | back
        shared = self.filter.shared_origin
        alike = fresh & (t.labels[:, 0] == (-1 if shared is None else shared))
        labels = t.labels
        if new.any() or alike.any():
            labels = labels.copy()
            shared_ok = np.zeros(len(t), dtype=bool)
            if alike.any():  # shared births: (shared, k, PUBLISHED_BASE + cell) as elsewhere
                edge = alike & (labels[:, 2] & EDGE_FLAG != 0)
                labels[edge, 2] -= EDGE_FLAG
                shared_ok = stamp_shared(labels, keys, alike, new | alike, k)
                labels[edge & shared_ok, 1] += 1  # its plot near a cell edge: the next scan
                new |= alike & ~shared_ok
            held = labels[~new & (labels[:, 0] == self.origin) & (labels[:, 1] == k)
                          & (labels[:, 2] >= PUBLISHED_BASE), 2]  # moved here (take_moves)
            first = PUBLISHED_BASE if not len(held) else max(PUBLISHED_BASE, held.max() + 1)
            labels[new] = new_labels(self.origin, k, int(new.sum()), first)
            self._stamped = labels[new | shared_ok]
            self.state = LmbState(LabelledBernoulliSet.trusted(labels, t.existence, t.weights,
                                                               t.means, t.covs, t.owner),
                                  self.state.hits, self.state.k, self.state.pending)
            was &= ~(new | shared_ok)
        if len(moving):  # moved last scan, still uncorroborated: offered to move again
            again = pub & keys_isin(label_keys(labels), label_keys(moving))
            self._stamped = np.concatenate([self._stamped, labels[again]])
        on = was | pub
        self._remember(label_keys(labels[on]), np.where(pub, k, last)[on],
                       ((strong & was) | (pub & high))[on])
        return pub

    def _note_moves(self, before: np.ndarray, after: np.ndarray) -> None:
        """Remember the own labels :func:`peers.labelling.take_moves` moved (``before (n, 3)``
        -> ``after (n, 3)``) with the scan each was first stamped, for :meth:`_still_moving`."""
        diff = (before != after).any(axis=1)
        if not diff.any():
            self._moving = before[:0]
            self._moving_first = np.zeros(0, dtype=np.int64)
            return
        old = before[diff]
        first = old[:, 1].copy()
        if len(self._moving):  # a label moved before keeps the scan of its first stamp
            keys, prev = label_keys(old), label_keys(self._moving)
            by = np.argsort(prev)
            pos = np.searchsorted(prev[by], keys).clip(max=len(prev) - 1)
            seen = keys_equal(prev[by][pos], keys)
            first[seen] = self._moving_first[by[pos[seen]]]
        self._moving, self._moving_first = after[diff], first

    def _still_moving(self, k: int) -> np.ndarray:
        """``(m, 3)`` the labels moved by the last relabel that may move again at scan ``k``:
        now of scan ``k`` and first stamped less than :attr:`corroborate_scans` scans before."""
        if not len(self._moving):
            return self._moving
        ok = (self._moving[:, 1] == k) & (k - self._moving_first < self.corroborate_scans)
        return self._moving[ok]

    @staticmethod
    def _gap(gap: int | None) -> float:
        return np.inf if gap is None else float(gap)

    def _lookup(self, keys: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Whether each of ``keys (n,)`` has been on the network, the scan it last was, and
        whether it was above the publication threshold: ``(n,)`` bool, int64, bool."""
        if not len(self._published):
            z = np.zeros(len(keys), dtype=bool)
            return z, np.zeros(len(keys), dtype=np.int64), z.copy()
        known, pos = keys_find(self._published, keys)
        return (known, np.where(known, self._last_pub[pos], 0),
                known & self._strong[pos])

    def _remember(self, keys: np.ndarray, last: np.ndarray, strong: np.ndarray) -> None:
        """Keep ``keys (n,)`` as the labels on the network (a key twice: its latest scan, and
        strong if either was)."""
        order = np.lexsort((-last, keys))
        keys, last, strong = keys[order], last[order], strong[order]
        first = np.ones(len(keys), dtype=bool)
        first[1:] = ~keys_equal(keys[1:], keys[:-1])
        grp = np.cumsum(first) - 1
        anystrong = np.bincount(grp, weights=strong, minlength=int(first.sum())) > 0
        self._published, self._last_pub, self._strong = keys[first], last[first], anystrong

    def fresh_stamps(self) -> np.ndarray | None:
        """The labels ``(b, 3)`` the last step stamped at first publication (None: no
        labels)."""
        return None if self.origin is None else self._stamped

    def _own(self, mix: GaussianMixture) -> LmbState | None:
        """The state behind ``mix`` if it is our last step's density, else None."""
        last = self._last
        return last[1] if last is not None and mix is last[0] else None

    def _take_states(self) -> None:
        """Feedback of states only (``adopt_states`` n > 0): each of our tracks whose label is
        more than n scans old and that the fused density holds under its label takes those
        fused rows (weights renormalised) as its density; its existence, confirmation count
        and every other track stay ours. The diffusion of a covariance-intersection estimate
        (Hu, Xie & Zhang, "Diffusion Kalman filtering based on covariance intersection",
        IEEE TSP 60(2), 2012): the hybrid's CI states spread hop by hop without
        overconfidence, while young tracks stay independent evidence for the fusion's
        existence pool (tracking.fusion_rules.pool_existence), and the fused density's
        clutter rows never become our prior (docs/labelled-tracking.md, issue 33)."""
        fused, labels = self._adopted, self._adopted_labels
        self._adopted = self._adopted_labels = None
        old, t = self.state, self.state.tracks
        if labels is None or not len(t) or not len(fused):
            return
        kt, kf = label_keys(t.labels), label_keys(labels)
        use = (keys_isin(kf, kt) & (fused.weights > 0)
               & (self.k - labels[:, 1] > self.adopt_states))
        if not use.any():
            return
        by = np.argsort(kt, kind="stable")
        own_of = by[np.searchsorted(kt[by], kf[use])]  # the track of each fused row taken
        taken = np.zeros(len(t), dtype=bool)
        taken[own_of] = True
        keep = ~taken[t.owner]
        w = fused.weights[use]
        rel = w / np.bincount(own_of, w, minlength=len(t))[own_of]
        owner = np.concatenate([t.owner[keep], own_of])
        order = np.argsort(owner, kind="stable")
        self.state = LmbState(LabelledBernoulliSet.trusted(
            t.labels, t.existence, np.concatenate([t.weights[keep], rel])[order],
            np.concatenate([t.means[keep], fused.means[use]])[order],
            np.concatenate([t.covs[keep], fused.covs[use]])[order],
            owner[order].astype(np.int64)), old.hits, old.k, old.pending)

    def _take_adopted(self) -> None:
        """The adopted fused density as the LMB state, plus our own tracks that were not
        published (the fusion never saw them: tentative tracks would otherwise be erased every
        scan and never grow); tracks whose label we had keep their confirmation counts, the
        pending adaptive births stay."""
        fused, labels = self._adopted, self._adopted_labels
        self._adopted = self._adopted_labels = None
        old = self.state
        mine = old.tracks.select(self._unpublished)
        tracks = lmb_from_mixture(fused, labels, self.filter.origin, self.k)
        if len(mine):  # a fused label equal to a kept one (it never went out): the fused goes
            clash = keys_isin(label_keys(tracks.labels), label_keys(mine.labels))
            tracks = LabelledBernoulliSet.concatenate([tracks.select(~clash), mine])
        hits = np.zeros(len(tracks), dtype=np.int64)
        if len(old.tracks) and len(tracks):
            keys, new = label_keys(old.tracks.labels), label_keys(tracks.labels)
            by = np.argsort(keys)
            pos = np.searchsorted(keys[by], new).clip(max=len(keys) - 1)
            seen = keys[by][pos] == new
            hits[seen] = old.hits[by[pos[seen]]]
        self.state = LmbState(tracks, hits, old.k, old.pending)


__all__ = ["ADOPTED_BASE", "PUBLISHED_BASE", "LmbEstimator", "lmb_from_mixture", "phd_mixture"]
