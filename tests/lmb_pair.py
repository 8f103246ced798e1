"""Two LMB peers fused one round a scan as the consensus runs it (labels of each peer's
published PHD, own first, with the estimator's fresh stamps): the driver of the label-stamp
tests (tests/test_lmb_corroborate.py, tests/test_lmb_birth_edge.py)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from sensornet.peers.labelling import label_fused
from sensornet.peers.lmb_estimator import LmbEstimator


def run_pair(a: LmbEstimator, b: LmbEstimator, plots: Callable[[int], tuple],
             scans: int) -> dict[int, list[tuple]]:
    """Scans 1..``scans``: ``plots(k) = (za, zb)``, each ``(m, 2)``; returns the label each
    peer published first, per scan (from its first publication), keyed by its origin."""
    seen: dict[int, list[tuple]] = {a.origin: [], b.origin: []}
    for k in range(1, scans + 1):
        outs = []
        for e, z in zip((a, b), plots(k), strict=True):
            e.begin_scan(k)
            outs.append(e.step(1, np.asarray(z, float).reshape(-1, 2)))
        for e, out in ((a, outs[0]), (b, outs[1])):
            if len(out.labels["posterior"]):
                seen[e.origin].append(tuple(out.labels["posterior"][0].tolist()))
        for e, mine, theirs in ((a, outs[0], outs[1]), (b, outs[1], outs[0])):
            own = (mine.published["posterior"], mine.labels["posterior"])
            nbr = (theirs.published["posterior"], theirs.labels["posterior"])
            fused = own[0] if len(own[0]) else nbr[0]
            if len(fused):
                e.relabel(label_fused(fused, [own, nbr], e.origin, k,
                                      bump=e.fresh_stamps()).own)
    return seen
