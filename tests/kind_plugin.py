"""A small peer kind registered from outside the project (tests/test_kinds.py): each peer keeps
the measurements confirmed by one in the previous scan within a gate, as 4-D Gaussians, and
fuses its neighbours' by the arithmetic average. Found by the run's processes through the
``SENSORNET_KINDS`` plug-in variable: ``toy=kind_plugin:TOY``."""

from __future__ import annotations

import numpy as np
from scipy.spatial.distance import cdist
from sensornet.peers.contracts import LocalOutput
from sensornet.peers.fusers import AaFuser
from sensornet.sim.kinds import PeerKind
from sensornet.tracking.mixture import GaussianMixture
from sensornet.tracking.reduction import Reducer

SIGMA = 20.0
"""Position spread of a confirmed point, metres."""


class ConfirmedPoints:
    """Local estimator: the scan's points that have a point of the last scan within ``gate``."""

    kinds = ("posterior",)
    position_index = (0, 2)
    dim = 4

    def __init__(self, gate: float = 60.0) -> None:
        self.gate = gate
        self.prev = np.empty((0, 2))

    def _mixture(self, pts: np.ndarray) -> GaussianMixture:
        n = len(pts)
        means = np.zeros((n, 4))
        means[:, [0, 2]] = pts
        cov = np.diag([SIGMA**2, 100.0, SIGMA**2, 100.0])
        return GaussianMixture(np.ones(n), means, np.broadcast_to(cov, (n, 4, 4)).copy())

    def step(self, steps: int, z: np.ndarray) -> LocalOutput:
        z = np.asarray(z, float).reshape(-1, 2)
        keep = (cdist(z, self.prev).min(axis=1) < self.gate * steps if len(z) and len(self.prev)
                else np.zeros(len(z), bool))
        self.prev = z
        mix = self._mixture(z[keep])
        return LocalOutput(mix, {"posterior": mix}, {"n_components": len(mix)})

    def predict(self, mix: GaussianMixture, steps: int) -> GaussianMixture:
        return mix

    def extract(self, mix: GaussianMixture) -> np.ndarray:
        return mix.means[mix.weights > 0.5]

    def adopt(self, fused: GaussianMixture) -> None:
        pass


def build(scn, name: str, run: int = 0):
    return ConfirmedPoints(), AaFuser(Reducer(merge_threshold=4.0))


TOY = PeerKind("toy", "confirmed points, AA-fused (a test plug-in)", build, ("aa",))
