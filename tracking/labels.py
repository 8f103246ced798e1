"""Labelled GM-PHD components: tag propagation (Panta, Clark & Vo 2009) and network-wide ids.

Every component of a PHD intensity carries a label ``(origin, birth_scan, index)`` (int64): the
peer whose filter gave birth to it, the scan of that birth and its index among that scan's new
labels. Labels live in an array ``labels (n, 3)`` beside an unchanged
:class:`~tracking.mixture.GaussianMixture` (:class:`LabelledMixture`), so every unlabelled
caller and every number of the filter stay as they are: the labelled steps call the same
functions (:func:`tracking.gmphd.update_parents`, :meth:`tracking.reduction.Reducer.with_sources`)
and only gather labels by the indices they return.

Tag rules (Panta, Clark & Vo 2009, IEEE TAES 45(3), §IV, "track labelling"; our reading):

* predict: a surviving component keeps its label; each birth component gets a new label
  ``(origin, k, i)``, ``i = 0 .. n_birth - 1``;
* update: the missed-detection term of component ``j`` and every detection term ``(z, j)``
  inherit ``j``'s label (several components now share one);
* prune / cap: labels leave with their components; merge: the merged component takes the label
  of the heaviest member of its group (the sweep's centre);
* duplicates (the paper's split rule, after the reduction): where several components above the
  extraction threshold share a label, the heaviest keeps it and each other one gets a new label
  ``(origin, k, n_birth + i)``; lighter sharers keep the shared label (not yet targets);
* extraction returns the labels of the extracted components;
* confirmation (:class:`Confirmation`): a label is confirmed once a component carrying it has
  had weight above the extraction threshold in ``scans`` scans (not necessarily consecutive)
  and, on a network, once it is ``settle`` scans old (its ``birth_scan`` that many scans back:
  an earlier label of the same target has then had time to arrive, see :class:`Confirmation`);
  it stays confirmed while any component carries it, and is forgotten when none does;
* first publication (:class:`Publication`): an own label whose track first goes onto the
  network takes ``(origin, k, PUBLISHED_BASE + i)``, so "earliest birth" means earliest on
  the network.

Across peers, :func:`match_labels` pairs a neighbour's tracks with ours (SciPy
``linear_sum_assignment`` on the Mahalanobis distance ``(m_i - n_j)^T (P_i + Q_j)^-1
(m_i - n_j)``, gated) and :func:`adopt_labels` applies the network rule: a matched pair takes
the smaller label in the order ``(birth_scan, origin, index)`` (earliest birth, then lowest
origin id), so every peer converges on one id per target whichever fuses first.

The label rows and :class:`LabelledMixture` live in :mod:`tracking.label_keys`, confirmation and
publication in :mod:`tracking.label_confirmation`, matching across peers in
:mod:`tracking.label_matching` (issue 37); every name stays importable from here.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from sensornet.tracking.gmphd import GMPHDFilter, SensorParams, extract_index, update_parents
from sensornet.tracking.gmphd import predict as gm_predict
from sensornet.tracking.label_confirmation import REPUBLISH_GAP, Confirmation, Publication
from sensornet.tracking.label_keys import (
    LABEL_COLUMNS,
    PUBLISHED_BASE,
    SHARED_ORIGIN,
    LabelledMixture,
    as_labels,
    label_keys,
    new_labels,
    precedes,
)
from sensornet.tracking.label_matching import LabelMatch, adopt_labels, match_labels
from sensornet.tracking.mixture import GaussianMixture
from sensornet.tracking.models import ConstantVelocity
from sensornet.tracking.reduction import Reducer


# -- the filter's steps with labels -------------------------------------------------------------
def predict_labelled(lm: LabelledMixture, motion: ConstantVelocity, survival_probability: float,
                     birth: GaussianMixture | None, k: int, origin: int,
                     steps: int = 1) -> LabelledMixture:
    """:func:`tracking.gmphd.predict` (the same numbers); survivors keep their labels, births
    get ``(origin, k, 0 .. n_birth - 1)``."""
    mix = gm_predict(lm.mixture, motion, survival_probability, birth, steps)
    nb = len(mix) - len(lm)
    labels = lm.labels if nb == 0 else np.concatenate((lm.labels, new_labels(origin, k, nb)))
    return LabelledMixture(mix, labels)


def update_labelled(lm: LabelledMixture, scan: np.ndarray, sensor: SensorParams,
                    gate: float | None = None, min_weight: float = 0.0) -> LabelledMixture:
    """:func:`tracking.gmphd.update` (the same numbers); missed and detection terms inherit
    the label of the predicted component they come from (Panta et al. 2009, §IV)."""
    mix, parents = update_parents(lm.mixture, scan, sensor, gate, min_weight)
    return LabelledMixture(mix, np.concatenate((lm.labels, lm.labels[parents])))


def reduce_labelled(reducer: Reducer, lm: LabelledMixture) -> LabelledMixture:
    """``reducer(mix)`` (the same numbers); each kept or merged component takes the label of
    the heaviest member of its merge group; pruned and capped labels are dropped."""
    mix, src = reducer.with_sources(lm.mixture)
    return LabelledMixture(mix, lm.labels[src])


def split_duplicates(lm: LabelledMixture, threshold: float, origin: int, k: int,
                     start: int = 0) -> LabelledMixture:
    """Panta et al.'s rule for a label shared by several components heavier than
    ``threshold``: the heaviest keeps it, each other gets ``(origin, k, start + i)`` in order
    of decreasing weight. Components at or below ``threshold`` keep their labels."""
    w = lm.mixture.weights
    above = (w > threshold).nonzero()[0]
    if above.size <= 1:
        return lm
    lab = lm.labels[above]
    by = np.lexsort((-w[above], lab[:, 2], lab[:, 1], lab[:, 0]))  # label, heaviest first
    s = lab[by]
    dup = np.zeros(above.size, dtype=bool)
    dup[1:] = (s[1:] == s[:-1]).all(axis=1)
    if not dup.any():
        return lm
    rows = above[by[dup]]
    rows = rows[np.argsort(-w[rows], kind="stable")]
    labels = lm.labels.copy()
    labels[rows] = new_labels(origin, k, rows.size, start)
    return LabelledMixture(lm.mixture, labels)


def step_labels_many(labels: Sequence[np.ndarray], parents: Sequence[np.ndarray],
                     weights: Sequence[np.ndarray], births: Sequence[int],
                     birth_origins: Sequence[int], origins: Sequence[int],
                     ks: Sequence[int], thresholds: Sequence[float]) -> list[np.ndarray]:
    """The posterior labels of many labelled GM-PHD steps at once (a peer host's co-hosted
    peers): for problem ``p``, the prior's ``labels[p] (n, 3)`` and ``births[p]`` birth labels
    ``(birth_origins[p], ks[p], 0 ..)`` gathered by ``parents[p]`` (tag propagation, Panta,
    Clark & Vo 2009 §IV), then :func:`split_duplicates` with ``weights[p]``,
    ``thresholds[p]``, ``origins[p]``, ``ks[p]``, start ``births[p]``. Why: the per-peer
    rule is ~15 small NumPy calls paid per peer and scan; here every problem's rows are one
    array, the sort keyed by the problem first, so each result is its own rule's to the bit
    (tests/test_step_labels_many.py)."""
    P = len(labels)
    if P == 0:
        return []
    n_prior = np.array([len(x) for x in labels], dtype=np.int64)
    nb = np.asarray(births, dtype=np.int64)
    n_pred = n_prior + nb
    pred_off = np.concatenate(([0], np.cumsum(n_pred)[:-1]))
    birth_p = np.repeat(np.arange(P), nb)
    birth = np.empty((int(nb.sum()), 3), dtype=np.int64)
    birth[:, 0] = np.asarray(birth_origins, dtype=np.int64)[birth_p]
    birth[:, 1] = np.asarray(ks, dtype=np.int64)[birth_p]
    birth[:, 2] = np.arange(len(birth)) - np.repeat(np.cumsum(nb) - nb, nb)
    b_end = np.cumsum(nb).tolist()
    parts: list[np.ndarray] = []
    for p in range(P):  # (per problem, not per row: the prior's rows, then its births)
        parts += [labels[p], birth[b_end[p] - births[p]:b_end[p]]]
    pred = np.concatenate(parts).astype(np.int64, copy=False)
    n_post = np.array([len(x) for x in parents], dtype=np.int64)
    prob = np.repeat(np.arange(P), n_post)
    par = np.concatenate(parents).astype(np.int64, copy=False) + pred_off[prob]
    out = pred[par]
    w = np.concatenate(weights)
    above = np.flatnonzero(w > np.asarray(thresholds, dtype=float)[prob])
    if above.size > 1:
        lab, pa = out[above], prob[above]
        by = np.lexsort((-w[above], lab[:, 2], lab[:, 1], lab[:, 0], pa))
        s, sp = lab[by], pa[by]
        dup = np.zeros(above.size, dtype=bool)
        dup[1:] = (s[1:] == s[:-1]).all(axis=1) & (sp[1:] == sp[:-1])
        if dup.any():
            rows = above[by[dup]]
            rows = rows[np.lexsort((-w[rows], prob[rows]))]  # per problem, heaviest first
            rp = prob[rows]
            first = np.flatnonzero(np.r_[True, rp[1:] != rp[:-1]])
            rank = np.arange(len(rows)) - np.repeat(first, np.diff(np.r_[first, len(rows)]))
            out[rows, 0] = np.asarray(origins, dtype=np.int64)[rp]
            out[rows, 1] = np.asarray(ks, dtype=np.int64)[rp]
            out[rows, 2] = nb[rp] + rank
    return np.split(out, np.cumsum(n_post)[:-1])


def extract_labelled(lm: LabelledMixture, threshold: float = 0.5,
                     rule: str = "cardinality") -> tuple[np.ndarray, np.ndarray]:
    """:func:`tracking.gmphd.extract` (the same states ``(p, d)``) and their labels
    ``(p, 3)``."""
    idx = extract_index(lm.mixture, threshold, rule)
    return lm.mixture.means[idx], lm.labels[idx]


@dataclass(frozen=True)
class ExtractedTracks:
    """What a labelled extraction reports, in the shapes of ``protocol.messages.Tracks``:
    ``states (p, d)``, ``ids (p, 3)`` int64, ``covs (p, d, d)``, ``existence (p,)`` (the
    component weight clipped to [0, 1]) and ``status (p,)`` int8 (1 confirmed, 0 tentative)."""

    states: np.ndarray
    ids: np.ndarray
    covs: np.ndarray
    existence: np.ndarray
    status: np.ndarray


def extract_tracks(lm: LabelledMixture, threshold: float = 0.5, rule: str = "cardinality",
                   confirmation: Confirmation | None = None) -> ExtractedTracks:
    """:func:`extract_labelled` with each state's covariance, existence and status (all
    tentative without a ``confirmation``), ready for a ``Tracks`` message."""
    idx = extract_index(lm.mixture, threshold, rule)
    ids = lm.labels[idx]
    status = (np.zeros(len(idx), dtype=np.int8) if confirmation is None
              else confirmation.status_rows(lm.labels, idx))
    return ExtractedTracks(lm.mixture.means[idx], ids, lm.mixture.covs[idx],
                           np.clip(lm.mixture.weights[idx], 0.0, 1.0), status)


@dataclass
class LabelledGMPHD:
    """A :class:`~tracking.gmphd.GMPHDFilter` whose components carry labels: the same numbers
    as the filter, plus the tag rules of the module docstring. ``origin``: this peer's id."""

    filter: GMPHDFilter
    origin: int
    """This peer's id: the first column of the labels its births get."""
    split_duplicates: bool = True
    """Apply Panta et al.'s duplicate rule (:func:`split_duplicates`) after each correction.
    False keeps every inherited label: no switch when clutter beside a target briefly makes
    two heavy components of one track, but then two states may report one label that scan."""

    def initial(self) -> LabelledMixture:
        return LabelledMixture.empty(self.filter.motion.dim)

    def predict(self, lm: LabelledMixture, k: int, steps: int = 1) -> LabelledMixture:
        f = self.filter
        return predict_labelled(lm, f.motion, f.survival_probability, f.birth, k, self.origin,
                                steps)

    def correct(self, lm: LabelledMixture, k: int,
                scans: Sequence[np.ndarray]) -> LabelledMixture:
        """:meth:`GMPHDFilter.correct` with labels, then the duplicate rule (new indices
        start after the births' so labels of scan ``k`` stay unique)."""
        f = self.filter
        if len(scans) != len(f.sensors):
            raise ValueError(f"expected {len(f.sensors)} scans, got {len(scans)}")
        for sensor, scan in zip(f.sensors, scans, strict=True):
            lm = update_labelled(lm, scan, sensor, f.gate, f.reducer.prune_threshold)
            lm = reduce_labelled(f.reducer, lm)
        if not self.split_duplicates:
            return lm
        nb = 0 if f.birth is None else len(f.birth)
        return split_duplicates(lm, f.extraction_threshold, self.origin, k, nb)

    def step(self, lm: LabelledMixture, k: int, *scans: np.ndarray) -> LabelledMixture:
        """Predict to scan ``k`` (one step), then correct with its scan(s)."""
        return self.correct(self.predict(lm, k), k, scans)

    def extract(self, lm: LabelledMixture) -> tuple[np.ndarray, np.ndarray]:
        """States ``(p, d)`` and labels ``(p, 3)`` by the filter's extraction rule."""
        return extract_labelled(lm, self.filter.extraction_threshold, self.filter.extraction)


__all__ = [
    "LABEL_COLUMNS",
    "PUBLISHED_BASE",
    "REPUBLISH_GAP",
    "SHARED_ORIGIN",
    "Confirmation",
    "ExtractedTracks",
    "LabelMatch",
    "LabelledGMPHD",
    "LabelledMixture",
    "Publication",
    "adopt_labels",
    "as_labels",
    "extract_labelled",
    "extract_tracks",
    "label_keys",
    "match_labels",
    "new_labels",
    "precedes",
    "predict_labelled",
    "reduce_labelled",
    "split_duplicates",
    "update_labelled",
]
