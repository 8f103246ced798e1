"""Measurement flooding (seed 004; docs/seed004.md): everything importable from one place.

- :mod:`peers.flooder`: sans-I/O, one peer's flooding state (:class:`Flooder`), :func:`flood`
  over a network, and the tuples and bytes a flood sends (:func:`flooding_tuples`,
  :func:`flooding_bytes`);
- :mod:`peers.flood_parts`: flooding as a peer mode, the :mod:`peers.contracts` parts
  (:class:`FloodEstimator`, :class:`FloodFuser`, and the iterated corrector's
  :class:`IcFloodEstimator`, :class:`IcFloodFuser`, :func:`corrector_order`).
"""

from __future__ import annotations

from sensornet.peers.flood_parts import (
    FloodEstimator,
    FloodFuser,
    IcFloodEstimator,
    IcFloodFuser,
    corrector_order,
)
from sensornet.peers.flooder import (
    TUPLES_PER_MEASUREMENT,
    Deliver,
    Flooder,
    FloodOutcome,
    ScanKey,
    flood,
    flooding_bytes,
    flooding_tuples,
)

__all__ = ["Deliver", "FloodEstimator", "FloodFuser", "FloodOutcome", "Flooder",
           "IcFloodEstimator", "IcFloodFuser", "ScanKey", "TUPLES_PER_MEASUREMENT",
           "corrector_order", "flood", "flooding_bytes", "flooding_tuples"]
