"""Where fused OSPA(2) loses to the centralised reference (issue 33, docs/labelled-tracking.md,
"Fused vs centralised: where the gap is").

OSPA(2) (:func:`tracking.track_metrics.ospa2_dense`, cut-off ``c``, order ``p``, window ``w``)
per window: ``d^p = (sum over assigned pairs of b_ij^p + c^p |n - m|) / max(n, m)``, with the
base distance of estimate ``i`` and truth ``j`` ``b_ij = (L_ij + c (M_ij + X_ij)) / U_ij``
over the ``U_ij`` scans of the window where either exists: ``L_ij`` the sum of
``min(c, |x - y|)`` where both exist, ``M_ij`` the scans where only the truth exists, ``X_ij``
where only the estimate does. The parts (:data:`PARTS`), each window's ``d`` split in
proportion to its terms of ``d^p`` (an assigned pair's ``b^p`` as ``b^(p-1) L / U``,
``b^(p-1) c M / U`` ...), so they add up to ``d`` and, averaged over windows, to the study's
OSPA(2) (the mean over the windows ending at each scan):

* ``loc``: localisation (both exist);
* ``late``: the truth present before its assigned track's first scan in the run (latency of
  birth or confirmation);
* ``gap``: the truth present, its assigned track absent otherwise (a miss, or the track that
  covers it there has another id: a switch);
* ``extra``: the assigned track present, its truth absent (it outlives the target, or started
  on another one);
* ``dup``: an unassigned track (``n > m``) near a truth (within ``near`` of one in half its
  scans of the window or more): a second track of a target, the other side of a switch;
* ``false``: an unassigned track not near a truth (clutter);
* ``missed``: an unassigned truth (``m > n``).

``python -m sensornet.sim.studies.labelled.ospa2_floor [--runs 100,101] [--scans 100]
[--graphs full3,circ20] [--kinds gmphd,lmb] [--pds 0.99,0.9] [--rule hybrid]``: per cell the
parts of local, fused (all and confirmed tracks) and centralised (all and confirmed), mean over
peers and runs.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from scipy.optimize import linear_sum_assignment
from sensornet.sim.run.twin import run_twin
from sensornet.sim.studies.labelled.centralised import central_gmphd, central_lmb, run_central
from sensornet.sim.studies.labelled.study import (
    RULES,
    WINDOW,
    Graph,
    central_table,
    peer_tables,
    scenario_of,
    truth_table,
)
from sensornet.sim.world import generate_run
from sensornet.tracking.track_metrics import TrackTable

PARTS = ("loc", "late", "gap", "extra", "dup", "false", "missed")
GRAPHS = {"full3": Graph("full-3 (seed 000)", "seed000", 1),
          "circ20": Graph("circ4-20", "circulant:20:4", 1)}


def ospa2_parts_dense(E: np.ndarray, Y: np.ndarray, c: float = 200.0, p: float = 2.0,
                      window: int | None = None, near: float | None = None
                      ) -> dict[str, np.ndarray]:
    """The parts (:data:`PARTS`) of OSPA(2) between ``E (T, n, d)`` and ``Y (T, m, d)`` (NaN
    where absent), per window ending at each scan ``(T,)`` (``window=None``: one window,
    ``(1,)``), plus ``"total"``: their sum, :func:`tracking.track_metrics.ospa2_dense`'s value.
    ``near`` (default ``c / 4``) separates ``dup`` from ``false``."""
    near = c / 4 if near is None else near
    T = E.shape[0]
    ex, ty = ~np.isnan(E).any(-1), ~np.isnan(Y).any(-1)  # (T, n), (T, m)
    D = np.linalg.norm(E[:, :, None, :] - Y[:, None, :, :], axis=-1)  # (T, n, m)
    both = ex[:, :, None] & ty[:, None, :]
    either = ex[:, :, None] | ty[:, None, :]
    first = np.where(ex.any(0), ex.argmax(0), T)  # (n,) an estimate's first scan
    before = np.arange(T)[:, None] < first[None, :]  # (T, n)
    only_t = ty[:, None, :] & ~ex[:, :, None]
    late = only_t & before[:, :, None]
    Dn = np.where(np.isnan(D), np.inf, D)
    close = (Dn.min(axis=2, initial=np.inf) < near) & ex  # (T, n) near some truth

    def cum(a: np.ndarray) -> np.ndarray:
        a = np.asarray(a, float)
        return np.concatenate([np.zeros((1, *a.shape[1:])), np.cumsum(a, axis=0)])

    cL = cum(np.where(both, np.minimum(Dn, c), 0.0))
    cLate, cGap, cX = cum(late), cum(only_t & ~late), cum(ex[:, :, None] & ~ty[:, None, :])
    cU, cx, cy, cnear = cum(either), cum(ex), cum(ty), cum(close)
    ends = np.arange(1, T + 1) if window else np.array([T])
    starts = np.maximum(ends - window, 0) if window else np.array([0])
    out = {k: np.zeros(len(ends)) for k in (*PARTS, "total")}
    for k, (s, e) in enumerate(zip(starts, ends, strict=True)):
        xi, yj = np.nonzero(cx[e] - cx[s])[0], np.nonzero(cy[e] - cy[s])[0]
        n, m = len(xi), len(yj)
        terms = dict.fromkeys(PARTS, 0.0)
        if n and m:
            sub = np.ix_(xi, yj)
            U = cU[e][sub] - cU[s][sub]
            L, La = cL[e][sub] - cL[s][sub], cLate[e][sub] - cLate[s][sub]
            G, X = cGap[e][sub] - cGap[s][sub], cX[e][sub] - cX[s][sub]
            base = (L + c * (La + G + X)) / U
            r, q = linear_sum_assignment(base**p)
            w = base[r, q] ** (p - 1) / U[r, q]
            terms.update(loc=float((w * L[r, q]).sum()), late=float((w * c * La[r, q]).sum()),
                         gap=float((w * c * G[r, q]).sum()), extra=float((w * c * X[r, q]).sum()))
            if n > m:
                free = np.setdiff1d(np.arange(n), r)
                seen = cx[e][xi[free]] - cx[s][xi[free]]
                dup = (cnear[e][xi[free]] - cnear[s][xi[free]]) >= 0.5 * seen
                terms["dup"] = c**p * float(dup.sum())
                terms["false"] = c**p * float((~dup).sum())
            terms["missed"] = c**p * max(m - n, 0)
        else:
            terms["false" if n else "missed"] = c**p * max(n, m)
        S = sum(terms.values())
        if S > 0:
            d = (S / max(n, m)) ** (1.0 / p)
            for key, v in terms.items():
                out[key][k] = d * v / S
            out["total"][k] = d
    return out


def ospa2_parts(truth: TrackTable, est: TrackTable, c: float = 200.0, p: float = 2.0,
                window: int | None = WINDOW, scans: np.ndarray | None = None,
                near: float | None = None) -> dict[str, float]:
    """:func:`ospa2_parts_dense` on tables, each part's mean over the windows (``total``: the
    study's OSPA(2), :func:`tracking.track_metrics.track_report`'s ``ospa2_mean``)."""
    grid = (np.unique(np.concatenate([truth.scan, est.scan])) if scans is None
            else np.unique(np.asarray(scans, dtype=np.int64)))
    parts = ospa2_parts_dense(est.dense(grid)[1], truth.dense(grid)[1], c, p, window, near)
    return {k: float(v.mean()) if len(v) else 0.0 for k, v in parts.items()}


def stitch(table: TrackTable, gate: float) -> TrackTable:
    """An oracle for ids that agree from a track's first scan: a track whose first scan ``k``
    is within ``gate`` of a track whose last scan was ``k - 1`` continues it (its id becomes
    the earlier one's; pairs by least distance, SciPy ``linear_sum_assignment``), as when a
    peer's track takes the network's id. Not causal: a floor for id schemes, not a peer."""
    ids, P = table.dense(np.unique(table.scan)) if len(table.scan) else (np.zeros(0), None)
    if P is None:
        return table
    grid = np.unique(table.scan)
    on = ~np.isnan(P).any(-1)  # (T, n)
    first, last = on.argmax(0), len(grid) - 1 - on[::-1].argmax(0)
    root = np.arange(len(ids))
    for k in range(1, len(grid)):
        if grid[k] != grid[k - 1] + 1:
            continue
        a, b = np.flatnonzero(last == k - 1), np.flatnonzero(first == k)
        if not len(a) or not len(b):
            continue
        Dm = np.linalg.norm(P[k - 1, a][:, None] - P[k, b][None], axis=-1)
        r, q = linear_sum_assignment(np.where(Dm <= gate, Dm, 1e12))
        for i, j in zip(r, q, strict=True):
            if Dm[i, j] <= gate:
                root[b[j]] = root[a[i]]
    col = np.searchsorted(ids, table.id)
    return TrackTable(table.scan, ids[root[col]], table.pos)


def shown(table: TrackTable, scans: int) -> TrackTable:
    """A causal display rule: a track's rows from its ``scans``-th scan present on (counted
    over the run, gaps allowed); the first ``scans - 1`` are dropped."""
    order = np.lexsort((table.scan, table.id))
    ids = table.id[order]
    start = np.r_[0, np.flatnonzero(np.diff(ids)) + 1]
    nth = np.arange(len(ids)) - np.repeat(start, np.diff(np.r_[start, len(ids)]))
    keep = order[nth >= scans - 1]
    return TrackTable(table.scan[keep], table.id[keep], table.pos[keep])


def _mean(rows: list[dict[str, float]]) -> dict[str, float]:
    return {k: float(np.mean([r[k] for r in rows])) for k in rows[0]}


def cell(graph: Graph, kind: str, pd: float, run: int, scans: int | None, rule: str = "hybrid",
         clutter: float = 10.0, extra: dict | None = None, extra_all: dict | None = None,
         with_local: bool = True, with_central: bool = True) -> dict[str, dict[str, float]]:
    """One (graph, kind, Pd, run): the parts (mean over peers) of ``local``, ``fused``,
    ``fused_confirmed``, ``fused_stitched`` (:func:`stitch`, gate ``c / 4``), ``fused_shown2``
    (:func:`shown`, 2 scans), ``central``, ``central_confirmed``, ``central_shown2``.
    ``extra``: overrides of the fused twin's scenario (a design variant);
    ``extra_all``: of every estimate's (the centralised reference's too)."""
    out = {}
    scn = scenario_of(graph, kind, pd, clutter, scans, extra_all)
    c, p = scn.metrics.ospa_cutoff, scn.metrics.ospa_order
    grid = np.arange(1, scn.num_scans + 1)
    truth, meas = generate_run(scn, run)
    T = truth_table(truth)

    def parts(tabs: dict[str, TrackTable]) -> dict[str, float]:
        return _mean([ospa2_parts(T, t, c, p, WINDOW, grid) for t in tabs.values()])

    variants = [("fused", {**RULES[rule], **(extra_all or {}), **(extra or {})})]
    if with_local:
        variants.append(("local", {"fusion.rule": "none", **(extra_all or {})}))
    for which, over in variants:
        s = scenario_of(graph, kind, pd, clutter, scans, over)
        twin = run_twin(s, run)
        code: dict = {}
        tabs = peer_tables(twin, s.sensor_names, which, code)
        out[which] = parts(tabs)
        if which == "fused":
            out["fused_confirmed"] = parts(peer_tables(twin, s.sensor_names, which, code, True))
            out["fused_stitched"] = parts({p: stitch(t, c / 4) for p, t in tabs.items()})
            out["fused_shown2"] = parts({p: shown(t, 2) for p, t in tabs.items()})
    if with_central:
        tracks, _ = run_central(central_lmb(scn) if kind == "lmb" else central_gmphd(scn), meas)
        out["central"] = parts({"c": central_table(tracks)})
        out["central_confirmed"] = parts({"c": central_table(tracks, True)})
        out["central_shown2"] = parts({"c": shown(central_table(tracks), 2)})
    return out


def format_rows(rows: list[tuple[str, str, float, str, dict[str, float]]]) -> str:
    """A markdown table: graph, kind, Pd, estimate, OSPA(2) and its parts."""
    lines = ["| graph | kind | Pd | estimate | OSPA(2) | " + " | ".join(PARTS) + " |",
             "|---|---|---:|---|---:|" + "---:|" * len(PARTS)]
    for g, kind, pd, est, r in rows:
        lines.append(f"| {g} | {kind} | {pd} | {est} | {r['total']:.1f} | "
                     + " | ".join(f"{r[k]:.1f}" for k in PARTS) + " |")
    return "\n".join(lines) + "\n"


def _overrides(items: list[str]) -> dict:
    out: dict = {}
    for kv in items:
        k, v = kv.split("=", 1)
        if v.lower() in ("true", "false"):  # a flag
            out[k] = v.lower() == "true"
            continue
        try:
            out[k] = float(v) if "." in v else int(v)
        except ValueError:
            out[k] = v
    return out


def cell_arguments(prog: str, doc: str, set_help: str | None,
                   kinds: str = "gmphd,lmb") -> argparse.ArgumentParser:
    """The options of a study over the labelled cells (runs, scans, graphs, kinds, Pd, rule,
    and with ``set_help`` the fused twin's overrides), shared by this study, ``design_check``
    and ``pool_check``."""
    ap = argparse.ArgumentParser(prog=f"python -m sensornet.sim.studies.labelled.{prog}",
                                 description=doc.split("\n\n")[0])
    ap.add_argument("--runs", default="100,101", help="runs (training: 100, 101)")
    ap.add_argument("--scans", type=int, help="scans per run (default: the scenario's)")
    ap.add_argument("--graphs", default="full3,circ20")
    ap.add_argument("--kinds", default=kinds)
    ap.add_argument("--pds", default="0.99,0.9")
    ap.add_argument("--rule", default="hybrid", choices=sorted(RULES))
    if set_help is not None:
        ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                        help=set_help)
    return ap


def main(argv: list[str] | None = None) -> int:
    ap = cell_arguments("ospa2_floor", __doc__,
                        "override of the fused twin's scenario (a design variant)")
    ap.add_argument("--set-all", action="append", default=[], metavar="KEY=VALUE",
                    help="override of every estimate's scenario (local, fused, centralised)")
    a = ap.parse_args(argv)
    extra, extra_all = _overrides(a.set), _overrides(a.set_all)
    runs = [int(x) for x in a.runs.split(",")]
    rows = []
    t0 = time.perf_counter()
    for g in a.graphs.split(","):
        for kind in a.kinds.split(","):
            for pd in (float(x) for x in a.pds.split(",")):
                per = [cell(GRAPHS[g], kind, pd, r, a.scans, a.rule, extra=extra,
                            extra_all=extra_all)
                       for r in runs]
                for est in per[0]:
                    rows.append((g, kind, pd, est, _mean([x[est] for x in per])))
                print(format_rows(rows[-len(per[0]):]), flush=True)
    print(format_rows(rows) + f"\nruns {a.runs}, {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
