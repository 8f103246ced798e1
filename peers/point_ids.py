"""Track ids for the peer kinds whose filters have no labels (issue 33 item 2).

The single-target kinds (IMM-PF / IMM-EKF, the PDA family), the extended-target GM-PHD and
flooding's clustering extract points, not labelled tracks. A :class:`PointIds` attached to such
an estimator (its optional ``point_tracks`` hook, :class:`peers.contracts.EstimatorHooks`) gives
those points ids by :class:`tracking.point_tracks.PointTracker`: one tracker for the peer's
local estimates, one for its published (fused) tracks. The core fills the ids and status into
the published :class:`~protocol.messages.Tracks` (protocol 2) and the results table
(:class:`peers.core_outputs.CoreOutputs`); the points themselves are never changed.

A kind that labels its own components (``origin`` hook: GM-PHD with tags, LMB) never uses it.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from sensornet.protocol.messages import Tracks
from sensornet.tracking.point_tracks import PointTrackConfig, PointTracker


class PointIds:
    """The local and the fused point trackers of one peer.

    ``origin``: the peer's label origin (:func:`peers.labelling.origin_of`), the first column
    of its local ids; the fused ids take ``config.fused_origin`` when set (a network-wide
    origin: see :class:`tracking.point_tracks.PointTrackConfig`). ``position_index``: the
    columns of (x, y) in a state row. A scan number at or below the last one (the world's
    numbering restarted) starts a fresh tracker."""

    def __init__(self, origin: int, config: PointTrackConfig,
                 position_index: tuple[int, int]) -> None:
        self.origin = int(origin)
        self.config = config
        self.position_index = tuple(position_index)
        fo = self.origin if config.fused_origin is None else int(config.fused_origin)
        self.local = PointTracker(self.origin, config)
        self.fused = PointTracker(fo, config)

    def _ids(self, which: str, k: int, states: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        tr: PointTracker = getattr(self, which)
        if tr.k is not None and k <= tr.k:
            tr = PointTracker(tr.origin, self.config)
            setattr(self, which, tr)
        X = np.asarray(states, dtype=float)
        X = X.reshape(len(X), -1) if X.size else np.zeros((0, 2))
        return tr.update(k, X[:, list(self.position_index)] if len(X) else X)

    def local_ids(self, k: int, states: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Ids ``(n, 3)`` and status ``(n,)`` of the local estimate's states ``(n, d)``."""
        return self._ids("local", k, states)

    def tracks(self, msg: Tracks) -> Tracks:
        """``msg`` with the ids and status of its states (one fused tracker update), or
        ``msg`` itself if it carries ids already."""
        if msg.ids is not None:
            return msg
        ids, status = self._ids("fused", msg.k, msg.states)
        return replace(msg, ids=ids, status=status)


def single_target(fusing: bool) -> PointTrackConfig:
    """A single-target kind's one track (IMM, PDA): any distance, confirmed once initialised,
    never deleted while its filter runs (it reports one state every scan). Fused, the network's
    id: every peer initialises the one target at its first scan, and by the earliest-birth,
    lowest-origin rule (:mod:`peers.labelling`) that is origin 0's, ``(0, first scan, 0)``;
    without fusion (``fusing`` False) each peer's own."""
    return PointTrackConfig(fused_origin=0 if fusing else None)


EXTRACTED = PointTrackConfig(gate=100.0, m=3, n=4, max_missed=3, fused_origin=0)
"""Extracted targets of the multi-target kinds without labels (extended-target GM-PHD, seed
002; flooding's clustering, seed 004): a target moves at most ~35 m a scan there and its
extracted position is off by about a noise deviation (10-20 m), so a 100 m gate around the
alpha-beta prediction holds it while two targets 100 m apart stay apart; confirmed after 3 of 4
scans (a clutter cluster seldom recurs at one place), deleted after 3 scans missed. Fused ids
take origin 0, the network's: peers whose fused points (nearly) coincide (flooding peers
pooling the same scans, ET-GM-PHD peers fusing on a full mesh) then give a target the same id,
births being numbered by position."""
