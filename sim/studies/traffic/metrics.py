"""Track metrics over hours of real traffic, in memory that grows with the tracks present at
once, not with every track of the run (issue 34 item 4).

:mod:`tracking.track_metrics` densifies a whole run into ``(T, n, m)`` pair distances; over
3 hours of 2 s ticks (``T = 5400``) with thousands of track ids that is tens of gigabytes. Here
OSPA(2) is computed on chunks of scans (each window looks back ``window - 1`` scans only, so
the curve is the same), HOTA from per-scan similarity of the tracks present (TrackEval's input
is per time step anyway), and per scan OSPA and GOSPA by :mod:`tracking.metrics`.

Per aircraft (:func:`per_aircraft`): ``continuity``, the share of its present scans held by
the single track matched to it most often (CLEAR MOT matching, :func:`tracking.track_metrics.
clear_match`), and its identity switches per hour present. An aircraft that leaves the region
(or is not reported for longer than ``traffic.max_gap``) and comes back is absent in between:
no track can hold it across, so :func:`visits` splits it into one truth per visit (a maximal
run of consecutive scans present) first.
"""

from __future__ import annotations

import numpy as np
from sensornet.tracking.metrics import gospa, ospa
from sensornet.tracking.track_metrics import (
    TrackTable,
    clear_match,
    clear_mot,
    ospa2_dense,
)


def _rows_between(t: TrackTable, lo: int, hi: int) -> TrackTable:
    """The rows of ``t`` with ``lo <= scan <= hi``."""
    keep = (t.scan >= lo) & (t.scan <= hi)
    return TrackTable(t.scan[keep], t.id[keep], t.pos[keep])


def by_chunks(fn, truth: TrackTable, est: TrackTable, grid: np.ndarray, window: int,
              chunk: int = 400, shape: tuple[int, ...] = ()) -> np.ndarray:
    """A windowed metric ``fn(est_dense, truth_dense) -> (t, *shape)`` over a long run,
    ``chunk`` scans of ``grid (T,)`` (sorted) at a time, each chunk with the ``window - 1``
    scans before it (a window looks back no further): ``(T, *shape)``."""
    grid = np.asarray(grid, dtype=np.int64)
    out = np.empty((len(grid), *shape))
    for a in range(0, len(grid), chunk):
        b = min(a + chunk, len(grid))
        s = max(a - window + 1, 0)
        sub = grid[s:b]
        T, E = (_rows_between(x, int(sub[0]), int(sub[-1])) for x in (truth, est))
        out[a:b] = fn(E.dense(sub)[1], T.dense(sub)[1])[a - s:]
    return out


def ospa2_curve(truth: TrackTable, est: TrackTable, grid: np.ndarray, c: float, p: float,
                window: int, chunk: int = 400) -> np.ndarray:
    """``(T,)`` OSPA(2) of the windows of ``window`` scans ending at each scan of ``grid (T,)``
    (sorted), equal to :func:`tracking.track_metrics.ospa2_dense` on the whole run, computed
    ``chunk`` scans at a time."""
    return by_chunks(lambda E, T: ospa2_dense(E, T, c, p, window), truth, est, grid, window,
                     chunk)


def _per_scan(t: TrackTable, grid: np.ndarray) -> list[np.ndarray]:
    """``[(n_k, dpos)]`` positions of ``t`` at each scan of ``grid``."""
    order = np.argsort(t.scan, kind="stable")
    s, pos = t.scan[order], t.pos[order]
    b = np.searchsorted(s, np.concatenate([grid, [grid[-1] + 1]]) if len(grid) else grid)
    return [pos[b[i]:b[i + 1]] for i in range(len(grid))]


