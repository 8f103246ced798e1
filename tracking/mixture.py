"""Gaussian mixtures as arrays: the one data type the estimation core passes around.

A PHD intensity ``D(x) = sum_j w_j N(x; m_j, P_j)`` (Vo & Ma 2006) is stored as three arrays:
``weights (n,)``, ``means (n, d)``, ``covs (n, d, d)``. The sum of the weights is the expected
number of targets. No Python object per component: every operation works on whole arrays.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from sensornet.tracking.gaussian import gaussian_pdf_points


@dataclass(frozen=True)
class GaussianMixture:
    """An array-backed Gaussian mixture (an unnormalised intensity in general).

    weights: (n,) non-negative component weights.
    means:   (n, d) component means.
    covs:    (n, d, d) symmetric positive-definite component covariances.
    """

    weights: np.ndarray
    means: np.ndarray
    covs: np.ndarray

    def __post_init__(self) -> None:
        w = np.asarray(self.weights, dtype=float).reshape(-1)
        m = np.asarray(self.means, dtype=float)
        n = w.shape[0]
        if m.ndim == 1:
            m = m.reshape(n, -1) if n else m.reshape(0, m.shape[0] if m.size else 0)
        P = np.asarray(self.covs, dtype=float)
        d = m.shape[1] if m.ndim == 2 else 0
        if P.size == 0:
            P = P.reshape(n, d, d)
        if m.shape != (n, d) or P.shape != (n, d, d):
            raise ValueError(
                f"GaussianMixture shapes disagree: weights {w.shape}, means {m.shape}, "
                f"covs {P.shape}; expected (n,), (n, d), (n, d, d)"
            )
        object.__setattr__(self, "weights", w)
        object.__setattr__(self, "means", m)
        object.__setattr__(self, "covs", P)

    # -- construction -------------------------------------------------------------------
    @classmethod
    def trusted(cls, weights: np.ndarray, means: np.ndarray, covs: np.ndarray) -> GaussianMixture:
        """A mixture from arrays the caller guarantees: float ``(n,)``, ``(n, d)``,
        ``(n, d, d)``. No conversion and no shape checks (for filter hot paths whose arrays
        come from validated mixtures; the checks cost more than a small filter step's
        arithmetic)."""
        mix = object.__new__(cls)
        object.__setattr__(mix, "weights", weights)
        object.__setattr__(mix, "means", means)
        object.__setattr__(mix, "covs", covs)
        return mix

    @classmethod
    def empty(cls, dim: int) -> GaussianMixture:
        """A mixture with no components in ``dim`` dimensions."""
        return cls(np.zeros(0), np.zeros((0, dim)), np.zeros((0, dim, dim)))

    @classmethod
    def concatenate(cls, mixtures: Sequence[GaussianMixture]) -> GaussianMixture:
        """The union of the components of several mixtures (the sum of their intensities)."""
        mixtures = list(mixtures)
        if not mixtures:
            raise ValueError("concatenate needs at least one mixture")
        return cls(
            np.concatenate([g.weights for g in mixtures]),
            np.concatenate([g.means for g in mixtures]),
            np.concatenate([g.covs for g in mixtures]),
        )

    # -- views ----------------------------------------------------------------------------
    def __len__(self) -> int:
        return int(self.weights.shape[0])

    @property
    def dim(self) -> int:
        """State dimension ``d``."""
        return int(self.means.shape[1])

    @property
    def mass(self) -> float:
        """Total weight: the expected number of targets for a PHD intensity."""
        return float(self.weights.sum())

    def select(self, index: np.ndarray | slice) -> GaussianMixture:
        """The sub-mixture of the components picked by a boolean mask or index array."""
        if not isinstance(index, slice) and np.ndim(index) == 0:  # one component: validated
            return GaussianMixture(self.weights[index], self.means[index], self.covs[index])
        return GaussianMixture.trusted(self.weights[index], self.means[index], self.covs[index])

    def scaled(self, factor: float) -> GaussianMixture:
        """The same components with every weight multiplied by ``factor``."""
        return GaussianMixture(self.weights * factor, self.means, self.covs)

    def normalised(self) -> GaussianMixture:
        """The mixture scaled to total weight 1 (a probability density)."""
        mass = self.mass
        if mass <= 0:
            raise ValueError("cannot normalise a mixture with zero total weight")
        return self.scaled(1.0 / mass)

    def sorted(self) -> GaussianMixture:
        """Components ordered by decreasing weight (a canonical order for comparisons)."""
        order = np.argsort(-self.weights, kind="stable")
        return self.select(order)

    def moments(self) -> tuple[np.ndarray, np.ndarray]:
        """Mean (d,) and covariance (d, d) of the normalised mixture (moment matching)."""
        w = self.weights / self.mass
        mean = w @ self.means
        diff = self.means - mean
        cov = np.einsum("n,nij->ij", w, self.covs) + np.einsum("n,ni,nj->ij", w, diff, diff)
        return mean, cov

    def pdf(self, x: np.ndarray) -> np.ndarray:
        """Intensity at points ``x (p, d)``: returns ``(p,)``. For tests and plots."""
        x = np.atleast_2d(np.asarray(x, dtype=float))
        if len(self) == 0:
            return np.zeros(x.shape[0])
        return gaussian_pdf_points(x, self.means, self.covs) @ self.weights

    def copy(self) -> GaussianMixture:
        return GaussianMixture(self.weights.copy(), self.means.copy(), self.covs.copy())
