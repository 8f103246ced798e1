"""Motion and sensor models (docs/algorithms.md: notation) as small objects with array methods.

State order is ``x = [px, vx, py, vy]`` (metres, m/s).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property, lru_cache
from typing import Protocol, runtime_checkable

import numpy as np


@runtime_checkable
class MeasurementModel(Protocol):
    """What a filter needs of a sensor: ``z (2,)`` from a 4-D state ``[px, vx, py, vy]``."""

    dim: int
    angular: tuple[bool, ...]
    """Which measurement components are angles (residuals wrapped)."""
    selected: tuple[int, ...] | None
    """For a linear model that picks state entries (``H`` rows of the identity), their
    indices: then ``H P H^T`` and ``P H^T`` are exact sub-blocks of ``P``; else None."""

    @property
    def R(self) -> np.ndarray: ...

    def predict(self, means: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Predicted measurements ``(n, dim)`` and Jacobians ``(n, dim, 4)``."""
        ...

    def residual(self, z: np.ndarray, zhat: np.ndarray) -> np.ndarray: ...


@dataclass(frozen=True)
class ConstantVelocity:
    """Nearly-constant-velocity model in 2-D: ``F``, ``Q = sigma_w^2 G G^T`` (seed 000 §4)."""

    T: float = 1.0
    """Scan period in seconds."""
    sigma_w: float = 2.0
    """Process noise standard deviation in m/s^2."""

    dim: int = field(default=4, init=False)

    @property
    def F(self) -> np.ndarray:
        T = self.T
        return np.array([[1, T, 0, 0], [0, 1, 0, 0], [0, 0, 1, T], [0, 0, 0, 1]], dtype=float)

    @property
    def Q(self) -> np.ndarray:
        T = self.T
        G = np.array([[T * T / 2, 0], [T, 0], [0, T * T / 2], [0, T]], dtype=float)
        return self.sigma_w**2 * G @ G.T

    def transition(self, steps: int = 1) -> tuple[np.ndarray, np.ndarray]:
        """``F(k, a) = F^steps`` and ``Q(k, a) = sum_{t<steps} F^t Q F^t^T`` (multi-step, §1)."""
        return _multi_step(self.T, self.sigma_w, int(steps))

    def sample(self, states: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Propagate true states ``(n, 4)`` one scan with process noise."""
        T = self.T
        G = np.array([[T * T / 2, 0], [T, 0], [0, T * T / 2], [0, T]])
        accel = rng.normal(0.0, self.sigma_w, size=(len(states), 2))  # Q = sigma_w^2 G G^T
        return states @ self.F.T + accel @ G.T


@lru_cache(maxsize=256)
def _multi_step(T: float, sigma_w: float, steps: int) -> tuple[np.ndarray, np.ndarray]:
    """Closed form of ``F^n`` and ``sum_{t<n} F^t Q F^t^T`` for the CV model (O(1) in ``n``).

    Per axis ``F^t G = [T^2 (t + 1/2), T]``, so the sum is ``sigma_w^2`` times
    ``[[T^4 (n^3/3 - n/12), T^3 n^2/2], [T^3 n^2/2, T^2 n]]``. A loop over ``n`` would let one
    message with a far-away scan index stall a peer (a scan 10^9 ahead is 10^9 iterations).
    """
    if steps < 0:
        raise ValueError(f"cannot predict backwards ({steps} steps)")
    n = float(steps)
    F1 = np.array([[1.0, n * T], [0.0, 1.0]])
    q = sigma_w**2 * np.array([[T**4 * (n**3 / 3 - n / 12), T**3 * n * n / 2],
                               [T**3 * n * n / 2, T * T * n]])
    F = np.kron(np.eye(2), F1)
    Q = np.kron(np.eye(2), q)
    F.setflags(write=False)
    Q.setflags(write=False)
    return F, Q


@dataclass(frozen=True)
class LinearPosition:
    """Position sensor ``z = H x + v``, ``H`` picks (px, py), ``R = sigma_r^2 I`` (§1)."""

    sigma_r: float = 20.0
    """Measurement noise standard deviation per axis in metres."""
    position: tuple[float, float] = (0.0, 0.0)
    """Sensor position (not used by the linear model; kept for display)."""

    H_MATRIX = np.array([[1.0, 0, 0, 0], [0, 0, 1.0, 0]])
    dim: int = field(default=2, init=False)
    angular: tuple[bool, ...] = field(default=(False, False), init=False)
    selected: tuple[int, ...] | None = field(default=(0, 2), init=False)

    @cached_property
    def R(self) -> np.ndarray:
        """(2, 2) measurement noise covariance (built once, read-only)."""
        return _read_only(self.sigma_r**2 * np.eye(2))

    def predict(self, means: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Predicted measurements ``(n, 2)`` and Jacobians ``(n, 2, 4)`` at ``means (n, 4)``."""
        H = np.broadcast_to(self.H_MATRIX, (len(means), 2, 4))
        return means[:, [0, 2]], H

    def residual(self, z: np.ndarray, zhat: np.ndarray) -> np.ndarray:
        """``z - zhat`` (broadcast)."""
        return z - zhat

    def measure(self, states: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Noisy measurements of true states ``(n, 4)``: ``(n, 2)``."""
        return states[:, [0, 2]] + rng.normal(0.0, self.sigma_r, size=(len(states), 2))


def _read_only(a: np.ndarray) -> np.ndarray:
    a.setflags(write=False)
    return a


def wrap_angle(a: np.ndarray) -> np.ndarray:
    """Angle(s) wrapped to ``[-pi, pi)``: every bearing difference goes through this."""
    return (np.asarray(a) + np.pi) % (2.0 * np.pi) - np.pi


@dataclass(frozen=True)
class RangeBearing:
    """Radar at ``position``: ``z = [range, bearing] + v``, bearing = atan2(dy, dx) (§1)."""

    sigma_r: float = 3.0
    """Range noise standard deviation in metres."""
    sigma_theta: float = np.deg2rad(0.08)
    """Bearing noise standard deviation in radians."""
    position: tuple[float, float] = (0.0, 0.0)
    """Radar position (sx, sy) in metres."""

    dim: int = field(default=2, init=False)
    angular: tuple[bool, ...] = field(default=(False, True), init=False)
    selected: tuple[int, ...] | None = field(default=None, init=False)

    @cached_property
    def R(self) -> np.ndarray:
        """(2, 2) measurement noise covariance (built once, read-only)."""
        return _read_only(np.diag([self.sigma_r**2, self.sigma_theta**2]))

    def h(self, means: np.ndarray) -> np.ndarray:
        dx = means[:, 0] - self.position[0]
        dy = means[:, 2] - self.position[1]
        return np.stack([np.hypot(dx, dy), np.arctan2(dy, dx)], axis=1)

    def predict(self, means: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Predicted measurements ``(n, 2)`` and Jacobians ``(n, 2, 4)`` (EKF linearisation)."""
        dx = means[:, 0] - self.position[0]
        dy = means[:, 2] - self.position[1]
        r2 = np.maximum(dx * dx + dy * dy, 1e-12)
        r = np.sqrt(r2)
        H = np.zeros((len(means), 2, 4))
        H[:, 0, 0] = dx / r
        H[:, 0, 2] = dy / r
        H[:, 1, 0] = -dy / r2
        H[:, 1, 2] = dx / r2
        return np.stack([r, np.arctan2(dy, dx)], axis=1), H

    def residual(self, z: np.ndarray, zhat: np.ndarray) -> np.ndarray:
        """``z - zhat`` with the bearing difference wrapped to ``[-pi, pi)``."""
        d = np.asarray(z - zhat, dtype=float).copy()
        d[..., 1] = wrap_angle(d[..., 1])
        return d

    def measure(self, states: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        z = self.h(states) + rng.normal(0.0, 1.0, size=(len(states), 2)) * [
            self.sigma_r,
            self.sigma_theta,
        ]
        z[:, 1] = wrap_angle(z[:, 1])
        return z
