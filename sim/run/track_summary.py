"""Track-level numbers of a finished run, from its per-track table (issue 33 item 5): per peer
and estimate (local, fused) OSPA(2) and identity switches per 1,000 true
target-scans, per peer the share of its fused target-scans whose id every other peer gave the
same target, and the network's label agreement.

Input: each peer's per-scan columns (:data:`peers.scan_results.COLUMNS`, as its part or the
merged ``results.parquet`` holds them). Tracks are matched to the truth by CLEAR MOT
(:func:`tracking.track_metrics.clear_match`, gate the OSPA cut-off); OSPA(2) is Beard, Vo & Vo
2020 (:func:`tracking.track_metrics.ospa2`) on windows of :data:`WINDOW` scans ending at each
scan, averaged over the run (one window over a whole run charges every short-lived false track
the cut-off for the whole run; ``ospa2_run`` keeps that number). Trajectory GOSPA and HOTA
are left out: too slow for the end of every run (``track_report`` has them).
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
from sensornet.tracking.track_metrics import TrackTable, clear_match, clear_mot, ospa2

ESTIMATES = ("local", "fused")
WINDOW = 10
"""OSPA(2)'s window in scans (tracking.track_metrics.track_report's default)."""


def _rows(cols: Mapping[str, list], which: str, pos: list[int]):
    """``(scans (N,), ids (N, 3), xy (N, 2), row scans (R,))`` of one peer's ``which`` tracks
    (an id twice in one scan keeps its first, heaviest row); None when the peer has tracks but
    no ids (a kind without labels)."""
    sel = [i for i, e in enumerate(cols["estimate"]) if e == which]
    row_scans = np.asarray([cols["scan"][i] for i in sel], dtype=np.int64)
    n = [len(cols["tracks"][i]) for i in sel]
    ids = [cols["track_ids"][i] for i in sel]
    if any(len(t) != k for t, k in zip(ids, n, strict=True)):
        return None  # tracks without their ids
    scans = np.repeat(row_scans, n)
    if not len(scans):
        return scans, np.zeros((0, 3), np.int64), np.zeros((0, 2)), row_scans
    X = np.asarray([x for i in sel for x in cols["tracks"][i]], dtype=float)[:, pos]
    L = np.asarray([lab for t in ids for lab in t], dtype=np.int64).reshape(-1, 3)
    return scans, L, X, row_scans


def _truth(tables: Mapping[str, Mapping[str, list]], pos: list[int]) -> TrackTable | None:
    """The true targets by id over every scan any peer has a row for; None without ids."""
    seen: dict[int, tuple[list, list]] = {}
    for cols in tables.values():
        for k, t, ids in zip(cols["scan"], cols["truth"], cols["truth_ids"], strict=True):
            if int(k) not in seen:
                if len(ids) != len(t):
                    return None
                seen[int(k)] = (t, ids)
    S = np.repeat(np.fromiter(seen, np.int64, len(seen)), [len(v[1]) for v in seen.values()])
    ids = np.asarray([i for _, v in seen.values() for i in v], dtype=np.int64)
    X = (np.asarray([x for t, _ in seen.values() for x in t], dtype=float)[:, pos]
         if len(ids) else np.zeros((0, 2)))
    return TrackTable(S, ids, X)


def track_summary(tables: Mapping[str, Mapping[str, list]], position_index, cutoff: float,
                  order: float = 2.0) -> dict:
    """Track-level numbers of one run: ``{"peers": {peer: {"local": m, "fused": m,
    "agreement": a}}, "label_agreement": a, "confirmed": n}`` with ``m = {"ospa2" (mean over
    windows of :data:`WINDOW` scans), "ospa2_run" (one window), "switches",
    "switches_per_1000", "fragmentations", "truth_scans"}`` (None for a peer
    without ids) and ``a`` the share of target-scans matched at this peer (at every peer, for
    the run's number) and at one other peer or more whose ids all agree (NaN when none).

    ``tables``: ``{peer: columns}`` (``scan``, ``estimate``, ``tracks``, ``track_ids``,
    ``truth``, ``truth_ids``); ``position_index``: where x, y sit in a state row. The
    evaluation grid is every scan any peer has a row for, so a peer's missing scans (it was
    killed, or late) count as misses. Empty dict when the truth has no ids."""
    pos = list(position_index)
    truth = _truth(tables, pos)
    if truth is None or not tables:
        return {}
    grid = np.unique(np.concatenate([np.asarray(c["scan"], np.int64) for c in tables.values()]
                                    + [truth.scan]))
    rows = {(p, w): _rows(cols, w, pos) for p, cols in tables.items() for w in ESTIMATES}
    labelled = [r for r in rows.values() if r is not None]
    every = (np.concatenate([r[1] for r in labelled]) if labelled
             else np.zeros((0, 3), np.int64))
    _, code = np.unique(every, axis=0, return_inverse=True)  # one integer per id, all peers
    code = code.reshape(-1)
    out: dict = {"peers": {p: {} for p in tables}}
    matched: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    start = 0
    for (p, w), r in rows.items():
        if r is None:
            out["peers"][p][w] = None
            continue
        scans, _, X, _ = r
        ids = code[start:start + len(scans)]
        start += len(scans)
        _, first = np.unique(np.stack([scans, ids], axis=1), axis=0, return_index=True)
        first = np.sort(first)  # the first (heaviest) row of an id in a scan
        est = TrackTable(scans[first], ids[first], X[first])
        cl = clear_match(truth, est, cutoff, grid)
        mot = clear_mot(cl)
        n = mot["truth_scans"]
        out["peers"][p][w] = {
            "ospa2": float(ospa2(truth, est, cutoff, order, WINDOW, grid).mean()),
            "ospa2_run": float(ospa2(truth, est, cutoff, order, None, grid)[0]),
            "switches": mot["switches"], "fragmentations": mot["fragmentations"],
            "switches_per_1000": 1000.0 * mot["switches"] / n if n else float("nan"),
            "truth_scans": n}
        if w == "fused":
            label = cl.est_ids[np.maximum(cl.match, 0)] if len(cl.est_ids) else cl.match
            matched[p] = (cl.match >= 0, label)  # (T, m) each
    if matched:
        F = np.stack([m for m, _ in matched.values()])  # (P, T, m): matched at each peer
        L = np.stack([lab for _, lab in matched.values()])  # (P, T, m): its id there
        for i, p in enumerate(matched):
            others = np.delete(np.arange(len(matched)), i)
            seen = F[i] & F[others].any(axis=0)
            same = seen & (~F[others] | (L[others] == L[i])).all(axis=0)
            out["peers"][p]["agreement"] = (float(same.sum() / seen.sum()) if seen.sum()
                                            else float("nan"))
        at_all = F.all(axis=0)
        agree = at_all & (L == L[0]).all(axis=0)
        out["label_agreement"] = (float(agree.sum() / at_all.sum()) if at_all.sum()
                                  else float("nan"))
        out["confirmed"] = int(at_all.sum())
    for p in tables:
        out["peers"][p].setdefault("agreement", None)
    return out


def track_columns(ts: dict) -> dict[str, float]:
    """A campaign row's track-level columns from :func:`track_summary`: ``fused_ospa2``,
    ``local_ospa2`` and ``fused_switches_per_1000`` averaged over the peers with ids, and the
    run's ``label_agreement``; empty when no peer has ids."""
    peers = [v for v in (ts.get("peers") or {}).values()]
    out: dict[str, float] = {}
    for which, key, col in (("fused", "ospa2", "fused_ospa2"), ("local", "ospa2", "local_ospa2"),
                            ("fused", "switches_per_1000", "fused_switches_per_1000")):
        vals = [p[which][key] for p in peers if p.get(which)]
        if vals:
            out[col] = float(np.nanmean(vals)) if np.isfinite(vals).any() else float("nan")
    if "label_agreement" in ts:
        out["label_agreement"] = float(ts["label_agreement"])
    return out
