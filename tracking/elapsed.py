"""Constant-velocity motion over an elapsed time: plots taken at their own times (issue 34).

A rotating radar's plots are made when its beam crosses each aircraft, not at the network's
fusion tick. A filter that takes them at their own times predicts over the time elapsed since
its last update, which need not be a whole number of ticks. :class:`ElapsedMotion` is the
constant-velocity model with continuous white-noise acceleration over ``dt`` (Bar-Shalom, Li &
Kirubarajan, "Estimation with Applications to Tracking and Navigation", 2001, Sec. 6.2.2): its
``Q(dt)`` is additive over splits of ``dt``, so many short predictions equal one long one,
which the scenario's discretised model (``Q = sigma_w^2 G G^T`` per step) is not. Its
intensity ``q = sigma_w^2 T`` gives one tick ``T`` the velocity variance of the tick model.

:func:`slice_of` puts plot times into the slices of a tick (the same rule as
``sim.studies.traffic.asynchronous.plot_batches``), so a peer and the centralised reference
cut a radar's plots alike.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import lru_cache

import numpy as np


@lru_cache(maxsize=1024)
def _cwna(dt: float, q: float) -> tuple[np.ndarray, np.ndarray]:
    """``F (4, 4)`` and ``Q (4, 4)`` of the CV model over ``dt`` with continuous white-noise
    acceleration of intensity ``q`` (Bar-Shalom, Li & Kirubarajan 2001, eq. 6.2.2-12), state
    ``[px, vx, py, vy]``."""
    F1 = np.array([[1.0, dt], [0.0, 1.0]])
    q1 = q * np.array([[dt**3 / 3.0, dt**2 / 2.0], [dt**2 / 2.0, dt]])
    F, Q = np.kron(np.eye(2), F1), np.kron(np.eye(2), q1)
    F.setflags(write=False)
    Q.setflags(write=False)
    return F, Q


@dataclass(frozen=True)
class ElapsedMotion:
    """Constant velocity over an elapsed time ``dt`` (s), continuous white-noise acceleration
    ``q = sigma_w^2 T`` (module docstring): ``transition(steps)`` is over ``steps * dt``, the
    interface of :class:`tracking.models.ConstantVelocity` the filters call."""

    T: float
    """The tick the scenario's ``sigma_w`` is stated for (s)."""
    sigma_w: float
    dt: float = 0.0
    dim: int = field(default=4, init=False)

    def __post_init__(self) -> None:
        if not (self.T > 0 and self.sigma_w >= 0 and self.dt >= 0):
            raise ValueError(f"ElapsedMotion needs T > 0, sigma_w >= 0, dt >= 0; got T={self.T}, "
                             f"sigma_w={self.sigma_w}, dt={self.dt}")

    def at(self, dt: float) -> ElapsedMotion:
        """The same model over ``dt`` seconds."""
        return replace(self, dt=float(dt))

    def transition(self, steps: int = 1) -> tuple[np.ndarray, np.ndarray]:
        return _cwna(self.dt * steps, self.sigma_w**2 * self.T)


def slices_per_tick(T: float, slice_s: float) -> int:
    """``T / slice_s`` as an integer (ticks are slice ends); ValueError naming ``slice_s``
    if it does not divide ``T``."""
    n = T / slice_s if slice_s > 0 else 0.5
    if not (slice_s > 0 and abs(n - round(n)) < 1e-9):
        raise ValueError(f"slice_s must divide the tick ({T:g} s), got {slice_s!r}")
    return int(round(n))


def slice_of(times: np.ndarray, slice_s: float) -> np.ndarray:
    """``(m,)`` the 1-based slice ``j`` whose interval ``((j-1) slice_s, j slice_s]`` holds each
    of ``times (m,)`` (seconds after the run's origin); a time within ``1e-9`` of a slice's
    end belongs to that slice."""
    return np.ceil(np.asarray(times, float) / slice_s - 1e-9).astype(np.int64)


__all__ = ["ElapsedMotion", "slice_of", "slices_per_tick"]
