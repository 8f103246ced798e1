"""Track-level metrics over whole runs: OSPA(2), trajectory GOSPA, CLEAR MOT (MOTA, MOTP,
identity switches, fragmentations), IDF1, HOTA, and label agreement between peers.

Input: a flat table, one row per (scan, track id) — the layout of a results parquet table with
one row per (peer, scan, id) once split by peer (:func:`tables_by_peer`)::

    TrackTable(scan (N,) int64, id (N,) int64, pos (N, dpos) float)

Truth and estimates are tables of the same layout; an estimate's ``id`` is its label, a
truth's ``id`` the target. Internally a table becomes dense trajectories over a common scan
grid, ``(T, n_tracks, dpos)`` with NaN where a track is absent (:meth:`TrackTable.dense`).
The grid defaults to the union of both tables' scans; pass ``scans`` when scans with nothing in
either table must count (OSPA(2) windows are positions on the grid).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment
from sensornet.tracking.tgospa import trajectory_gospa


@dataclass(frozen=True)
class TrackTable:
    """Tracks as rows: ``scan (N,) int64``, ``id (N,) int64``, ``pos (N, dpos)``; a (scan, id)
    pair at most once."""

    scan: np.ndarray
    id: np.ndarray
    pos: np.ndarray

    def __post_init__(self) -> None:
        scan = np.asarray(self.scan, dtype=np.int64).reshape(-1)
        ids = np.asarray(self.id, dtype=np.int64).reshape(-1)
        pos = np.asarray(self.pos, dtype=float)
        if pos.ndim == 1:
            pos = pos.reshape(len(scan), -1) if len(scan) else pos.reshape(0, 1)
        if not (len(scan) == len(ids) == len(pos)):
            raise ValueError(f"TrackTable columns differ in length: scan {len(scan)}, "
                             f"id {len(ids)}, pos {len(pos)}")
        if not np.isfinite(pos).all():
            raise ValueError("TrackTable.pos has a non-finite value")
        key = np.stack([scan, ids], axis=1)
        if len(key) and len(np.unique(key, axis=0)) != len(key):
            raise ValueError("TrackTable has a (scan, id) pair twice")
        object.__setattr__(self, "scan", scan)
        object.__setattr__(self, "id", ids)
        object.__setattr__(self, "pos", pos)

    @classmethod
    def from_columns(cls, columns, pos: Sequence[str] = ("x", "y"), scan: str = "scan",
                     id: str = "id") -> TrackTable:
        """From anything indexable by column name (dict of arrays, pandas or pyarrow table)."""
        return cls(np.asarray(columns[scan]), np.asarray(columns[id]),
                   np.stack([np.asarray(columns[c], dtype=float) for c in pos], axis=1))

    def dense(self, scans: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(ids (n,), P (T, n, dpos))`` on the grid ``scans (T,)`` (sorted), NaN where a track
        is absent; ids sorted ascending."""
        ids, col = np.unique(self.id, return_inverse=True)
        row = np.searchsorted(scans, self.scan)
        if len(row) and (row.max() >= len(scans) or np.any(scans[row] != self.scan)):
            raise ValueError("TrackTable has a scan outside the evaluation grid")
        P = np.full((len(scans), len(ids), self.pos.shape[1]), np.nan)
        P[row, col] = self.pos
        return ids, P


def tables_by_peer(columns, peer: str = "peer", pos: Sequence[str] = ("x", "y"),
                   scan: str = "scan", id: str = "id") -> dict:
    """Split a flat table with a ``peer`` column into ``{peer: TrackTable}``."""
    peers = np.asarray(columns[peer])
    cols = {k: np.asarray(columns[k]) for k in (scan, id, *pos)}
    return {pv: TrackTable.from_columns({k: v[peers == pv] for k, v in cols.items()},
                                        pos, scan, id)
            for pv in np.unique(peers).tolist()}


def _grid(*tables: TrackTable, scans: np.ndarray | None = None) -> np.ndarray:
    if scans is not None:
        return np.unique(np.asarray(scans, dtype=np.int64))
    return np.unique(np.concatenate([t.scan for t in tables]))


