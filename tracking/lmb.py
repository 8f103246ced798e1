"""Labelled multi-Bernoulli (LMB) filter with Gaussian-mixture track densities.

Reuter, Vo, Vo & Dietmayer, "The labeled multi-Bernoulli filter", IEEE TSP 62(12), 2014.
Each track is a Bernoulli component: a label, an existence probability ``r`` and a spatial
density, a Gaussian mixture of at most ``J`` components. All tracks' components are stored flat
(``weights (c,)``, ``means (c, d)``, ``covs (c, d, d)``, ``owner (c,)``), so prediction, the
Kalman updates and the likelihoods are array operations over every component and measurement.

Labels are int64 rows ``(origin, birth_scan, index)`` as in :mod:`tracking.labels`: the peer
whose filter gave birth to the track, the scan of the birth and its index among that scan's
births (the fixed birth model's components first, then the measurement-driven births); with
``shared_origin`` births are labelled alike at every peer (the component, or the grid cell of
the birth's plot: :func:`tracking.label_keys.cell_index`, issue 33).

One scan: predict (``r+ = Ps r``, components through the motion model; Reuter eqs. 9-12),
add births (a fixed birth model, and adaptive births from the last scan's measurements that
no track explained: Reuter Sec. IV-C, eq. 31), correct (marginal association probabilities by
:mod:`tracking.lmb_association`, then the LMB approximation of the GLMB posterior, Reuter
eqs. 20-21), reduce each track's mixture, prune unlikely tracks and count confirmations.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from sensornet.tracking.gaussian import LOG_2PI, c_einsum, inv_det_spd
from sensornet.tracking.gmphd import SensorParams
from sensornet.tracking.label_keys import cell_index, new_labels, shared_births
from sensornet.tracking.lmb_association import (
    EXACT_LIMIT,
    GIBBS_TRACKS,
    METHODS,
    SCALABLE,
    marginals,
)
from sensornet.tracking.lmb_sets import LabelledBernoulliSet, reduce_components
from sensornet.tracking.mixture import GaussianMixture
from sensornet.tracking.models import ConstantVelocity

EDGE_FLAG = 1 << 33
"""Added to the index of a shared adaptive birth's label whose plot lies near a cell edge
(:attr:`LmbFilter.birth_edge`; cell indices are ``CELL_BASE + code`` with the code below
``2^32``); stripped when the label is stamped at its first publication."""


def predict(tracks: LabelledBernoulliSet, motion: ConstantVelocity, survival_probability: float,
            steps: int = 1) -> LabelledBernoulliSet:
    """Survivors: ``r+ = Ps^steps r``, each component ``F m``, ``F P F^T + Q`` (Reuter eqs. 9-12
    with a state-independent ``Ps``)."""
    if steps == 0 or len(tracks) == 0:
        return tracks
    F, Q = motion.transition(steps)
    return LabelledBernoulliSet.trusted(
        tracks.labels, tracks.existence * survival_probability**steps, tracks.weights,
        tracks.means @ F.T, F @ tracks.covs @ F.T + Q, tracks.owner)


def update(tracks: LabelledBernoulliSet, scan: np.ndarray, sensor: SensorParams,
           method: str = "auto", gate: float | None = None, min_weight: float = 0.0,
           exact_limit: int = EXACT_LIMIT, tol: float = 1e-9, scalable: str = "gibbs",
           rng: np.random.Generator | None = None, samples: int | None = None,
           gibbs_tracks: int | None = GIBBS_TRACKS) -> tuple[LabelledBernoulliSet, np.ndarray]:
    """The LMB posterior after scan ``Z (m, dz)`` (Reuter eqs. 20-21) and ``r_U (m,)``, each
    measurement's probability of belonging to a track (the adaptive birth's input, eq. 31).

    ``eta_i(z) = sum_k w_ik N(z; H m_ik, S_ik)``; association weights ``1 - r_i Pd`` (miss)
    and ``r_i Pd eta_i(z_j) / kappa`` (detect) give the marginals ``p_miss``, ``p``; then
    ``r_i' = p_miss_i r_i (1 - Pd) / (1 - r_i Pd) + sum_j p_ij`` and the track's density is
    its prior (weight of the first term) plus one Kalman-updated copy per measurement (weight
    ``p_ij``), normalised by ``r_i'``. ``gate``: pairs with ``nu^T S^-1 nu`` above it get
    likelihood 0. ``min_weight``: detection components lighter than this within their track
    are not materialised (pruning them early). No reduction here: see :func:`reduce_components`.
    ``method``, ``exact_limit``, ``tol``, ``scalable``, ``rng``, ``samples``, ``gibbs_tracks``:
    the association (:func:`lmb_association.marginals`).
    """
    Pd, kappa = sensor.detection_probability, sensor.clutter_intensity
    n, dz = len(tracks), sensor.model.dim
    scan = np.asarray(scan, dtype=float).reshape(-1, dz)
    m = len(scan)
    r, w, mean, P, owner = (tracks.existence, tracks.weights, tracks.means, tracks.covs,
                            tracks.owner)
    miss = 1.0 - r * Pd
    stay = np.divide(r * (1.0 - Pd), miss, out=np.zeros(n), where=miss > 0)
    if n == 0 or m == 0:
        return LabelledBernoulliSet.trusted(tracks.labels, stay, w, mean, P, owner), np.zeros(m)
    cols = sensor.model.selected
    if cols is not None:  # H picks state entries: H P H^T and P H^T are sub-blocks of P
        cols = list(cols)
        zhat, PHt = mean[:, cols], P[:, :, cols]  # (c, dz), (c, d, dz)
        S = PHt[:, cols, :] + sensor.model.R
    else:
        zhat, H = sensor.model.predict(mean)
        PHt = P @ H.swapaxes(1, 2)
        S = H @ PHt + sensor.model.R
    S_inv, S_det = inv_det_spd(S)
    nu = sensor.model.residual(scan[None, :, :], zhat[:, None, :])  # (c, m, dz)
    d2 = c_einsum("cmi,cij,cmj->cm", nu, S_inv, nu)
    wq = np.exp(-0.5 * (d2 + (np.log(S_det) + dz * LOG_2PI)[:, None])) * w[:, None]  # (c, m)
    if gate is not None:
        wq[d2 > gate] = 0.0
    starts = tracks.starts()
    eta = np.add.reduceat(wq, starts, axis=0)  # (n, m)
    p_miss, p = marginals(miss, (r * Pd)[:, None] * eta / kappa, method, exact_limit,
                          tol, scalable=scalable, rng=rng, samples=samples,
                          gibbs_tracks=gibbs_tracks)
    exist_miss = p_miss * stay
    r_post = exist_miss + p.sum(axis=1)
    inv_r = np.divide(1.0, r_post, out=np.zeros(n), where=r_post > 0)
    coef = np.divide(p, eta, out=np.zeros((n, m)), where=eta > 0) * inv_r[:, None]
    rel = wq * coef[owner]  # (c, m): each detection component's weight within its track
    ci, zj = np.nonzero(rel > min_weight) if min_weight > 0 else np.nonzero(rel >= 0)
    K = PHt @ S_inv  # (c, d, dz)
    P_upd = P - K @ PHt.swapaxes(1, 2)
    P_upd = 0.5 * (P_upd + P_upd.swapaxes(1, 2))
    means_upd = mean[ci] + c_einsum("kij,kj->ki", K[ci], nu[ci, zj])
    all_owner = np.concatenate((owner, owner[ci]))
    order = np.argsort(all_owner, kind="stable")
    post = LabelledBernoulliSet.trusted(
        tracks.labels, r_post,
        np.concatenate((w * (exist_miss * inv_r)[owner], rel[ci, zj]))[order],
        np.concatenate((mean, means_upd))[order],
        np.concatenate((P, P_upd[ci]))[order], all_owner[order])
    return post, p.sum(axis=0)


def adaptive_birth_existence(r_u: np.ndarray, birth_rate: float,
                             max_existence: float) -> np.ndarray:
    """Reuter et al. 2014 eq. 31, ``r_B(z) = min(r_B,max, lambda_B (1 - r_U(z)) /
    sum_xi (1 - r_U(xi)))`` per measurement ``(m,)``, with the sum floored at 1 (our change):
    as printed, a scan whose every measurement is explained (``r_U = 1 - 1e-4``, say) still
    spawns ``lambda_B`` births at them, duplicates that then steal existence from the tracks;
    with the floor such a scan spawns ``lambda_B (1 - r_U)`` and the expected number of
    births stays at most ``lambda_B``."""
    unexplained = np.clip(1.0 - r_u, 0.0, 1.0)
    return np.minimum(max_existence, birth_rate * unexplained / max(unexplained.sum(), 1.0))


def map_cardinality(existence: np.ndarray) -> int:
    """The most probable number of tracks of an LMB: the mode of the Poisson-binomial
    distribution of independent Bernoullis ``existence (n,)`` (Reuter Sec. IV-D)."""
    dist = np.ones(1)
    for r in existence.tolist():  # one convolution per track: O(n^2) in all
        dist = np.concatenate((dist * (1.0 - r), [0.0])) + np.concatenate(([0.0], dist * r))
    return int(np.argmax(dist))


@dataclass(frozen=True)
class LmbTracks:
    """What :meth:`LmbFilter.extract` reports, one row per extracted track:
    ``labels (p, 3)`` int64, ``states (p, d)`` and ``covs (p, d, d)`` (the heaviest component of
    the track's mixture), ``existence (p,)`` and ``status (p,)`` int8 (0 tentative, 1
    confirmed)."""

    labels: np.ndarray
    states: np.ndarray
    covs: np.ndarray
    existence: np.ndarray
    status: np.ndarray

    def __len__(self) -> int:
        return int(self.existence.shape[0])


@dataclass(frozen=True)
class LmbState:
    """The filter's state between scans.

    tracks:  the LMB (posterior after scan ``k``, or predicted to ``k``).
    hits:    (n,) int64 per track, scans in which its ``r`` reached the confirmation level.
    k:       the scan the tracks refer to (-1 before the first).
    pending: adaptive births from scan ``k``'s measurements, to join at the next prediction:
             one component each, its weight the birth existence ``r_B``.
    """

    tracks: LabelledBernoulliSet
    hits: np.ndarray
    k: int
    pending: GaussianMixture


EXTRACTION_RULES = ("threshold", "map")


@dataclass
class LmbFilter:
    """An LMB filter for one sensor: ``step(state, scan) -> state``, ``extract(state)``."""

    motion: ConstantVelocity
    sensor: SensorParams
    """Measurement model, ``Pd`` and clutter intensity ``kappa`` (must be > 0)."""
    survival_probability: float = 0.99
    birth: GaussianMixture | None = None
    """Fixed birth model: each component is one birth Bernoulli, ``r = weight`` (<= 1)."""
    adaptive_birth: bool = True
    """Measurement-driven births (Reuter Sec. IV-C); needs a model with ``selected`` columns."""
    birth_rate: float = 0.1
    """``lambda_B``: expected adaptive births per scan."""
    birth_max_existence: float = 0.1
    """``r_B,max``."""
    birth_velocity_std: float = 30.0
    """Std (m/s) of the unmeasured state entries of an adaptive birth (mean 0)."""
    method: str = "auto"
    """Association: ``"auto"``, ``"exact"``, ``"lbp"`` or ``"gibbs"``
    (:func:`lmb_association.marginals`)."""
    exact_limit: int = EXACT_LIMIT
    lbp_tol: float = 1e-9
    scalable: str = "gibbs"
    """What ``"auto"`` runs on a cluster with a cycle beyond ``exact_limit`` hypotheses:
    ``"gibbs"`` or ``"lbp"``."""
    gibbs_samples: int | None = None
    """Gibbs draws per such cluster (None: grows with its links)."""
    gibbs_tracks: int | None = GIBBS_TRACKS
    """Such a cluster of more tracks keeps LBP's marginals (None: Gibbs at any size;
    :data:`lmb_association.GIBBS_TRACKS`)."""
    seed: int = 0
    """Seed of the filter's Generator (the Gibbs draws): one scan sequence, one result."""
    gate: float | None = None
    """Optional gate on ``nu^T S^-1 nu``."""
    max_components: int = 5
    """``J``: components kept per track."""
    component_prune: float = 1e-4
    """Components lighter than this (within their track) are dropped."""
    merge_threshold: float = 4.0
    """Vo-Ma merge threshold ``U`` within a track."""
    existence_prune: float = 1e-3
    """Tracks (and births) with ``r`` below this are deleted."""
    extraction: str = "threshold"
    """``"threshold"`` (``r >= extraction_threshold``) or ``"map"`` (MAP cardinality)."""
    extraction_threshold: float = 0.5
    confirm_existence: float = 0.8
    """A scan counts toward confirmation when ``r`` is at least this."""
    confirm_scans: int = 3
    """Counted scans (not necessarily consecutive) after which a track is confirmed."""
    origin: int = 0
    """This peer's id: the first column of its tracks' labels."""
    shared_origin: int | None = None
    """Births labelled alike at every peer (issue 33; ``tracking.label_keys.SHARED_ORIGIN``):
    a fixed birth component ``i`` is ``(shared_origin, k, i)``, an adaptive birth ``(shared_origin,
    k, cell_index(z, birth_cell))`` by the grid cell of its plot ``z`` (two in one cell: the
    likelier keeps it, the other an own label). None: every birth ``(origin, k, .)``."""
    birth_cell: float = 200.0
    """Width (m) of the grid cells of shared adaptive-birth labels (:func:`cell_index`)."""
    birth_edge: float = 0.0
    """With :attr:`shared_origin`: an adaptive birth whose plot lies within this distance (m)
    of an edge of its cell is flagged (:data:`EDGE_FLAG` in its label's index), and its shared
    stamp at first publication takes the next scan (``peers.lmb_estimator``): a stamp other peers
    may give the target in the neighbouring cell then loses the tie to the stamps of plots
    well inside a cell (docs/labelled-tracking.md). 0: no flag."""
    _birth_cov: np.ndarray | None = field(default=None, init=False, repr=False)
    _rng: np.random.Generator | None = field(default=None, init=False, repr=False)

    def __post_init__(self) -> None:
        if self.method not in METHODS:
            raise ValueError(f"unknown association method {self.method!r}; expected {METHODS}")
        if self.scalable not in SCALABLE:
            raise ValueError(f"unknown scalable association {self.scalable!r}; "
                             f"expected {SCALABLE}")
        if self.gibbs_tracks is not None and self.gibbs_tracks < 0:
            raise ValueError(f"gibbs_tracks must be >= 0 or None, got {self.gibbs_tracks}")
        self._rng = np.random.default_rng(self.seed)
        if self.extraction not in EXTRACTION_RULES:
            raise ValueError(f"unknown extraction {self.extraction!r}; "
                             f"expected {EXTRACTION_RULES}")
        for name in ("survival_probability", "birth_max_existence", "existence_prune",
                     "confirm_existence"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ValueError(f"LmbFilter.{name} must be in [0, 1], got {getattr(self, name)}")
        if not 0.0 < self.sensor.detection_probability <= 1.0:
            raise ValueError("sensor detection_probability must be in (0, 1]")
        if not self.sensor.clutter_intensity > 0:
            raise ValueError("sensor clutter_intensity must be > 0 (use a tiny value for none)")
        if self.max_components < 1:
            raise ValueError(f"LmbFilter.max_components must be >= 1, got {self.max_components}")
        if self.birth is not None and (self.birth.weights.max(initial=0) > 1
                                       or self.birth.dim != self.motion.dim):
            raise ValueError("LmbFilter.birth needs weights <= 1 and the motion model's dim")
        if self.shared_origin is not None and self.shared_origin == self.origin:
            raise ValueError(f"LmbFilter.origin {self.origin} is shared_origin's: own origins "
                             f"must differ from the shared births' ({self.shared_origin})")
        if not (np.isfinite(self.birth_edge) and 0 <= self.birth_edge < self.birth_cell / 2):
            raise ValueError(f"LmbFilter.birth_edge must be in [0, birth_cell / 2) m, got "
                             f"{self.birth_edge!r}")
        if not (np.isfinite(self.birth_cell) and self.birth_cell > 0):
            raise ValueError(f"LmbFilter.birth_cell must be a positive number of metres, got "
                             f"{self.birth_cell!r}")
        if self.adaptive_birth:
            cols = self.sensor.model.selected
            if cols is None:
                raise ValueError("adaptive_birth needs a linear position model (selected columns)")
            d = self.motion.dim
            cov = np.eye(d) * self.birth_velocity_std**2
            cov[np.ix_(cols, cols)] = self.sensor.model.R
            self._birth_cov = cov

    def initial(self) -> LmbState:
        """No tracks, scan -1 (births arrive at the first prediction)."""
        d = self.motion.dim
        return LmbState(LabelledBernoulliSet.empty(d), np.zeros(0, dtype=np.int64), -1,
                        GaussianMixture.empty(d))

    def predict(self, state: LmbState, k: int | None = None) -> LmbState:
        """Survivors and births at scan ``k`` (default ``state.k + 1``): the fixed births get
        labels ``(origin, k, 0..nb-1)``, the pending adaptive ones ``nb..``; the pending births
        move through the motion model over the same steps. Each birth is one Bernoulli, ``r``
        its weight clipped to [0, 1] (:meth:`LabelledBernoulliSet.births`), appended to the
        survivors' arrays in one concatenation each (no intermediate sets: a scan's few tracks
        cost less than the objects around them)."""
        k = state.k + 1 if k is None else int(k)
        if k <= state.k:
            raise ValueError(f"cannot predict from scan {state.k} to scan {k}")
        steps = k - state.k if state.k >= 0 else 1
        t = predict(state.tracks, self.motion, self.survival_probability, steps)
        pend, fixed = state.pending, self.birth
        w, m, P = [], [], []
        if fixed is not None:
            w.append(fixed.weights)
            m.append(fixed.means)
            P.append(fixed.covs)
        if len(pend):
            F, Q = self.motion.transition(steps)
            w.append(pend.weights)
            m.append(pend.means @ F.T)
            P.append(F @ pend.covs @ F.T + Q)
        nb = sum(len(x) for x in w)
        n = len(t)
        if nb == 0:
            labels = np.zeros((0, 3), dtype=np.int64)
        elif self.shared_origin is not None:
            labels = self._shared_labels(pend, k)
        else:
            labels = new_labels(self.origin, k, nb)
        tracks = LabelledBernoulliSet.trusted(
            np.concatenate((t.labels, labels)),
            np.concatenate([t.existence] + [np.clip(x, 0.0, 1.0) for x in w]),
            np.concatenate((t.weights, np.ones(nb))),
            np.concatenate([t.means] + m), np.concatenate([t.covs] + P),
            np.concatenate((t.owner, np.arange(n, n + nb, dtype=np.int64))))
        hits = np.concatenate((state.hits, np.zeros(nb, dtype=np.int64)))
        return LmbState(tracks, hits, k, _empty_mixture(self.motion.dim))

    def _shared_labels(self, pending: GaussianMixture, k: int) -> np.ndarray:
        """Labels ``(nb, 3)`` of scan ``k``'s births (fixed components, then ``pending``, the
        adaptive births at their plots) made alike at every peer (:attr:`shared_origin`)."""
        nf = 0 if self.birth is None else len(self.birth)
        fixed = new_labels(self.shared_origin, k, nf)
        if not len(pending):
            return fixed
        plots = pending.means[:, list(self.sensor.model.selected)]
        cells = shared_births(cell_index(plots, self.birth_cell), pending.weights,
                              self.shared_origin, self.origin, k, nf)
        if self.birth_edge > 0:  # a plot near a cell edge: another peer's may be across it
            frac = plots / self.birth_cell - np.floor(plots / self.birth_cell)  # (nb, dz)
            near = (self.birth_cell * np.minimum(frac, 1.0 - frac) < self.birth_edge).any(axis=1)
            cells[near & (cells[:, 0] == self.shared_origin), 2] += EDGE_FLAG
        return np.concatenate((fixed, cells))

    def correct(self, state: LmbState, scan: np.ndarray) -> LmbState:
        """Update with scan ``Z (m, dz)``, reduce each track's mixture, delete tracks below
        ``existence_prune``, count confirmations and queue the adaptive births."""
        scan = check_scan(scan, self.sensor.model.dim)
        post, r_u = update(state.tracks, scan, self.sensor, self.method, self.gate,
                           self.component_prune, self.exact_limit, self.lbp_tol, self.scalable,
                           self._rng, self.gibbs_samples, self.gibbs_tracks)
        return self.finish(state, post, r_u, scan)

    def finish(self, state: LmbState, post: LabelledBernoulliSet, r_u: np.ndarray,
               scan: np.ndarray) -> LmbState:
        """The rest of :meth:`correct` after :func:`update` (``post``, ``r_u``) of the predicted
        ``state`` with ``scan`` (checked): reduce each track's mixture, then :meth:`settle`
        (:func:`tracking.lmb_batch.step_many` reduces its stacked steps together)."""
        post = reduce_components(post, self.component_prune, self.merge_threshold,
                                 self.max_components)
        return self.settle(state, post, r_u, scan)

    def settle(self, state: LmbState, post: LabelledBernoulliSet, r_u: np.ndarray,
               scan: np.ndarray) -> LmbState:
        """The end of :meth:`finish` on the reduced ``post``: delete tracks below
        ``existence_prune``, count confirmations, queue the adaptive births (reads
        ``state.hits`` and ``state.k`` only)."""
        keep = post.existence >= self.existence_prune
        hits = state.hits[keep] + (post.existence[keep] >= self.confirm_existence)
        pending = _empty_mixture(self.motion.dim)
        if self.adaptive_birth and len(scan):
            r_b = adaptive_birth_existence(r_u, self.birth_rate, self.birth_max_existence)
            born = r_b >= self.existence_prune
            nb = int(born.sum())
            means = np.zeros((nb, self.motion.dim))
            means[:, list(self.sensor.model.selected)] = scan[born]
            pending = GaussianMixture.trusted(r_b[born], means,
                                              np.repeat(self._birth_cov[None], nb, axis=0))
        return LmbState(post.select(keep), hits.astype(np.int64), state.k, pending)

    def step(self, state: LmbState, scan: np.ndarray, k: int | None = None) -> LmbState:
        """Predict to scan ``k`` (default the next), then correct with its scan."""
        return self.correct(self.predict(state, k), scan)

    def extract(self, state: LmbState) -> LmbTracks:
        """Tracks with ``r >= extraction_threshold`` (or the MAP-cardinality most likely ones),
        each reported by its heaviest component, in label order."""
        t = state.tracks
        idx, top = self.extract_rows(state)
        status = (state.hits[idx] >= self.confirm_scans).astype(np.int8)
        return LmbTracks(t.labels[idx], t.means[top], t.covs[top], t.existence[idx], status)

    def extract_rows(self, state: LmbState) -> tuple[np.ndarray, np.ndarray]:
        """The tracks :meth:`extract` reports ``(p,)`` (ascending) and each one's heaviest
        component row ``(p,)`` (for callers that report rows of their own, once)."""
        t = state.tracks
        r = t.existence
        if self.extraction == "threshold":
            idx = np.flatnonzero(r >= self.extraction_threshold)
        else:
            idx = np.sort(np.argsort(-r, kind="stable")[:map_cardinality(r)])
        return idx, t.heaviest()[idx]


def _empty_mixture(dim: int) -> GaussianMixture:
    """``GaussianMixture.empty(dim)`` without its checks (the same arrays)."""
    return GaussianMixture.trusted(np.zeros(0), np.zeros((0, dim)), np.zeros((0, dim, dim)))


def check_scan(scan: np.ndarray, dim: int) -> np.ndarray:
    """``scan`` as a float ``(m, dim)`` array, or a one-line ValueError naming the problem."""
    z = np.asarray(scan, dtype=float)
    if z.size == 0:
        return z.reshape(0, dim)
    if z.ndim != 2 or z.shape[1] != dim:
        raise ValueError(f"scan has shape {z.shape}, expected (m, {dim})")
    if not np.isfinite(z).all():
        row = int(np.flatnonzero(~np.isfinite(z).all(axis=1))[0])
        raise ValueError(f"scan row {row} is not finite: {z[row].tolist()}")
    return z


__all__ = ["EDGE_FLAG", "EXTRACTION_RULES", "LabelledBernoulliSet", "LmbFilter", "LmbState",
           "LmbTracks", "adaptive_birth_existence", "check_scan", "map_cardinality", "predict",
           "reduce_components", "update"]
