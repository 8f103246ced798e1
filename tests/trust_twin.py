"""The trust tests' twin run with a host's fusion batch of their making (tests/test_trust_batch.py,
tests/test_trust_shared.py): ``twin.FusionBatch`` swapped for the run and put back after."""

from __future__ import annotations

from collections.abc import Callable

from sensornet.sim.run import twin


def run_with_batch(scn, peers: dict, batch: Callable) -> tuple[object, dict]:
    """The twin of ``peers`` on run 0 with ``batch()`` as the host's FusionBatch: its result
    and every peer's trust summary (each peer's trust finished first)."""
    saved = twin.FusionBatch
    twin.FusionBatch = batch
    try:
        res = twin.run_twin(scn, 0, peers=peers, batch=True)
    finally:
        twin.FusionBatch = saved
    summaries = {}
    for q, core in peers.items():
        core.consensus.trust.finish()
        summaries[q] = core.consensus.trust.summary()
    return res, summaries