def _pair_dist(E: np.ndarray, Y: np.ndarray) -> np.ndarray:
    """``(T, n, m)`` distances between estimates ``E (T, n, d)`` and truths ``Y (T, m, d)``,
    NaN where either is absent. Memory ``O(T n m)``."""
    return np.linalg.norm(E[:, :, None, :] - Y[:, None, :, :], axis=-1)


# ---------------------------------------------------------------------------------------------
# OSPA(2)


def ospa2_dense(E: np.ndarray, Y: np.ndarray, c: float = 200.0, p: float = 2.0,
                window: int | None = None) -> np.ndarray:
    """OSPA(2) (Beard, Vo & Vo 2020, IEEE TSP 68, Sec. VI; Beard et al. 2017) between dense
    estimates ``E (T, n, d)`` and truth ``Y (T, m, d)``, per window ending at each scan:
    ``(T,)``. ``window=None``: one window over all scans, returned as ``(1,)``.

    Base distance between tracks ``x, y`` on a window: the mean over the scans where at least
    one exists of ``min(c, |x_t - y_t|)`` (both exist) or ``c`` (one exists); then OSPA of
    order ``p``, cut-off ``c`` between the sets of tracks present in the window.
    """
    T = E.shape[0]
    ex, ty = ~np.isnan(E).any(-1), ~np.isnan(Y).any(-1)  # (T, n), (T, m)
    D = _pair_dist(E, Y)
    either = ex[:, :, None] | ty[:, None, :]
    C = np.where(np.isnan(D), np.where(either, c, 0.0), np.minimum(D, c))  # (T, n, m)

    def cum(a: np.ndarray) -> np.ndarray:  # window sums as differences of these
        return np.concatenate([np.zeros((1, *a.shape[1:])), np.cumsum(a, axis=0)])

    cC, cU, cx, cy = cum(C), cum(either.astype(float)), cum(ex.astype(float)), cum(ty.astype(float))
    ends = np.arange(1, T + 1) if window else np.array([T])
    starts = np.maximum(ends - window, 0) if window else np.array([0])
    out = np.empty(len(ends))
    for k, (s, e) in enumerate(zip(starts, ends, strict=True)):
        xi, yj = np.nonzero(cx[e] - cx[s])[0], np.nonzero(cy[e] - cy[s])[0]
        n, m = len(xi), len(yj)
        if n == 0 or m == 0:
            out[k] = 0.0 if n == m else c
            continue
        sub = np.ix_(xi, yj)
        base = (cC[e][sub] - cC[s][sub]) / (cU[e][sub] - cU[s][sub])
        B = base**p
        r, q = linear_sum_assignment(B)
        out[k] = ((B[r, q].sum() + c**p * abs(n - m)) / max(n, m)) ** (1.0 / p)
    return out


DENSE_LIMIT = 20_000_000
"""Pair-scan cells ``T x n x m`` above which :func:`ospa2` works a chunk of scans at a time
(a 3-hour run with thousands of track ids is tens of gigabytes dense)."""


