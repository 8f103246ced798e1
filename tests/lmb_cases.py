"""Random LMB update cases shared by tests/test_lmb.py and benchmarks/bench_lmb_association.py:
tracks that compete for measurements, so association matters."""

from __future__ import annotations

import numpy as np
from sensornet.tracking.gmphd import SensorParams
from sensornet.tracking.lmb_sets import LabelledBernoulliSet
from sensornet.tracking.models import LinearPosition


def random_case(rng: np.random.Generator, max_tracks: int = 4, max_meas: int = 4,
                shape: tuple[int, int] | None = None):
    """<= ``max_tracks`` tracks (1-3 components each) and <= ``max_meas`` measurements near
    them (or exactly ``shape = (n, m)``), Pd and kappa drawn so that miss, detection and clutter
    all carry weight. Returns ``(tracks, Z (m, 2), sensor)``. With the defaults, the draws of
    the original 200-case test (seed 2014)."""
    if shape is None:
        n, m = int(rng.integers(1, max_tracks + 1)), int(rng.integers(0, max_meas + 1))
    else:
        n, m = shape
    sizes = rng.integers(1, 4, size=n)
    owner = np.repeat(np.arange(n), sizes)
    c = len(owner)
    centres = rng.uniform(-60, 60, size=(n, 2))
    means = np.zeros((c, 4))
    means[:, [0, 2]] = centres[owner] + rng.normal(0, 8, size=(c, 2))
    means[:, [1, 3]] = rng.normal(0, 3, size=(c, 2))
    A = rng.normal(size=(c, 4, 4))
    covs = A @ A.swapaxes(1, 2) * 20 + np.eye(4) * 30
    w = rng.uniform(0.1, 1, size=c)
    w /= np.bincount(owner, w)[owner]
    r = rng.uniform(0.05, 1.0, size=n)
    r[rng.random(n) < 0.2] = 1.0
    labels = np.stack([np.zeros(n), np.ones(n), np.arange(n)], axis=1).astype(np.int64)
    tracks = LabelledBernoulliSet(labels, r, w, means, covs, owner)
    Z = centres[rng.integers(0, n, size=m)] + rng.normal(0, 15, size=(m, 2))
    sensor = SensorParams(LinearPosition(sigma_r=float(rng.uniform(3, 15))),
                          float(rng.uniform(0.3, 1.0)), float(10 ** rng.uniform(-6, -3)))
    return tracks, Z, sensor
