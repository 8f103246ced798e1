"""Random dense track arrays for the OSPA(2) decomposition tests (one copy)."""

from __future__ import annotations

import numpy as np


def random_dense(rng: np.random.Generator, T: int, n: int, frac: float) -> np.ndarray:
    """``(T, n, 2)`` positions ~ N(0, 600 m) per axis, each (scan, track) absent (NaN) with
    probability ``frac``."""
    X = rng.normal(0.0, 600.0, (T, n, 2))
    X[rng.random((T, n)) < frac] = np.nan
    return X