def ospa2(truth: TrackTable, est: TrackTable, c: float = 200.0, p: float = 2.0,
          window: int | None = None, scans: np.ndarray | None = None,
          limit: int = DENSE_LIMIT) -> np.ndarray:
    """:func:`ospa2_dense` on tables: per-scan curve ``(T,)`` over windows of ``window`` scans,
    or the whole-run value as ``(1,)`` when ``window`` is None. Dense up to ``limit`` pair-scan
    cells; above it in chunks of scans, in memory that grows with the tracks present in a
    chunk (equal to the dense value up to summation order)."""
    grid = _grid(truth, est, scans=scans)
    n, m = len(np.unique(est.id)), len(np.unique(truth.id))
    if len(grid) * n * m <= limit:
        return ospa2_dense(est.dense(grid)[1], truth.dense(grid)[1], c, p, window)
    per = max(1, limit // max(n * m, 1))
    if window is None:
        return _ospa2_run_chunked(truth, est, grid, c, p, per)
    return _ospa2_windows_chunked(truth, est, grid, c, p, window, per)


def _between(t: TrackTable, lo: int, hi: int) -> TrackTable:
    """The rows of ``t`` with ``lo <= scan <= hi``."""
    keep = (t.scan >= lo) & (t.scan <= hi)
    return TrackTable(t.scan[keep], t.id[keep], t.pos[keep])


def _ospa2_windows_chunked(truth: TrackTable, est: TrackTable, grid: np.ndarray, c: float,
                           p: float, window: int, per: int) -> np.ndarray:
    """The windowed curve a chunk of scans at a time, each chunk with the ``window - 1``
    scans before it (a window looks back no further); chunks of at least ``4 window``."""
    chunk = max(per, 4 * window)
    out = np.empty(len(grid))
    for a in range(0, len(grid), chunk):
        b = min(a + chunk, len(grid))
        s = max(a - window + 1, 0)
        sub = grid[s:b]
        T, E = (_between(x, int(sub[0]), int(sub[-1])) for x in (truth, est))
        out[a:b] = ospa2_dense(E.dense(sub)[1], T.dense(sub)[1], c, p, window)[a - s:]
    return out


def _ospa2_run_chunked(truth: TrackTable, est: TrackTable, grid: np.ndarray, c: float,
                       p: float, per: int) -> np.ndarray:
    """The whole-run value from per-pair sums gathered a chunk of scans at a time: over the
    run, a pair's summed cost is ``sum_both min(d, c) + c (n_x + n_y - 2 n_both)`` and its
    scans with either ``n_x + n_y - n_both`` (``n_x``, ``n_y``: scans present)."""
    eids, tids = np.unique(est.id), np.unique(truth.id)
    S = np.zeros((len(eids), len(tids)))  # sum of min(d, c) over scans with both
    nb = np.zeros((len(eids), len(tids)))  # scans with both
    for a in range(0, len(grid), per):
        sub = grid[a:a + per]
        T, E = (_between(x, int(sub[0]), int(sub[-1])) for x in (truth, est))
        (ei, Ed), (ti, Yd) = E.dense(sub), T.dense(sub)
        if not len(ei) or not len(ti):
            continue
        D = _pair_dist(Ed, Yd)  # (t, n, m), NaN unless both present
        both = ~np.isnan(D)
        blk = np.ix_(np.searchsorted(eids, ei), np.searchsorted(tids, ti))
        S[blk] += np.where(both, np.minimum(D, c), 0.0).sum(axis=0)
        nb[blk] += both.sum(axis=0)
    nx = np.bincount(np.searchsorted(eids, est.id), minlength=len(eids)).astype(float)
    ny = np.bincount(np.searchsorted(tids, truth.id), minlength=len(tids)).astype(float)
    n, m = len(eids), len(tids)
    if n == 0 or m == 0:
        return np.array([0.0 if n == m else c])
    cost = S + c * (nx[:, None] + ny[None, :] - 2 * nb)
    base = cost / (nx[:, None] + ny[None, :] - nb)
    B = base**p
    r, q = linear_sum_assignment(B)
    return np.array([((B[r, q].sum() + c**p * abs(n - m)) / max(n, m)) ** (1.0 / p)])


# ---------------------------------------------------------------------------------------------
# CLEAR MOT and identity


@dataclass(frozen=True)
class Clear:
    """CLEAR MOT matching (Bernardin & Stiefelhagen 2008) of estimates to truths.

    ``match (T, m)``: the matched estimate's column (in ``est_ids``) per scan and truth, -1 if
    unmatched or absent; ``dist (T, m)`` its distance (NaN otherwise); ``switch (T, m)``: an
    identity switch there (the truth's matched estimate differs from its last matched one);
    ``truth_ids (m,)``, ``est_ids (n,)``; ``present (T, m)``, ``est_present (T, n)``.
    """

    truth_ids: np.ndarray
    est_ids: np.ndarray
    present: np.ndarray
    est_present: np.ndarray
    match: np.ndarray
    dist: np.ndarray
    switch: np.ndarray


def clear_match(truth: TrackTable, est: TrackTable, gate: float,
                scans: np.ndarray | None = None) -> Clear:
    """Per scan: keep last scan's correspondences still within ``gate``, then assign the rest
    by least total distance among pairs within ``gate`` (most pairs first), as py-motmetrics'
    ``MOTAccumulator.update`` does; a truth earlier in id order keeps a contested estimate."""
    grid = _grid(truth, est, scans=scans)
    tids, Y = truth.dense(grid)
    eids, E = est.dense(grid)
    T, m, n = len(grid), len(tids), len(eids)
    ty, ex = ~np.isnan(Y).any(-1), ~np.isnan(E).any(-1)
    match = np.full((T, m), -1)
    dist = np.full((T, m), np.nan)
    switch = np.zeros((T, m), bool)
    last = np.full(m, -1)  # last matched estimate per truth
    for t in range(T):
        J, I = np.nonzero(ty[t])[0], np.nonzero(ex[t])[0]
        if len(J) == 0 or len(I) == 0:
            continue
        D = np.linalg.norm(Y[t, J][:, None] - E[t, I][None], axis=-1)  # (|J|, |I|)
        ok = D <= gate
        where = np.full(n, -1)
        where[I] = np.arange(len(I))
        k = np.where(last[J] >= 0, where[last[J]], -1)
        keep = (k >= 0) & ok[np.arange(len(J)), np.maximum(k, 0)]
        rows = np.nonzero(keep)[0]
        _, first = np.unique(k[rows], return_index=True)
        rows = rows[first]  # a contested estimate stays with the first truth
        cols = k[rows]
        free_r = np.setdiff1d(np.arange(len(J)), rows)
        free_c = np.setdiff1d(np.arange(len(I)), cols)
        sub = ok[np.ix_(free_r, free_c)]
        if sub.any():
            Ds = D[np.ix_(free_r, free_c)]
            big = 2 * min(sub.shape) * (Ds[sub].max() + 1) + 1
            r, q = linear_sum_assignment(np.where(sub, Ds, big))
            good = sub[r, q]
            new_r, new_c = free_r[r[good]], free_c[q[good]]
            jj = J[new_r]
            switch[t, jj] = (last[jj] >= 0) & (last[jj] != I[new_c])
            rows, cols = np.concatenate([rows, new_r]), np.concatenate([cols, new_c])
        match[t, J[rows]] = I[cols]
        dist[t, J[rows]] = D[rows, cols]
        last[J[rows]] = I[cols]
    return Clear(tids, eids, ty, ex, match, dist, switch)


def clear_mot(cl: Clear) -> dict:
    """MOTA, MOTP (mean matched distance), switches, fragmentations (tracked -> untracked ->
    tracked over the truth's present scans), mostly tracked / lost (>= 80 % / <= 20 % of present
    scans matched), and per truth: ``continuity`` (share of its present scans matched to its most
    often matched estimate) and ``switches``."""
    tracked = cl.match >= 0
    n_gt = int(cl.present.sum())
    n_match = int(tracked.sum())
    misses, fps = n_gt - n_match, int(cl.est_present.sum()) - n_match
    sw = int(cl.switch.sum())
    # fragmentation: a re-acquisition after an untracked present scan, once tracked before
    T, m = tracked.shape
    t_idx = np.arange(T)[:, None]
    last_present = np.maximum.accumulate(np.where(cl.present, t_idx, -1), axis=0)
    prev_present = np.vstack([np.full((1, m), -1), last_present[:-1]])
    prev_tracked = np.where(prev_present >= 0,
                            tracked[np.maximum(prev_present, 0), np.arange(m)], False)
    ever = np.vstack([np.zeros((1, m), bool), np.logical_or.accumulate(tracked, axis=0)[:-1]])
    frag = tracked & (prev_present >= 0) & ~prev_tracked & ever
    counts = np.zeros((m, len(cl.est_ids)))
    tt, jj = np.nonzero(tracked)
    np.add.at(counts, (jj, cl.match[tt, jj]), 1)
    present_n = cl.present.sum(axis=0)
    ratio = tracked.sum(axis=0) / np.maximum(present_n, 1)
    return {
        "mota": 1.0 - (misses + fps + sw) / n_gt if n_gt else float("nan"),
        "motp": float(np.nansum(cl.dist) / n_match) if n_match else float("nan"),
        "matches": n_match, "misses": misses, "false": fps, "switches": sw,
        "fragmentations": int(frag.sum()), "truth_scans": n_gt,
        "mostly_tracked": int((ratio >= 0.8)[present_n > 0].sum()),
        "mostly_lost": int((ratio <= 0.2)[present_n > 0].sum()),
        "per_truth": {
            "id": cl.truth_ids,
            "continuity": (counts.max(axis=1, initial=0) / np.maximum(present_n, 1)),
            "switches": cl.switch.sum(axis=0),
            "fragmentations": frag.sum(axis=0),
            "scans": present_n,
        },
    }


def idf1(truth: TrackTable, est: TrackTable, gate: float,
         scans: np.ndarray | None = None) -> dict:
    """IDF1, IDP, IDR (Ristani et al. 2016): one-to-one truth-estimate identity matching that
    maximises the scans where the pair is within ``gate`` (IDTP)."""
    grid = _grid(truth, est, scans=scans)
    _, Y = truth.dense(grid)
    _, E = est.dense(grid)
    within = (_pair_dist(E, Y) <= gate).sum(axis=0)  # (n, m) co-located scans per pair
    r, q = linear_sum_assignment(-within) if within.size else ([], [])
    idtp = int(within[r, q].sum())
    n_gt, n_est = int((~np.isnan(Y).any(-1)).sum()), int((~np.isnan(E).any(-1)).sum())
    return {"idf1": 2 * idtp / (n_gt + n_est) if n_gt + n_est else float("nan"),
            "idp": idtp / n_est if n_est else float("nan"),
            "idr": idtp / n_gt if n_gt else float("nan"), "idtp": idtp,
            "idfp": n_est - idtp, "idfn": n_gt - idtp}


def hota(truth: TrackTable, est: TrackTable, gate: float,
         scans: np.ndarray | None = None) -> dict:
    """HOTA, DetA, AssA, LocA (Luiten et al. 2021, IJCV 129) by TrackEval's implementation,
    averaged over its thresholds alpha = 0.05 .. 0.95, with similarity ``max(0, 1 - d / gate)``
    between points (a pair matches at threshold alpha when within ``(1 - alpha) gate``)."""
    from trackeval.metrics import HOTA  # heavy optional dependency: trackeval

    grid = _grid(truth, est, scans=scans)
    _, Y = truth.dense(grid)
    _, E = est.dense(grid)
    ty, ex = ~np.isnan(Y).any(-1), ~np.isnan(E).any(-1)
    S = np.maximum(0.0, 1.0 - _pair_dist(E, Y) / gate)  # (T, n, m), NaN where absent
    data = {"num_timesteps": len(grid), "num_gt_ids": Y.shape[1],
            "num_tracker_ids": E.shape[1], "num_gt_dets": int(ty.sum()),
            "num_tracker_dets": int(ex.sum()),
            "gt_ids": [np.nonzero(r)[0] for r in ty],
            "tracker_ids": [np.nonzero(r)[0] for r in ex],
            "similarity_scores": [S[t][np.ix_(ex[t], ty[t])].T for t in range(len(grid))]}
    res = HOTA().eval_sequence(data)
    return {k.lower(): float(np.mean(res[k])) for k in ("HOTA", "DetA", "AssA", "LocA")}


# ---------------------------------------------------------------------------------------------
# report and label agreement


def track_report(truth: TrackTable, est: TrackTable, c: float = 200.0, p: float = 2.0,
                 gamma: float | None = None, gate: float | None = None, window: int = 10,
                 scans: np.ndarray | None = None, with_hota: bool = True,
                 with_tgospa: bool = True) -> dict:
    """Every track metric of one run (one peer's estimates against the truth).

    ``gate`` (default ``c``): CLEAR MOT / IDF1 / HOTA match distance; ``gamma`` (default
    ``c``): trajectory GOSPA switch cost; ``window``: OSPA(2) window in scans. Returns plain
    floats/ints plus ``ospa2_curve (T,)``, ``scans (T,)`` and ``per_truth`` arrays;
    ``switches_per_1000`` is identity switches per 1,000 true target-scans. The trajectory
    GOSPA programme has ``T x K`` weights (``K``: pairs ever within ``c``), the slow part on
    long cluttered runs (1,000 scans, 554 pairs: ~25 s); ``with_tgospa=False`` skips it.
    """
    gate = c if gate is None else gate
    gamma = c if gamma is None else gamma
    grid = _grid(truth, est, scans=scans)
    _, Y = truth.dense(grid)
    _, E = est.dense(grid)
    cl = clear_mot(clear_match(truth, est, gate, grid))
    n_gt = cl["truth_scans"]
    curve = ospa2_dense(E, Y, c, p, window)
    out = {
        "scans": grid, "ospa2": float(ospa2_dense(E, Y, c, p, None)[0]),
        "ospa2_curve": curve, "ospa2_mean": float(curve.mean()) if len(grid) else 0.0,
        **cl,
        "switches_per_1000": 1000.0 * cl["switches"] / n_gt if n_gt else float("nan"),
        **idf1(truth, est, gate, grid),
    }
    if with_tgospa:
        tg = trajectory_gospa(E, Y, c, p, gamma)
        out.update({"tgospa": tg.distance,
                    "tgospa_per_scan": tg.distance / max(len(grid), 1) ** (1 / p),
                    "tgospa_localisation": tg.localisation, "tgospa_missed": tg.missed,
                    "tgospa_false": tg.false, "tgospa_switches": tg.switches,
                    "tgospa_integral": tg.integral})
    if with_hota:
        out.update(hota(truth, est, gate, grid))
    return out


def first_match_delay(truth: TrackTable, est: TrackTable, gate: float,
                      scans: np.ndarray | None = None) -> np.ndarray:
    """Track latency: per truth that some estimate ever matched (:func:`clear_match`,
    ``gate``), the scans from its first present scan to its first matched scan, ``(q,)``
    float (0: matched at once). With the confirmed tracks as ``est`` this is what a
    confirmation rule costs in latency (issue 33: confirmation that waits for the label to
    settle); truths never matched are left out (they are misses, not delays)."""
    cl = clear_match(truth, est, gate, scans)
    grid = _grid(truth, est, scans=scans)
    present, matched = cl.present, cl.match >= 0  # (T, m)
    seen = matched.any(axis=0)
    born = grid[present.argmax(axis=0)]
    first = grid[matched.argmax(axis=0)]
    return (first - born)[seen].astype(float)


def label_agreement(tables_by_peer: Mapping[object, TrackTable], truth: TrackTable,
                    gate: float, scans: np.ndarray | None = None) -> dict:
    """Share of confirmed target-scans where every peer's matched estimate carries the same id.

    Each peer's estimates are matched to the truth by :func:`clear_match` (``gate``).
    ``agreement``: among (truth, scan) pairs matched at every peer, the share where all the
    matched ids are equal; ``agreement_any``: among pairs matched at one peer or more, the share
    matched at every peer with equal ids (a peer without a match disagrees)."""
    if not tables_by_peer:
        raise ValueError("label_agreement needs at least one peer's table")
    grid = _grid(truth, *tables_by_peer.values(), scans=scans)
    labels, found = [], []
    for tab in tables_by_peer.values():
        cl = clear_match(truth, tab, gate, grid)
        found.append(cl.match >= 0)
        labels.append(cl.est_ids[np.maximum(cl.match, 0)] if len(cl.est_ids) else cl.match)
    L, matched = np.stack(labels), np.stack(found)  # (P, T, m): matched estimate id, whether
    every, some = matched.all(axis=0), matched.any(axis=0)
    same = every & (L == L[0]).all(axis=0)
    n_all, n_any, n_same = int(every.sum()), int(some.sum()), int(same.sum())
    return {"agreement": n_same / n_all if n_all else float("nan"),
            "agreement_any": n_same / n_any if n_any else float("nan"),
            "confirmed": n_all, "confirmed_any": n_any, "agreeing": n_same}
