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
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import linear_sum_assignment
from sensornet.tracking.gmphd import GMPHDFilter, SensorParams, extract_index, update_parents
from sensornet.tracking.gmphd import predict as gm_predict
from sensornet.tracking.mixture import GaussianMixture
from sensornet.tracking.models import ConstantVelocity
from sensornet.tracking.reduction import Reducer

LABEL_COLUMNS = ("origin", "birth_scan", "index")
PUBLISHED_BASE = 1 << 36
"""Index offset of the label an own track takes when it is first published (``(origin, k,
PUBLISHED_BASE + i)``: :class:`Publication`), apart from births and splits (small indices)
and a fusion's fresh labels (``peers.labelling.FRESH_BASE``)."""
"""Columns of a label array ``(n, 3)`` int64."""
_KEY = np.dtype([("origin", "<i8"), ("birth_scan", "<i8"), ("index", "<i8")])


def as_labels(labels, n: int | None = None, what: str = "labels") -> np.ndarray:
    """``labels`` as a contiguous int64 ``(n, 3)`` array, or ValueError naming ``what``."""
    a = np.asarray(labels)
    if a.size == 0:
        a = a.reshape(0, 3)
    if a.ndim != 2 or a.shape[1] != 3 or (n is not None and a.shape[0] != n):
        want = f"({n}, 3)" if n is not None else "(n, 3)"
        raise ValueError(f"{what} has shape {a.shape}, expected {want}")
    if a.dtype.kind not in "iu":
        raise ValueError(f"{what} has dtype {a.dtype}, expected integers")
    return np.ascontiguousarray(a, dtype=np.int64)


def new_labels(origin: int, k: int, count: int, start: int = 0) -> np.ndarray:
    """Fresh labels ``(origin, k, start + i)`` for ``i < count``: ``(count, 3)`` int64."""
    out = np.empty((count, 3), dtype=np.int64)
    out[:, 0] = origin
    out[:, 1] = k
    out[:, 2] = np.arange(start, start + count)
    return out


def label_keys(labels: np.ndarray) -> np.ndarray:
    """One structured scalar per label row ``(n,)``: comparable, sortable, ``np.isin``-able."""
    return np.ascontiguousarray(labels, dtype=np.int64).view(_KEY).reshape(-1)


