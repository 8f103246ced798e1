"""A run's tracks and truths as Stone Soup types, for its metrics and plotters.

Stone Soup (Hiscocks et al. 2023, ``pip install stonesoup``: the ``bench`` extra) is the
tracking community's Python framework. :func:`to_stonesoup` turns a :class:`sensornet.api.Run`
(``simulate`` or ``load_run``) into ``Track`` objects (one per track id ``origin.birth.index``
of a labelled peer; one per row and scan otherwise) and ``GroundTruthPath`` objects (one per
true target id), stamped ``epoch + k T``; :func:`measure` is the Euclidean distance on the
position entries the table was scored with, so Stone Soup's ``OSPAMetric``/``GOSPAMetric``
reproduce the table's ``ospa`` and ``gospa`` columns (tests/test_interop.py checks it).
The per-scan table holds no detections: they are not exported.
"""

from __future__ import annotations

import datetime as dt
from dataclasses import dataclass

import numpy as np

# heavy optional dependency: stonesoup (this module is imported only by who exports)
from stonesoup.measures import Euclidean
from stonesoup.types.array import StateVector
from stonesoup.types.groundtruth import GroundTruthPath, GroundTruthState
from stonesoup.types.state import State
from stonesoup.types.track import Track

EPOCH = dt.datetime(2000, 1, 1)
"""Scan ``k`` is stamped ``EPOCH + k T`` (the scenario's scan period ``T``, 1 s if unknown)."""


@dataclass
class StoneSoupRun:
    """One peer's estimates and the truth of a run, as Stone Soup objects."""

    tracks: set
    """``Track`` objects, ids ``"origin.birth.index"`` (or ``"k.row"`` without labels)."""
    truths: set
    """``GroundTruthPath`` objects, ids the true target ids."""
    times: dict[int, dt.datetime]
    """Scan index -> its timestamp."""


def stamp(k: int, period: float) -> dt.datetime:
    return EPOCH + dt.timedelta(seconds=k * period)


def measure(run) -> Euclidean:
    """Euclidean distance on the position entries the run's table was scored with."""
    return Euclidean(mapping=tuple(int(i) for i in run.meta["position_index"]))


def to_stonesoup(run, peer: str, which: str = "fused") -> StoneSoupRun:
    """``peer``'s ``which`` estimates and the truth of ``run`` as Stone Soup types."""
    period = float(run.scenario.scan_period) if run.scenario is not None else 1.0
    scans = run.columns["scan"][run.select(peer, which)].tolist()
    times = {int(k): stamp(int(k), period) for k in scans}
    tracks = set()
    by_id = run.tracks_by_id(peer, which)
    if by_id:
        for key, (ks, xs) in by_id.items():
            tracks.add(Track([State(StateVector(x), timestamp=times[int(k)])
                              for k, x in zip(ks.tolist(), xs, strict=True)],
                             id=".".join(str(v) for v in key)))
    else:
        for k, xs in run.tracks(peer, which).items():
            for j, x in enumerate(xs):
                tracks.add(Track([State(StateVector(x), timestamp=times[k])], id=f"{k}.{j}"))
    truths = set()
    for tid, (ks, xs) in run.truth_by_id().items():
        states = [GroundTruthState(StateVector(x), timestamp=stamp(int(k), period))
                  for k, x in zip(ks.tolist(), xs, strict=True) if int(k) in times]
        if states:
            truths.add(GroundTruthPath(states, id=str(tid)))
    if not run.truth_by_id():  # a table without truth ids: one path per row and scan
        for k, xs in run.truth().items():
            if k in times:
                for j, x in enumerate(np.asarray(xs)):
                    truths.add(GroundTruthPath([GroundTruthState(
                        StateVector(x), timestamp=times[k])], id=f"{k}.{j}"))
    return StoneSoupRun(tracks=tracks, truths=truths, times=times)
