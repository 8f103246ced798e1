"""Where the fused tracks hold an aircraft later than the centralised reference, and which stage
holds them (issue 34, docs/real-traffic.md "Fused births pooled across radars").

An aircraft-tick is **held** by a table if one of its tracks lies within the OSPA cut-off of
the aircraft at that tick (any track: this asks whether an aircraft is covered, not by whom).
Per aircraft visit (:func:`.metrics.visits`): the first tick each table holds it, counted from
the visit's first tick (the visit's length if never). For the fused tracks against the
reference, a visit's **lag** (ticks the reference held it first) is split in order into

* ``local``: no peer's own (local) track held it yet (the peers' confirmation, ``r > 0.5``,
  which is also their publication threshold when tentative tracks are off);
* ``second``: one peer did, not two (pooling two inputs' existences,
  ``fusion.existence_prior``, needs two);
* ``half``: two did, but fewer than half of them plus one (5 of 8): the hybrid rule's fused
  existence of a target is the average of the peers' (AA, 1/8 each on the full graph), so
  ``round`` extraction (``r > 0.5``) waits for a majority;
* ``after``: a majority held it and the fused tracks still did not (fused labels, the support
  rule, existences below 1, the peers' tracks apart).

And the aircraft-ticks the reference holds and the fused tracks do not, over whole visits, by
how many peers' local tracks hold them then.

Why the other peers do not hold the aircraft in the ``half`` stage (:func:`waiting`): for each
peer without a track on it there, its own sensor model's ``Pd`` at the aircraft (the range
curve of the shared scenario, ``sim.world.birth.radar_pd``: could it see it at all?) and how
many plots of the aircraft its radar had made in the visit by then (has it had the data to
confirm?); and per peer, the ticks from its first plot of a visit to its first track on it.

``python -m sensornet.sim.studies.traffic.starts [SCENARIO] --file F --start S --minutes M
[--set KEY=VALUE ...] [--peer NAME]``: LMB peers (their fused twin gives both the local and the
fused tracks) against the asynchronous centralised LMB.
"""

from __future__ import annotations

import argparse
import sys

import numpy as np
from sensornet.sim.run.twin import run_twin
from sensornet.sim.scenario import ScenarioError
from sensornet.sim.studies.labelled.study import peer_tables, truth_table
from sensornet.sim.studies.traffic.metrics import visits
from sensornet.sim.studies.traffic.study import (
    MIN_SCANS,
    add_window_arguments,
    run_part,
    scenario_of,
    window_scenario,
)
from sensornet.sim.traffic.recorded import tick_plots, truth_ids
from sensornet.sim.world import generate_run
from sensornet.sim.world.birth import radar_pd
from sensornet.tracking.track_metrics import TrackTable

STAGES = ("local", "second", "half", "after")
"""The parts of a visit's lag (module docstring)."""


def held(truth: TrackTable, est: TrackTable, c: float) -> np.ndarray:
    """``(N,)`` bool per row of ``truth``: a row of ``est`` at the same scan within ``c`` (all
    pairs of a scan at once, no loop over scans)."""
    order = np.argsort(est.scan, kind="stable")
    s, pos = est.scan[order], est.pos[order]
    lo, hi = np.searchsorted(s, truth.scan, "left"), np.searchsorted(s, truth.scan, "right")
    n = hi - lo
    row = np.repeat(np.arange(len(truth.scan)), n)
    start = np.concatenate(([0], np.cumsum(n)[:-1]))
    col = lo[row] + np.arange(n.sum()) - start[row]
    near = np.linalg.norm(truth.pos[row] - pos[col], axis=-1) < c
    return np.bincount(row, weights=near, minlength=len(truth.scan)) > 0


def first_held(truth: TrackTable, tables: dict[str, TrackTable], grid: np.ndarray, c: float
               ) -> dict[str, np.ndarray]:
    """Per visit: ``start`` (its first scan), ``scans`` (its length), ``aircraft`` (its
    aircraft id) and for each table the ticks from its start to the first it holds (its
    length if never); ``held`` per table ``(N,)`` over ``truth``'s rows, ``visit`` ``(N,)``."""
    by_visit, owner = visits(truth, grid)
    v = by_visit.id
    nv = len(owner)
    start = np.full(nv, np.iinfo(np.int64).max)
    np.minimum.at(start, v, truth.scan)
    scans = np.bincount(v, minlength=nv)
    out = {"start": start, "scans": scans, "aircraft": owner, "visit": v, "held": {}}
    for name, t in tables.items():
        h = held(truth, t, c)
        first = scans.astype(np.int64).copy()
        np.minimum.at(first, v[h], truth.scan[h] - start[v[h]])
        out[name] = first
        out["held"][name] = h
    return out


