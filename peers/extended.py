"""The ET-GM-PHD local estimator (seed 002) behind :class:`peers.contracts.LocalEstimator`.

It is the GM-PHD peer's estimator with an extended-target filter inside: it publishes its
level-2 pruned posterior mixture and fuses with the same :class:`peers.fusers.GciFuser`.
"""

from __future__ import annotations

import numpy as np

from peers.contracts import LocalOutput
from peers.estimators import GmphdEstimator
from tracking.etgmphd import ETGMPHDFilter


class EtGmphdEstimator(GmphdEstimator):
    """An ET-GM-PHD filter on one sensor; records partitions per scan and oversized scans."""

    filter: ETGMPHDFilter

    def step(self, steps: int, z: np.ndarray) -> LocalOutput:
        out = super().step(steps, z)
        info = dict(out.info, n_partitions=len(self.filter.last_partitions),
                    scans_too_large=self.filter.counts["scans_too_large"])
        return LocalOutput(out.density, out.published, info)

    @property
    def last_partitions(self) -> list[np.ndarray]:
        """The latest scan's partitions (label arrays), for display."""
        return self.filter.last_partitions