def precedes(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise ``a < b`` for label arrays ``(n, 3)`` in the network rule's order ``(birth_scan,
    origin, index)`` (earliest birth first, then the lowest origin id): ``(n,)`` bool."""
    a = np.asarray(a, dtype=np.int64)[:, [1, 0, 2]]
    b = np.asarray(b, dtype=np.int64)[:, [1, 0, 2]]
    differ = a != b
    first = differ.argmax(axis=1)  # the first column that differs (0 if none does)
    rows = np.arange(len(a))
    return differ.any(axis=1) & (a[rows, first] < b[rows, first])


@dataclass(frozen=True)
class LabelledMixture:
    """A Gaussian mixture with one label per component.

    mixture: the intensity (``n`` components), unchanged by labelling.
    labels:  (n, 3) int64 ``(origin, birth_scan, index)``.
    """

    mixture: GaussianMixture
    labels: np.ndarray

    def __post_init__(self) -> None:
        object.__setattr__(self, "labels", as_labels(self.labels, len(self.mixture)))

    @classmethod
    def empty(cls, dim: int) -> LabelledMixture:
        return cls(GaussianMixture.empty(dim), np.zeros((0, 3), dtype=np.int64))

    def __len__(self) -> int:
        return len(self.mixture)

    def select(self, index: np.ndarray) -> LabelledMixture:
        """Components (and labels) picked by a boolean mask or an index array."""
        index = np.asarray(index)
        return LabelledMixture(self.mixture.select(index), self.labels[index])


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
    above = np.flatnonzero(w > threshold)
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
              else confirmation.status(ids))
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


@dataclass
class Confirmation:
    """Track confirmation: a label is confirmed once a component carrying it weighed more than
    ``threshold`` in ``scans`` :meth:`observe` calls (one per scan, not necessarily
    consecutive: a missed detection, which cuts a PHD weight to ``(1 - Pd) w``, does not undo
    it) and its ``birth_scan`` is at least ``settle`` scans before the scan observed last. A
    label is forgotten (its count restarts) once no component of the mixture carries it.

    ``settle`` is for networks (issue 33): the network rule (:func:`adopt_labels`) lets the
    earliest label of a target win, and a label spreads one hop per scan, so a label a peer
    holds can still be beaten by an earlier one on its way. A label born (first published,
    :class:`Publication`) at scan ``b`` can only be beaten by one published at ``b' <= b``,
    which has reached every peer within ``e`` hops by scan ``b' + e - 1``; with ``settle`` the
    peer's eccentricity in hops, a confirmed id is one no later arrival replaces (while the
    label spreads unhindered). The price is latency: a track is tentative for
    ``max(scans, settle - (k_first - b))`` scans after it appears at ``k_first``."""

    scans: int = 3
    threshold: float = 0.5
    settle: int = 0
    """Scans a label must be old (the scan observed minus its ``birth_scan``) to be confirmed;
    0: no such wait (a single filter, or labels that never change)."""
    _keys: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=_KEY), init=False,
                              repr=False)
    """Sorted keys of the labels in the mixture at the last scan."""
    _counts: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64),
                                init=False, repr=False)
    """Their counts of scans above the threshold."""
    _k: int | None = field(default=None, init=False, repr=False)
    """The scan of the last :meth:`observe` (None: not given)."""

    def __post_init__(self) -> None:
        if self.scans < 1:
            raise ValueError(f"Confirmation.scans must be at least 1, got {self.scans}")
        if self.settle < 0:
            raise ValueError(f"Confirmation.settle must be at least 0, got {self.settle}")

    def observe(self, lm: LabelledMixture, k: int | None = None) -> None:
        """Count scan ``k``: every label with a component above ``threshold`` goes up by one;
        labels no longer in the mixture are dropped. ``k`` is needed when ``settle > 0``."""
        if self.settle and k is None:
            raise ValueError("Confirmation with settle > 0 needs the scan k of each observe")
        self._k = None if k is None else int(k)
        keys = label_keys(lm.labels)
        present = np.unique(keys)
        above = np.isin(present, keys[lm.mixture.weights > self.threshold])
        counts = above.astype(np.int64)
        if self._keys.size and present.size:
            pos = np.searchsorted(self._keys, present).clip(max=self._keys.size - 1)
            seen = self._keys[pos] == present
            counts[seen] += self._counts[pos[seen]]
        self._keys, self._counts = present, counts

    def count(self, labels: np.ndarray) -> np.ndarray:
        """Scans above the threshold so far, per label row (0 if unknown): ``(n,)``."""
        keys = label_keys(as_labels(labels))
        if not self._keys.size:
            return np.zeros(keys.size, dtype=np.int64)
        pos = np.searchsorted(self._keys, keys).clip(max=self._keys.size - 1)
        return np.where(self._keys[pos] == keys, self._counts[pos], 0)

    def status(self, labels: np.ndarray) -> np.ndarray:
        """``(n,)`` int8: 1 confirmed, 0 tentative (the ``Tracks.status`` codes)."""
        labels = as_labels(labels)
        ok = self.count(labels) >= self.scans
        if self.settle and self._k is not None:
            ok &= self._k - labels[:, 1] >= self.settle
        return ok.astype(np.int8)


REPUBLISH_GAP = 3
"""Scans a published label may stay unpublished at a peer and keep its stamp
(:class:`Publication`); longer, and it is stamped anew when it returns."""


@dataclass
class Publication:
    """First publication (issue 33): what a peer's labels mean on the network.

    Each label whose components include one heavier than the publication threshold is
    published; :meth:`stamp` gives it ``(origin, k, PUBLISHED_BASE + i)`` (on every component
    carrying it, in the order of the old labels) when it is an own label (``origin``, index
    below :data:`PUBLISHED_BASE`) never published before, or any label returning after more
    than ``gap`` scans unpublished. So the network rule's "earliest birth" means "earliest on
    the network" (the LMB peers' rule, ``peers.lmb_estimator``), and

    * a GM-PHD birth component that lingered light cannot beat an id a neighbour already
      published;
    * a label that went dark but lingered light (a clutter track at a birth point, a track
      lost for a while) cannot take a target over later with its old, early stamp (a case
      traced in docs/labelled-tracking.md: such a label merged into a target's track scans
      later and replaced the target's confirmed id at 15 of 20 peers).

    A label the network gave us (:meth:`adopt`) counts as published. ``gap`` is chosen on
    training runs (docs/labelled-tracking.md); a miss or two at Pd 0.9 stays under it, and if
    the network still carries the old id the fusion gives it back (the new stamp is later)."""

    origin: int
    gap: int | None = REPUBLISH_GAP
    """None: a label once published keeps its stamp while any component carries it."""
    _keys: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=_KEY), init=False,
                              repr=False)
    """Sorted keys of the present labels that have been published."""
    _last: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64),
                              init=False, repr=False)
    """The scan each was last published."""
    _k: int = field(default=0, init=False, repr=False)

    def _lookup(self, keys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Whether each key was published, and its last scan (``(n,)`` bool, int64)."""
        if not self._keys.size:
            return np.zeros(keys.size, dtype=bool), np.zeros(keys.size, dtype=np.int64)
        pos = np.searchsorted(self._keys, keys).clip(max=self._keys.size - 1)
        known = self._keys[pos] == keys
        return known, np.where(known, self._last[pos], 0)

    def stamp(self, labels: np.ndarray, weights: np.ndarray, threshold: float,
              k: int) -> np.ndarray:
        """The labels ``(n, 3)`` of a mixture with weights ``(n,)`` at scan ``k``, the newly
        published stamped; remembers what is published (the present labels only)."""
        labels = as_labels(labels, len(weights))
        keys = label_keys(labels)
        on = np.isin(keys, keys[np.asarray(weights) > threshold])
        known, last = self._lookup(keys)
        fresh = ~known & (labels[:, 0] == self.origin) & (labels[:, 2] < PUBLISHED_BASE)
        back = known & (self.gap is not None) & (k - last > (self.gap or 0) + 1)
        new = on & (fresh | back)
        if new.any():
            uniq, inv = np.unique(keys[new], return_inverse=True)
            labels = labels.copy()
            labels[new] = new_labels(self.origin, k, len(uniq), PUBLISHED_BASE)[inv]
            keys = label_keys(labels)
            known[new] = False
        keep = on | known
        when = np.where(on, k, last)[keep]
        self._keys, idx = np.unique(keys[keep], return_index=True)
        self._last = when[idx] if self._keys.size else np.zeros(0, dtype=np.int64)
        self._k = int(k)
        return labels

    def adopt(self, labels: np.ndarray) -> None:
        """Labels the network gave us (a relabel's winners): published as of the last scan."""
        keys = np.unique(label_keys(as_labels(labels)))
        if not keys.size:
            return
        known, _ = self._lookup(keys)
        if (~known).any():
            add = keys[~known]
            allk = np.concatenate((self._keys, add))
            alll = np.concatenate((self._last, np.full(add.size, self._k, dtype=np.int64)))
            by = np.argsort(allk)
            self._keys, self._last = allk[by], alll[by]


# -- labels across peers ------------------------------------------------------------------------
@dataclass(frozen=True)
class LabelMatch:
    """Matched track pairs of two peers: ``own (p, 3)`` and ``nbr (p, 3)`` labels, ``cost
    (p,)`` their squared Mahalanobis distances (each at most the gate)."""

    own: np.ndarray
    nbr: np.ndarray
    cost: np.ndarray

    def __len__(self) -> int:
        return int(self.cost.shape[0])

    def as_dict(self) -> dict[tuple[int, int, int], tuple[int, int, int]]:
        """Neighbour label -> own label, as tuples."""
        return {tuple(b): tuple(a) for a, b in zip(self.own.tolist(), self.nbr.tolist(),
                                                    strict=True)}


def _unique_labels(labels: np.ndarray, what: str) -> None:
    s = labels[np.lexsort(labels.T)]  # rows sorted: a repeat is two equal neighbours
    if (s[1:] == s[:-1]).all(axis=1).any():  # (np.unique on label_keys: 7x the time)
        raise ValueError(f"{what} repeats a label; match tracks (one label each), not components")


def match_labels(own_labels: np.ndarray, own_means: np.ndarray, own_covs: np.ndarray,
                 nbr_labels: np.ndarray, nbr_means: np.ndarray, nbr_covs: np.ndarray,
                 gate: float) -> LabelMatch:
    """Pair a neighbour's tracks with ours: ``linear_sum_assignment`` on ``C_ij =
    (m_i - n_j)^T (P_i + Q_j)^-1 (m_i - n_j)`` (``(a, b)``, built in one stacked solve), pairs
    with ``C_ij > gate`` left unmatched (their cost capped at the gate inside the assignment).

    own_*: ``(a, 3)`` labels, ``(a, d)`` means, ``(a, d, d)`` covs; nbr_*: ``(b, ...)``
    likewise. Labels must be unique on each side (tracks, not components).
    """
    own_means = np.asarray(own_means, dtype=float)
    nbr_means = np.asarray(nbr_means, dtype=float)
    a, b = len(own_means), len(nbr_means)
    own_labels = as_labels(own_labels, a, "own_labels")
    nbr_labels = as_labels(nbr_labels, b, "nbr_labels")
    d = own_means.shape[1] if own_means.ndim == 2 else 0
    own_covs = np.asarray(own_covs, dtype=float)
    nbr_covs = np.asarray(nbr_covs, dtype=float)
    if a and own_covs.shape != (a, d, d):
        raise ValueError(f"own_covs has shape {own_covs.shape}, expected {(a, d, d)}")
    if b and (nbr_means.shape[1] != d or nbr_covs.shape != (b, d, d)):
        raise ValueError(f"nbr_means/nbr_covs have shapes {nbr_means.shape}/{nbr_covs.shape}, "
                         f"expected ({b}, {d})/({b}, {d}, {d})")
    if not gate > 0:
        raise ValueError(f"gate must be positive, got {gate}")
    _unique_labels(own_labels, "own_labels")
    _unique_labels(nbr_labels, "nbr_labels")
    none = np.zeros((0, 3), dtype=np.int64)
    if a == 0 or b == 0:
        return LabelMatch(none, none.copy(), np.zeros(0))
    diff = own_means[:, None, :] - nbr_means[None, :, :]  # (a, b, d)
    # a pair is solved only if it can pass the gate: C_ij >= |diff|^2 / lambda_max(P_i + Q_j)
    # >= |diff|^2 / (tr P_i + tr Q_j), so the rest cost more than the gate (capped to it below,
    # as they would be): the same assignment, one solve per nearby pair instead of all a x b
    trace = np.trace(own_covs, axis1=1, axis2=2)[:, None] + np.trace(nbr_covs, axis1=1, axis2=2)
    near = np.einsum("abi,abi->ab", diff, diff) <= gate * trace
    cost = np.full((a, b), np.inf)
    ii, jj = np.nonzero(near)
    dn = diff[ii, jj]
    cost[ii, jj] = np.einsum("pi,pi->p", dn, np.linalg.solve(own_covs[ii] + nbr_covs[jj],
                                                           dn[..., None])[..., 0])
    rows, cols = linear_sum_assignment(np.minimum(cost, gate))
    ok = cost[rows, cols] <= gate
    rows, cols = rows[ok], cols[ok]
    return LabelMatch(own_labels[rows], nbr_labels[cols], cost[rows, cols])


def adopt_labels(labels: np.ndarray, match: LabelMatch) -> np.ndarray:
    """The network-wide label rule: for every matched pair, components labelled with our label
    take the smaller of the two in ``(birth_scan, origin, index)`` order. ``labels (n, 3)``
    (a whole mixture's or a track list's) -> ``(n, 3)``. A pair whose winning label already
    marks one of our other components is left unchanged (two of our targets would share it).
    The rule picks the same label on both peers, so fusing A into B and B into A agree."""
    labels = as_labels(labels)
    if len(match) == 0 or len(labels) == 0:
        return labels
    win = np.where(precedes(match.nbr, match.own)[:, None], match.nbr, match.own)
    change = (label_keys(win) != label_keys(match.own))
    own_keys, win_keys = label_keys(match.own)[change], label_keys(win)[change]
    keys = label_keys(labels)
    clash = np.isin(win_keys, keys[~np.isin(keys, own_keys)])
    own_keys, win_keys = own_keys[~clash], win_keys[~clash]
    if own_keys.size == 0:
        return labels
    by = np.argsort(own_keys)
    own_sorted, new_sorted = own_keys[by], win[change][~clash][by]
    pos = np.searchsorted(own_sorted, keys).clip(max=own_sorted.size - 1)
    hit = own_sorted[pos] == keys
    out = labels.copy()
    out[hit] = new_sorted[pos[hit]]
    return out


__all__ = [
    "LABEL_COLUMNS",
    "PUBLISHED_BASE",
    "REPUBLISH_GAP",
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
