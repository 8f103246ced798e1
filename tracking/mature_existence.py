"""Extraction of a fused track whose target the inputs just missed (issue 33,
docs/labelled-tracking.md "Fused tracks outlive their targets").

The hybrid rule's existence of a fused LMB track is the inputs' weighted mean (AA, Li 2022), so
it falls no faster than one peer's own: at ``Pd`` 0.9 an LMB track that misses once keeps
``r (1 - Pd) / (1 - r Pd)``, about 0.91 from ``r`` = 0.99 (Reuter et al. 2014, eq. 21 with no
measurement), and a target that died was reported by every peer for a scan or more after its
death, where the centralised filter, with every sensor's miss, drops it at once. Here a mature
fused track (its label more than ``young`` scans old, held by two inputs or more) weighs for
extraction at most its inputs' existences pooled as independent evidence about the common
prior ``Ps^s w_prev``, its fused weight at this peer's previous scan predicted ``s`` scans:
``logit r = logit r0 + sum_i (logit r_i - logit r0)`` (Bayes' rule for data independent given
the prior, Chong, Mori & Chang 1990; :func:`tracking.fusion_rules.pool_existence` with a
per-track prior), so each input that missed lowers it as each sensor's miss lowers the
centralised existence. It only lowers (the minimum of that and the fused weight: pooled
mature tracks with a low prior raise dead targets, docs/labelled-tracking.md "Design B"), and
only the weights extraction reads: the fused density, its labels and what is published are the
fuser's.

``absent`` (``fusion.existence_absent``): an input that gives the track no mass at all counts in
the pool at that existence, the threshold it publishes tracks from (its own existence of the
target is below it: a censored observation, taken at the bound most favourable to the track),
instead of being left out. Why (docs/labelled-tracking.md "Inputs without the track count"): at
a target's death two of a peer's five inputs often hold no component of it, and the three that
missed once alone pooled to 0.6-0.99 about the fused prior, so dead targets were still reported.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.special import expit, logit
from sensornet.tracking.fusion_rules import POOL_CLIP
from sensornet.tracking.label_keys import label_keys


@dataclass
class MatureExistence:
    """One peer's rule (module docstring): call :meth:`caps` once per scan with that scan's
    fused density; it remembers each label's fused weight for the next scan."""

    survival: float
    """``Ps`` per scan (the prior's prediction)."""
    young: int = 2
    """Labels at most this many scans old are young (``fusion.existence_young``: pooled up,
    :func:`tracking.support.pooled_weights`), not lowered here."""
    absent: float = 0.0
    """An input holding no mass of a mature track counts at this existence (the inputs'
    publication threshold, module docstring), if below the prior; 0: such inputs left out."""
    _keys: np.ndarray = field(default_factory=lambda: label_keys(np.zeros((0, 3), np.int64)),
                              repr=False)
    _w: np.ndarray = field(default_factory=lambda: np.zeros(0), repr=False)
    _k: int | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        if not 0.0 < self.survival <= 1.0:
            raise ValueError(f"survival must be in (0, 1], got {self.survival}")
        if self.young < 0:
            raise ValueError(f"young must be >= 0, got {self.young}")
        if not 0.0 <= self.absent < 1.0:
            raise ValueError(f"absent must be in [0, 1), got {self.absent}")

    def caps(self, fused: np.ndarray, labels: np.ndarray, k: int, mass: np.ndarray
             ) -> np.ndarray:
        """``(n,)`` upper bounds of the fused components' extraction weights: the pooled
        existence for the mature rows held by two inputs or more (``mass (n, I)``,
        :func:`tracking.support.input_mass`) whose label had a fused weight at the last call
        (scan ``k - s``), ``inf`` for the others; with :attr:`absent`, the inputs holding no
        mass of the row count at that existence. Remembers this scan's fused weight of each
        label (``fused (n,)``, summed over its rows, at most 1)."""
        fused = np.asarray(fused, dtype=float).reshape(-1)
        n = len(fused)
        labels = np.asarray(labels, dtype=np.int64).reshape(-1, 3)
        mass = np.asarray(mass, dtype=float)
        if labels.shape[0] != n or mass.ndim != 2 or mass.shape[0] != n:
            raise ValueError(f"labels and mass must have {n} rows (the fused weights'), got "
                             f"{labels.shape[0]} and {mass.shape}")
        out = np.full(n, np.inf)
        keys = label_keys(labels)
        if self._k is not None and k > self._k and len(self._keys) and n:
            pos = np.searchsorted(self._keys, keys).clip(max=len(self._keys) - 1)
            seen = self._keys[pos] == keys
            held = mass > 0
            use = seen & (k - labels[:, 1] > self.young) & (held.sum(axis=1) >= 2)
            if use.any():
                r0 = np.clip(self.survival ** (k - self._k) * self._w[pos[use]], POOL_CLIP,
                             1.0 - POOL_CLIP)
                lo = logit(r0)
                r = logit(np.clip(mass[use], POOL_CLIP, 1.0 - POOL_CLIP))
                gone = (np.minimum(logit(self.absent) - lo, 0.0) if self.absent > 0
                        else np.zeros_like(lo))  # an absent input's term: only lowers
                out[use] = expit(lo + np.where(held[use], r - lo[:, None],
                                               gone[:, None]).sum(axis=1))
        u, inv = np.unique(keys, return_inverse=True)
        self._keys = u
        self._w = np.minimum(np.bincount(inv.reshape(-1), fused, minlength=len(u)), 1.0)
        self._k = int(k)
        return out


__all__ = ["MatureExistence"]
