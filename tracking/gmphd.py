"""Gaussian-mixture PHD filter (Vo & Ma 2006; seed 000 §3.1; docs/algorithms.md "GM-PHD filter").

The parts compose like Stone Soup's predictor / updater / reducer: ``predict`` (survival and
births), ``update`` (one scan, every (measurement, component) pair in one array computation),
the :class:`~tracking.reduction.Reducer`, and ``extract``. ``step`` chains them.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np
from sensornet.tracking.gaussian import c_einsum as _c_einsum
from sensornet.tracking.gaussian import inv_det_spd
from sensornet.tracking.mixture import GaussianMixture
from sensornet.tracking.models import ConstantVelocity, MeasurementModel
from sensornet.tracking.reduction import Reducer

SensorModel = MeasurementModel
"""Any sensor behind :class:`tracking.models.MeasurementModel` (linear, range-bearing)."""


@dataclass(frozen=True)
class SensorParams:
    """What the update needs to know about one sensor."""

    model: SensorModel
    """Measurement model (``predict``, ``residual``, ``R``)."""
    detection_probability: float = 0.99
    """``Pd``."""
    clutter_intensity: float = 10.0 / 4e6
    """``kappa(z) = lambda_c / V`` (per unit measurement volume)."""


def predict(
    mix: GaussianMixture,
    motion: ConstantVelocity,
    survival_probability: float,
    birth: GaussianMixture | None = None,
    steps: int = 1,
) -> GaussianMixture:
    """Survivors ``Ps^steps w, F m, F P F^T + Q`` (multi-step form, §1) plus the births once."""
    if steps == 0:
        w, m, P = mix.weights, mix.means, mix.covs
    else:
        F, Q = motion.transition(steps)
        w, m, P = mix.weights * survival_probability**steps, mix.means @ F.T, F @ mix.covs @ F.T + Q
    if birth is not None and len(birth):
        w = np.concatenate((w, birth.weights))
        m = np.concatenate((m, birth.means))
        P = np.concatenate((P, birth.covs))
    elif steps == 0:
        return mix
    return GaussianMixture.trusted(w, m, P)


def update(
    mix: GaussianMixture,
    scan: np.ndarray,
    sensor: SensorParams,
    gate: float | None = None,
    min_weight: float = 0.0,
) -> GaussianMixture:
    """PHD corrector for one scan ``Z (m, 2)`` (Vo & Ma 2006, Table I, steps 3-4).

    ``w_j(z) = Pd w_j q_j(z) / (kappa + Pd sum_l w_l q_l(z))`` over all (z, j) pairs at once.
    ``gate``: optional Mahalanobis gate on ``nu^T S^-1 nu`` (pairs outside get weight 0).
    ``min_weight``: detection terms lighter than this are not materialised (equivalent to
    pruning them afterwards; keeps heavy clutter cheap).
    """
    return update_parents(mix, scan, sensor, gate, min_weight)[0]


def update_parents(
    mix: GaussianMixture,
    scan: np.ndarray,
    sensor: SensorParams,
    gate: float | None = None,
    min_weight: float = 0.0,
) -> tuple[GaussianMixture, np.ndarray]:
    """:func:`update` (the same numbers) and the parent of each detection term: ``(p,)``
    indices into ``mix``. The result's first ``len(mix)`` components are the missed-detection
    terms of ``mix`` in order, the next ``p`` are the detection terms of ``mix[parents]``
    (what tag propagation needs: Panta, Clark & Vo 2009, §IV; tracking.labels)."""
    Pd = sensor.detection_probability
    w, mean, P = mix.weights, mix.means, mix.covs
    missed_w = w * (1.0 - Pd)
    scan = np.asarray(scan, dtype=float).reshape(-1, sensor.model.dim)
    n, m = len(mix), len(scan)
    if n == 0 or m == 0:
        return GaussianMixture.trusted(missed_w, mean, P), np.zeros(0, dtype=np.intp)
    cols = _selected_columns(sensor.model)
    R = sensor.model.R
    if cols is not None:  # H picks state entries: H P H^T and P H^T are sub-blocks of P
        zhat = mean[:, cols]  # (n, 2)
        PHt = P[:, :, cols]  # (n, d, 2)
        S = PHt[:, cols, :] + R  # (n, 2, 2)
    else:
        zhat, H = sensor.model.predict(mean)  # (n, 2), (n, 2, d)
        PHt = P @ np.swapaxes(H, 1, 2)  # (n, d, 2)
        S = H @ PHt + R  # (n, 2, 2)
    S_inv, S_det = (_inv_det_2x2(S) if S.shape[-1] == 2 else inv_det_spd(S))
    K = PHt @ S_inv  # (n, d, 2)
    P_upd = P - K @ PHt.swapaxes(1, 2)  # (n, d, d), symmetrised: (P + P^T) / 2
    P_upd = P_upd + P_upd.swapaxes(1, 2)
    P_upd *= 0.5
    nu = sensor.model.residual(scan[:, None, :], zhat[None, :, :])  # (m, n, 2)
    d2 = _c_einsum("...i,...ij,...j->...", nu, S_inv[None], nu)  # (m, n): quad_form
    # num = Pd w q(z): the operations of -0.5 (d2 + log det S + k log 2 pi), exp, times Pd w,
    # in that order, in place
    num = d2 + np.log(S_det)[None]
    num += S.shape[-1] * _LOG_2PI
    num *= -0.5
    np.exp(num, out=num)
    num *= Pd * w[None, :]  # (m, n)
    if gate is not None:
        num = np.where(d2 <= gate, num, 0.0)
    denom = num.sum(axis=1, keepdims=True)
    denom += sensor.clutter_intensity
    num /= denom  # w_upd
    zi, ji = (num > min_weight).nonzero() if min_weight > 0 else (num >= 0).nonzero()
    means_upd = mean[ji] + _c_einsum("kij,kj->ki", K[ji], nu[zi, ji])
    return GaussianMixture.trusted(
        np.concatenate((missed_w, num[zi, ji])),
        np.concatenate((mean, means_upd)),
        np.concatenate((P, P_upd[ji])),
    ), ji


_LOG_2PI = float(np.log(2 * np.pi))
_ADJ_SIGN = np.array([[1.0, -1.0], [-1.0, 1.0]])


def _inv_det_2x2(S: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`tracking.gaussian.inv_det_2x2` of ``S (n, 2, 2)`` (the same numbers: ``det =
    ad - bc``, entries of ``[[d, -b], [-c, a]]`` times ``1 / det``) in fewer NumPy calls."""
    det = S[:, 0, 0] * S[:, 1, 1] - S[:, 0, 1] * S[:, 1, 0]
    inv = S[:, ::-1, ::-1].swapaxes(1, 2) * _ADJ_SIGN  # [[d, -b], [-c, a]]
    inv *= (1.0 / det)[:, None, None]
    return inv, det