def set_errors(truth: TrackTable, est: TrackTable, grid: np.ndarray, c: float, p: float
               ) -> tuple[np.ndarray, np.ndarray]:
    """``(ospa (T,), gospa (T,))`` per scan of ``grid`` (GOSPA with ``alpha = 2``)."""
    Y, X = _per_scan(truth, grid), _per_scan(est, grid)
    o = np.array([ospa(x, y, c, p) for x, y in zip(X, Y, strict=True)])
    g = np.array([gospa(x, y, c, p) for x, y in zip(X, Y, strict=True)])
    return o, g


def hota_sparse(truth: TrackTable, est: TrackTable, gate: float, grid: np.ndarray) -> dict:
    """HOTA, DetA, AssA, LocA (Luiten et al. 2021) by TrackEval, as
    :func:`tracking.track_metrics.hota` (similarity ``max(0, 1 - d / gate)``), from the tracks
    present at each scan only."""
    from trackeval.metrics import HOTA  # heavy optional dependency: trackeval

    grid = np.asarray(grid, dtype=np.int64)
    tid, tcol = np.unique(truth.id, return_inverse=True)
    eid, ecol = np.unique(est.id, return_inverse=True)
    to, eo = np.argsort(truth.scan, kind="stable"), np.argsort(est.scan, kind="stable")
    tb = np.searchsorted(truth.scan[to], np.append(grid, grid[-1] + 1))
    eb = np.searchsorted(est.scan[eo], np.append(grid, grid[-1] + 1))
    gt_ids, tr_ids, sims = [], [], []
    for k in range(len(grid)):
        ti, ei = to[tb[k]:tb[k + 1]], eo[eb[k]:eb[k + 1]]
        gt_ids.append(tcol[ti])
        tr_ids.append(ecol[ei])
        d = np.linalg.norm(truth.pos[ti][:, None] - est.pos[ei][None], axis=-1)
        sims.append(np.maximum(0.0, 1.0 - d / gate))
    data = {"num_timesteps": len(grid), "num_gt_ids": len(tid), "num_tracker_ids": len(eid),
            "num_gt_dets": len(truth.scan), "num_tracker_dets": len(est.scan),
            "gt_ids": gt_ids, "tracker_ids": tr_ids, "similarity_scores": sims}
    res = HOTA().eval_sequence(data)
    return {k.lower(): float(np.mean(res[k])) for k in ("HOTA", "DetA", "AssA", "LocA")}


def visits(truth: TrackTable, grid: np.ndarray) -> tuple[TrackTable, np.ndarray]:
    """``truth`` with one id per visit (a maximal run of consecutive scans of ``grid`` where
    the aircraft is present) and ``(v,)`` the aircraft id of each visit id ``0 .. v-1``."""
    pos_in_grid = np.searchsorted(grid, truth.scan)
    order = np.lexsort((pos_in_grid, truth.id))
    i, g = truth.id[order], pos_in_grid[order]
    new = np.ones(len(i), bool)
    new[1:] = (i[1:] != i[:-1]) | (g[1:] != g[:-1] + 1)
    vid = np.empty(len(i), np.int64)
    vid[order] = np.cumsum(new) - 1
    return TrackTable(truth.scan, vid, truth.pos), i[new]


def per_aircraft(truth: TrackTable, est: TrackTable, gate: float, grid: np.ndarray,
                 scan_period: float) -> dict[str, np.ndarray]:
    """Per true aircraft: ``id (m,)``, ``scans (m,)`` present, ``continuity (m,)`` (share of
    its present scans held by its most often matched track), ``switches (m,)`` and
    ``switches_per_hour (m,)`` (per hour present)."""
    mot = clear_mot(clear_match(truth, est, gate, grid))
    pt = mot["per_truth"]
    hours = pt["scans"] * scan_period / 3600.0
    return {"id": pt["id"], "scans": pt["scans"], "continuity": pt["continuity"],
            "switches": pt["switches"],
            "switches_per_hour": pt["switches"] / np.maximum(hours, 1e-12),
            "matches": mot["matches"], "switches_total": mot["switches"],
            "truth_scans": mot["truth_scans"]}
