"""The ET-GM-PHD local estimator (seed 002) behind :class:`peers.contracts.LocalEstimator`.

It is the GM-PHD peer's estimator with an extended-target filter inside: it publishes its
level-2 pruned posterior mixture and fuses with the same :class:`peers.fusers.GciFuser`.
"""

from __future__ import annotations

import numpy as np
from sensornet.peers.contracts import LocalOutput
from sensornet.peers.estimators import GmphdEstimator
from sensornet.tracking.etgmphd import ETGMPHDFilter


class EtGmphdEstimator(GmphdEstimator):
    """An ET-GM-PHD filter on one sensor; records partitions per scan and oversized scans."""

    filter: ETGMPHDFilter

    last_scan: np.ndarray = np.zeros((0, 2))

    def step(self, steps: int, z: np.ndarray) -> LocalOutput:
        self.last_scan = np.asarray(z, dtype=float).reshape(-1, 2)
        out = super().step(steps, z)
        info = dict(out.info, n_partitions=len(self.filter.last_partitions),
                    scans_too_large=self.filter.counts["scans_too_large"])
        return LocalOutput(out.density, out.published, info)

    @property
    def last_partitions(self) -> list[np.ndarray]:
        """The latest scan's partitions (label arrays), for display."""
        return self.filter.last_partitions

    def partition_view(self) -> tuple[np.ndarray, np.ndarray] | None:
        """The latest scan ``(m, 2)`` and its most probable partition's labels ``(m,)`` (the
        heaviest ``w_p``), or None before the first partitioned scan."""
        parts, w = self.filter.last_partitions, self.filter.last_weights
        if not parts or len(parts[0]) != len(self.last_scan):
            return None
        best = int(np.argmax(w)) if w is not None and len(w) == len(parts) else 0
        return self.last_scan, parts[best]