@lru_cache(maxsize=64)
def _columns(selected: tuple[int, ...]) -> np.ndarray:
    cols = np.asarray(selected)
    cols.setflags(write=False)
    return cols


def _selected_columns(model: SensorModel) -> np.ndarray | None:
    """The state entries a linear model picks (``MeasurementModel.selected``), else None."""
    return None if model.selected is None else _columns(tuple(model.selected))


EXTRACTION_RULES = ("round", "cardinality")
"""Extraction rules accepted by :func:`extract`."""
DEFAULT_EXTRACTION = "cardinality"
"""The one default extraction rule (library, scenarios and docs/algorithms.md agree)."""


def extract(mix: GaussianMixture, threshold: float = 0.5,
            rule: str = DEFAULT_EXTRACTION) -> np.ndarray:
    """State estimates ``(n, d)`` from an intensity.

    ``"round"`` (Vo & Ma 2006, Table III): each component with ``w > threshold`` gives
    ``round(w)`` copies of its mean; a merged weight above 1.5 gives duplicates.
    ``"cardinality"``: the number of targets is the total mass rounded to the nearest integer
    and the means of that many heaviest components (each above ``threshold / 10``) are
    returned, as in cardinality-first extraction for CPHD filters (our reading; it suits
    fused intensities whose mass is spread unevenly over the targets).
    """
    return mix.means[extract_index(mix, threshold, rule)]


def extract_index(mix: GaussianMixture, threshold: float = 0.5,
                  rule: str = DEFAULT_EXTRACTION) -> np.ndarray:
    """The components :func:`extract` reports, as ``(n,)`` indices into ``mix`` (a component
    repeated ``round(w)`` times under ``"round"``): ``extract`` is ``mix.means[index]``."""
    if rule == "round":
        keep = np.flatnonzero(mix.weights > threshold)
        counts = np.maximum(np.rint(mix.weights[keep]).astype(int), 1)
        return np.repeat(keep, counts)
    if rule == "cardinality":
        n = int(np.floor(mix.mass + 0.5))
        order = np.argsort(-mix.weights, kind="stable")[:n]
        return order[mix.weights[order] > threshold / 10]
    raise ValueError(f"unknown extraction rule {rule!r}; expected {EXTRACTION_RULES}")


@dataclass
class GMPHDFilter:
    """A GM-PHD filter for one sensor (or several, by the iterated corrector)."""

    motion: ConstantVelocity
    """Motion model."""
    sensors: Sequence[SensorParams]
    """Sensors whose scans this filter corrects with, in order (one for a local filter)."""
    birth: GaussianMixture
    """Birth intensity added at every prediction."""
    survival_probability: float = 0.99
    """``Ps``."""
    reducer: Reducer = field(default_factory=Reducer)
    """Level-1 reduction applied after each correction."""
    extraction_threshold: float = 0.5
    """Components heavier than this are reported as targets."""
    extraction: str = DEFAULT_EXTRACTION
    """Extraction rule: ``"cardinality"`` (default) or ``"round"`` (Vo–Ma); see :func:`extract`."""
    gate: float | None = None
    """Optional Mahalanobis gate (``nu^T S^-1 nu`` threshold) in the update."""

    def initial(self) -> GaussianMixture:
        """The prior before the first scan: empty (births arrive at the first prediction)."""
        return GaussianMixture.empty(self.motion.dim)

    def predict(self, mix: GaussianMixture, steps: int = 1) -> GaussianMixture:
        return predict(mix, self.motion, self.survival_probability, self.birth, steps)

    def correct(self, mix: GaussianMixture, scans: Sequence[np.ndarray]) -> GaussianMixture:
        """Correct with one scan per configured sensor (iterated corrector), reducing after each."""
        if len(scans) != len(self.sensors):
            raise ValueError(f"expected {len(self.sensors)} scans, got {len(scans)}")
        for sensor, scan in zip(self.sensors, scans, strict=True):
            mix = update(mix, scan, sensor, self.gate, self.reducer.prune_threshold)
            mix = self.reducer(mix)
        return mix

    def step(self, mix: GaussianMixture, *scans: np.ndarray) -> GaussianMixture:
        """Predict one scan ahead, then correct with the scan(s) of this time step."""
        return self.correct(self.predict(mix), scans)

    def extract(self, mix: GaussianMixture) -> np.ndarray:
        return extract(mix, self.extraction_threshold, self.extraction)


__all__ = ["DEFAULT_EXTRACTION", "GMPHDFilter", "SensorParams", "extract", "extract_index",
           "predict", "update", "update_parents"]