def lag_stages(ref: np.ndarray, fused: np.ndarray, local: np.ndarray) -> dict[str, np.ndarray]:
    """Per visit the fused lag behind the reference ``max(fused - ref, 0)`` and its parts
    :data:`STAGES` (they add up to it, each the ticks until the next peer count, cut at the
    lag): ``ref``, ``fused (v,)`` and ``local (v, P)`` first ticks held (:func:`first_held`);
    "second" waits for the second peer, "half" for the ``P // 2 + 1``-th."""
    lag = np.maximum(fused - ref, 0)
    srt = np.sort(local, axis=1)
    out, done, since = {"lag": lag}, np.zeros_like(lag), ref
    for name, j in zip(STAGES[:3], (0, min(1, local.shape[1] - 1), local.shape[1] // 2),
                       strict=True):
        part = np.minimum(lag - done, np.maximum(srt[:, j] - since, 0))
        out[name], done, since = part, done + part, np.maximum(since, srt[:, j])
    out["after"] = lag - done
    return out


def report(truth: TrackTable, fused: TrackTable, ref: TrackTable,
           local: dict[str, TrackTable], grid: np.ndarray, c: float, min_scans: int = 0
           ) -> str:
    """The lag table and the missing aircraft-ticks by peers holding (module docstring), for
    visits of at least ``min_scans`` ticks."""
    names = list(local)
    f = first_held(truth, {"ref": ref, "fused": fused, **local}, grid, c)
    keep = f["scans"] >= min_scans
    L = np.stack([f[n] for n in names], axis=1)
    st = lag_stages(f["ref"], f["fused"], L)
    lines = [f"{int(keep.sum())} visits >= {min_scans} ticks; fused later than the reference "
             f"in {int((st['lag'][keep] > 0).sum())}; lag ticks in all {int(st['lag'][keep].sum())}"
             f" (mean {st['lag'][keep].mean():.2f} a visit): "
             + ", ".join(f"{s} {int(st[s][keep].sum())}" for s in STAGES)]
    lag = st["lag"][keep]
    if (lag > 0).any():
        q = np.percentile(lag[lag > 0], [50, 90])
        lines.append(f"lagging visits: median {q[0]:.0f}, p90 {q[1]:.0f}, max {lag.max()} ticks; "
                     f"first local peer after the reference in "
                     f"{int((st['local'][keep] > 0).sum())} visits")
    rows = keep[f["visit"]]
    gap = f["held"]["ref"] & ~f["held"]["fused"] & rows
    n_loc = np.sum([f["held"][n] for n in names], axis=0)
    cnt = np.bincount(n_loc[gap], minlength=len(names) + 1)
    tot = np.bincount(n_loc[f["held"]["ref"] & rows], minlength=len(names) + 1)
    lines.append("aircraft-ticks the reference holds, fused not, by local peers holding: "
                 + ", ".join(f"{j}: {cnt[j]}/{tot[j]}" for j in range(len(names) + 1)))
    worst = np.argsort(-st["lag"] * keep, kind="stable")[:10]
    lines.append("largest lags (aircraft, start tick, lag, " + "/".join(STAGES)
                 + ", first ticks ref/fused/each peer):")
    for i in worst:
        if st["lag"][i] == 0:
            break
        lines.append(f"  {f['aircraft'][i]} {f['start'][i]} {st['lag'][i]} "
                     + "/".join(str(st[s][i]) for s in STAGES) + " "
                     f"{f['ref'][i]}/{f['fused'][i]}/" + ",".join(str(x) for x in L[i]))
    return "\n".join(lines)


def plots_so_far(truth: TrackTable, visit: np.ndarray,
                 plots: list[tuple[np.ndarray, np.ndarray]]) -> np.ndarray:
    """``(N, P)``: per row of ``truth`` and sensor, the plots of the row's aircraft that the
    sensor made in the row's visit (``visit (N,)``) up to and including its tick; ``plots[j]``
    is sensor ``j``'s ``(ticks (m,), aircraft ids (m,))`` (aircraft plots only)."""
    N, base = len(truth.scan), int(max(truth.scan.max(initial=0),
                                       *(t.max(initial=0) for t, _ in plots))) + 1
    order = np.lexsort((truth.scan, visit))
    vo = visit[order]
    first = np.flatnonzero(np.r_[True, vo[1:] != vo[:-1]])
    row_key = truth.id * base + truth.scan
    out = np.zeros((N, len(plots)), np.int64)
    for j, (ticks, ids) in enumerate(plots):  # one pass per sensor, vectorised over plots
        u, cnt = np.unique(np.asarray(ids, np.int64) * base + np.asarray(ticks, np.int64),
                           return_counts=True)
        pos = np.searchsorted(u, row_key).clip(max=max(len(u) - 1, 0))
        per = np.where(u[pos] == row_key, cnt[pos], 0) if len(u) else np.zeros(N, np.int64)
        cs = np.cumsum(per[order])
        out[order, j] = cs - np.repeat(cs[first] - per[order][first],
                                       np.diff(np.r_[first, N]))
    return out


def waiting(truth: TrackTable, fused: TrackTable, ref: TrackTable,
            local: dict[str, TrackTable], grid: np.ndarray, c: float,
            plots: list[tuple[np.ndarray, np.ndarray]], pd: np.ndarray, min_scans: int = 0
            ) -> str:
    """Why peers lack the aircraft in the ``half`` stage (module docstring): over the
    (aircraft-tick, peer) cells of that stage where the peer has no track on it, its ``pd (N,
    P)`` (its own sensor model at each row's aircraft) and :func:`plots_so_far`; and per peer
    the ticks from its first plot in a visit to its first track (``plots`` and ``pd`` in
    ``local``'s order)."""
    names = list(local)
    f = first_held(truth, {"ref": ref, "fused": fused, **local}, grid, c)
    v, keep = f["visit"], f["scans"] >= min_scans
    L = np.stack([f[n] for n in names], axis=1)
    st = lag_stages(f["ref"], f["fused"], L)
    off = truth.scan - f["start"][v]
    a = (f["ref"] + st["local"] + st["second"])[v]
    rows = keep[v] & (off >= a) & (off < a + st["half"][v])
    hold = np.stack([f["held"][n] for n in names], axis=1)
    R, J = np.nonzero(rows[:, None] & ~hold)
    n = plots_so_far(truth, v, plots)
    cn, p = n[R, J], pd[R, J]
    lost = L[v[R], J] < off[R]
    lines = [f"half stage: {int(rows.sum())} aircraft-ticks, {len(R)} (tick, peer) cells "
             f"without the peer's track"]
    if len(R):
        lines.append(f"  their own Pd at the aircraft: < 0.1 in {int((p < 0.1).sum())}, < 0.5 in "
                     f"{int((p < 0.5).sum())}, median {np.median(p):.2f}, min {p.min():.2f}; "
                     f"plots of it in the visit by then: 0 in {int((cn == 0).sum())}, 1 in "
                     f"{int((cn == 1).sum())}, 2 or more in {int((cn >= 2).sum())}; held "
                     f"earlier in the visit in {int(lost.sum())}")
        lines.append("  by peer (cells, median plots by then, median Pd): " + "; ".join(
            f"{nm} {int((J == j).sum())}, {np.median(cn[J == j]):.0f}, "
            f"{np.median(p[J == j]):.2f}" for j, nm in enumerate(names) if (J == j).any()))
    first_plot = np.full((len(f["start"]), len(names)), np.iinfo(np.int64).max)
    r, j = np.nonzero(n > 0)
    np.minimum.at(first_plot, (v[r], j), off[r])
    ok = keep[:, None] & (first_plot <= L) & (L < f["scans"][:, None])
    at = hold & (off[:, None] == L[v]) & keep[v][:, None]  # each peer's first-held row
    parts = []
    for j, nm in enumerate(names):
        lat = (L - first_plot)[ok[:, j], j]
        if len(lat):
            parts.append(f"{nm} {np.median(lat):.0f} ({np.median(n[at[:, j], j]):.0f})")
    lines.append("per peer, ticks from its first plot of a visit to its first track (plots by "
                 "then), medians: " + "; ".join(parts))
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m sensornet.sim.studies.traffic.starts",
                                 description=__doc__.split("\n\n")[0])
    add_window_arguments(ap)
    ap.add_argument("--peer", help="whose fused tracks (default: the first radar)")
    ap.add_argument("--run", type=int, default=0)
    a = ap.parse_args(argv)
    try:
        over, base = window_scenario(a)
    except (ScenarioError, ValueError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    scn = scenario_of(a.scenario, over, "lmb", "fused")
    peer = a.peer or scn.sensor_names[0]
    if peer not in scn.sensor_names:
        print(f"error: no peer {peer!r} (have {', '.join(scn.sensor_names)})", file=sys.stderr)
        return 2
    truth, _ = generate_run(scn, a.run)
    twin = run_twin(scn, a.run)
    local = peer_tables(twin, scn.sensor_names, "local", {})
    fused = peer_tables(twin, [peer], "fused", {})[peer]
    ref = run_part(a.scenario, over, "lmb", "centralised", a.run, with_hota=False,
                   keep_tables=True).tables["central"]
    T, grid = truth_table(truth), np.arange(1, scn.num_scans + 1)
    print(report(T, fused, ref, local, grid, scn.metrics.ospa_cutoff, MIN_SCANS))
    plots = [(p.tick[p.truth != ""], truth_ids(p.truth[p.truth != ""]))
             for p in tick_plots(scn, a.run)]
    sites = np.array([s.position[:2] for s in scn.sensors], float)
    r = np.linalg.norm(T.pos[:, None, :] - sites[None], axis=-1)
    pd = np.stack([radar_pd(s)(r[:, j]) for j, s in enumerate(scn.sensors)], axis=1)
    print(waiting(T, fused, ref, local, grid, scn.metrics.ospa_cutoff, plots, pd, MIN_SCANS))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
