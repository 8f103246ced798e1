"""Where the fused LMB tracks still lose to the centralised reference, target by target
(issue 33, docs/labelled-tracking.md "Young fused tracks and the peer's own scan").

One twin run per cell with every peer's fused extraction recorded (its inputs and output,
``peers.consensus.Consensus._tracks``), then:

* the OSPA(2) parts of :mod:`sim.studies.labelled.ospa2_floor`, fused minus centralised, split
  per true target (:func:`parts_by_truth`: an assigned pair's terms to its target, a ``dup``
  track to the target it was nearest in most of its window's scans, a ``missed`` term to its
  target; ``false`` to none), by the phase of the target's life the window covers (``birth``:
  the window holds its first scan; ``death``: its last, and the scan after; else ``middle``)
  and by the peer's hops from the target's first detectors (the peers whose local tracks came
  within ``c/4`` of it first);
* every fused id change at a target (a peer's track within ``c/4`` of it changing label from
  one scan to the next), by kind: to an earlier shared stamp, a same-scan shared stamp (another
  200 m birth cell: the cell tie), a later one, or one involving own labels;
* every extracted row more than ``c/4`` from every live target, young (label at most 2 scans
  old) or mature;
* with ``--variant``, each peer's recorded calls replayed through a fresh peer of the variant
  scenario (extraction feeds nothing back, so the replay of the base equals the twin; the own
  scan of ``fusion.existence_own`` comes from the run's plots).

``python -m sensornet.sim.studies.labelled.gap_trace --runs 100,101 --graphs circ20 --pds 0.9
[--variant "own=fusion.existence_own=1"]`` (training runs only: choices are made there).
"""

from __future__ import annotations

import time
from collections import Counter, defaultdict
from contextlib import contextmanager
from types import SimpleNamespace

import numpy as np
from scipy.optimize import linear_sum_assignment
from sensornet.peers.consensus import Consensus
from sensornet.sim.run.peers import make_peer
from sensornet.sim.run.twin import run_twin
from sensornet.sim.studies.labelled.centralised import central_lmb, run_central
from sensornet.sim.studies.labelled.ospa2_floor import (
    GRAPHS,
    PARTS,
    _overrides,
    cell_arguments,
    ospa2_parts,
)
from sensornet.sim.studies.labelled.pool_check import parse_variant
from sensornet.sim.studies.labelled.study import (
    RULES,
    WINDOW,
    central_table,
    peer_tables,
    scenario_of,
    truth_table,
)
from sensornet.sim.world import generate_run
from sensornet.sim.world.build import adjacency
from sensornet.tracking.label_keys import SHARED_ORIGIN
from sensornet.tracking.track_metrics import TrackTable

C, P = 200.0, 2.0
NEAR = C / 4
YOUNG = 2


@contextmanager
def recording(calls: dict[str, list[dict]]):
    """Record every peer's fused extraction (``Consensus._tracks``) into ``calls`` by peer."""
    original = Consensus._tracks

    def tracks(self, k, fused, now, labels=None, inputs=None, copies=None, masses=None):
        mixes = self._input_mixtures(inputs)
        out = original(self, k, fused, now, labels, inputs, copies, masses)
        if labels is not None:
            t = out[0]
            calls.setdefault(self.o.name, []).append(dict(
                k=k, fused=fused, labels=labels.copy(), mixes=mixes,
                copies=None if copies is None else np.asarray(copies).copy(),
                ids=np.asarray(t.ids).copy(), states=np.asarray(t.states).copy()))
        return out

    Consensus._tracks = tracks
    try:
        yield calls
    finally:
        Consensus._tracks = original


def record(scn, run: int) -> dict:
    """One twin run of ``scn`` with its fused extractions recorded, the truth, the fused and
    local tables, the centralised LMB's table and the run's plots."""
    truth, meas = generate_run(scn, run)
    with recording({}) as calls:
        twin = run_twin(scn, run, data=(truth, meas))
    tracks, _ = run_central(central_lmb(scn), meas)
    return dict(calls=calls, meas=meas, T=truth_table(truth), names=scn.sensor_names,
                fused=peer_tables(twin, scn.sensor_names, "fused", {}),
                local=peer_tables(twin, scn.sensor_names, "local", {}),
                central=central_table(tracks), adjacency=adjacency(scn)[1])


def replay(rec: dict, scn) -> dict[str, TrackTable]:
    """Each peer's recorded extraction calls through a fresh peer of ``scn`` (a variant of
    the recorded run's scenario): its fused tables."""
    code: dict = {}
    out = {}
    for i, name in enumerate(rec["names"]):
        c = make_peer(scn, name, 0).consensus
        c._input_mixtures = lambda mixes: mixes
        S, Id, X = [], [], []
        for r in rec["calls"].get(name, []):
            c._scan = SimpleNamespace(k=r["k"], z=np.asarray(rec["meas"][i][r["k"] - 1]))
            t = c._tracks(r["k"], r["fused"], 0.0, r["labels"], r["mixes"], r["copies"])[0]
            _, first = np.unique(t.ids, axis=0, return_index=True)
            for j in np.sort(first):
                S.append(r["k"])
                Id.append(code.setdefault(tuple(int(v) for v in t.ids[j]), len(code)))
                X.append(t.states[j][[0, 2]])
        out[name] = TrackTable(np.array(S, dtype=np.int64), np.array(Id, dtype=np.int64),
                               np.array(X, dtype=float).reshape(-1, 2))
    return out


def parts_by_truth(E: np.ndarray, Y: np.ndarray, c: float = C, p: float = P,
                   window: int = WINDOW, near: float = NEAR
                   ) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """:func:`sim.studies.labelled.ospa2_floor.ospa2_parts_dense`'s parts per window ending at
    each scan and per truth (``(T, m)`` each; module docstring), and ``false`` ``(T,)``; summed
    over truths and with ``false`` they are that function's parts."""
    T, m = E.shape[0], Y.shape[1]
    ex, ty = ~np.isnan(E).any(-1), ~np.isnan(Y).any(-1)
    D = np.linalg.norm(E[:, :, None, :] - Y[:, None, :, :], axis=-1)
    Dn = np.where(np.isnan(D), np.inf, D)
    both, either = ex[:, :, None] & ty[:, None, :], ex[:, :, None] | ty[:, None, :]
    first = np.where(ex.any(0), ex.argmax(0), T)
    only_t = ty[:, None, :] & ~ex[:, :, None]
    late = only_t & (np.arange(T)[:, None] < first[None, :])[:, :, None]
    close = (Dn.min(axis=2, initial=np.inf) < near) & ex
    nearest = Dn.argmin(axis=2) if m else np.zeros(ex.shape, dtype=np.int64)

    def cum(a: np.ndarray) -> np.ndarray:
        return np.concatenate([np.zeros((1, *a.shape[1:])), np.cumsum(a, axis=0, dtype=float)])

    cL, cLa = cum(np.where(both, np.minimum(Dn, c), 0.0)), cum(late)
    cG, cX = cum(only_t & ~late), cum(ex[:, :, None] & ~ty[:, None, :])
    cU, cx, cy, cn = cum(either), cum(ex), cum(ty), cum(close)
    near_of = cum(ex[:, :, None] & (nearest[:, :, None] == np.arange(m)))  # (T+1, n, m)
    out = {k: np.zeros((T, m)) for k in PARTS}
    false = np.zeros(T)
    for e in range(1, T + 1):
        s = max(e - window, 0)
        xi, yj = np.nonzero(cx[e] - cx[s])[0], np.nonzero(cy[e] - cy[s])[0]
        n, mm = len(xi), len(yj)
        terms = {k: np.zeros(m) for k in PARTS}
        f = 0.0
        if n and mm:
            sub = np.ix_(xi, yj)
            U, L = cU[e][sub] - cU[s][sub], cL[e][sub] - cL[s][sub]
            La, G, X = (a[e][sub] - a[s][sub] for a in (cLa, cG, cX))
            base = (L + c * (La + G + X)) / U
            r, q = linear_sum_assignment(base**p)
            w = base[r, q] ** (p - 1) / U[r, q]
            for key, A in (("loc", L), ("late", c * La), ("gap", c * G), ("extra", c * X)):
                np.add.at(terms[key], yj[q], w * A[r, q])
            free = xi[np.setdiff1d(np.arange(n), r)]
            dup = (cn[e][free] - cn[s][free]) >= 0.5 * (cx[e][free] - cx[s][free])
            np.add.at(terms["dup"], (near_of[e][free[dup]] - near_of[s][free[dup]]).argmax(1),
                      c**p)
            f = c**p * float((~dup).sum())
            terms["missed"][yj[np.setdiff1d(np.arange(mm), q)]] = c**p
        elif n:
            f = c**p * n
        else:
            terms["missed"][yj] = c**p
        total = sum(v.sum() for v in terms.values()) + f
        if total > 0:
            d = (total / max(n, mm)) ** (1.0 / p)
            for key in PARTS:
                out[key][e - 1] = d * terms[key] / total
            false[e - 1] = d * f / total
    return out, false


def hops(adj: np.ndarray) -> np.ndarray:
    """``(n, n)`` hop counts of the graph ``adj`` (breadth-first, by matrix powers)."""
    n = len(adj)
    H = np.where(np.eye(n, dtype=bool), 0, -1)
    reach, step = np.eye(n, dtype=bool), 0
    while (H < 0).any() and step < n:
        step += 1
        reach = (reach.astype(int) @ (adj > 0).astype(int) > 0) | reach
        H[(H < 0) & reach] = step
    return H


def first_near(tab: TrackTable, Y: np.ndarray, grid: np.ndarray) -> np.ndarray:
    """``(m,)`` the first grid index a track of ``tab`` is within :data:`NEAR` of each truth
    (``len(grid)`` if never)."""
    E = tab.dense(grid)[1]
    D = np.linalg.norm(E[:, :, None] - Y[:, None], axis=-1)
    hit = (np.nan_to_num(D, nan=np.inf) < NEAR).any(axis=1)  # (T, m)
    return np.where(hit.any(0), hit.argmax(0), len(grid))


def gap_by(rec: dict) -> dict[tuple[str, str, int], float]:
    """Fused minus centralised OSPA(2), mean over peers, by ``(part, phase, hops)`` (``false``:
    phase ``"-"``, hops -1), and ``("pairs", "-", h)``: the share of (peer, target) pairs h
    hops from the target's first detectors."""
    grid = np.unique(rec["T"].scan)
    Y = rec["T"].dense(grid)[1]
    alive = ~np.isnan(Y).any(-1)
    born, last = alive.argmax(0), len(grid) - 1 - alive[::-1].argmax(0)
    seen = np.array([first_near(rec["local"][p], Y, grid) for p in rec["names"]])
    H = hops(rec["adjacency"])
    first = seen == seen.min(axis=0)  # (peers, m): the first detectors
    hop = np.where(first[None, :, :], H[:, :, None], len(H)).min(axis=1)  # (peers, m)
    e = np.arange(len(grid))[:, None]
    phase = np.where((born <= e) & (born > e - WINDOW), "birth",
                     np.where((last < e) & (last >= e - WINDOW), "death", "middle"))
    cen, cf = parts_by_truth(rec["central"].dense(grid)[1], Y)
    out: dict = defaultdict(float)
    n, T = len(rec["names"]), len(grid)
    for i, p in enumerate(rec["names"]):
        fu, ff = parts_by_truth(rec["fused"][p].dense(grid)[1], Y)
        for key in PARTS:
            d = (fu[key] - cen[key]) / (n * T)
            for ph in ("birth", "middle", "death"):
                for h in np.unique(hop[i]):
                    out[(key, ph, int(h))] += float(d[(phase == ph) & (hop[i] == h)].sum())
        out[("false", "-", -1)] += float((ff - cf).sum()) / (n * T)
    for h in np.unique(hop):
        out[("pairs", "-", int(h))] = float((hop == h).mean())
    return out


def change_kind(old: tuple, new: tuple) -> str:
    """What a fused id change at a target is (module docstring)."""
    if old[0] != SHARED_ORIGIN or new[0] != SHARED_ORIGIN:
        return "own"
    return "earlier" if new[1] < old[1] else "later" if new[1] > old[1] else "same-scan"


def events(rec: dict) -> tuple[list[tuple], list[tuple]]:
    """Id changes ``(peer, scan, target, old, new, kind, scans since birth)`` and far rows
    ``(peer, scan, label, age)``, from the recorded extractions."""
    grid = np.unique(rec["T"].scan)
    Y = rec["T"].dense(grid)[1]
    alive = ~np.isnan(Y).any(-1)
    born = grid[alive.argmax(0)]
    changes, far = [], []
    for p in rec["names"]:
        held: dict[int, tuple] = {}
        for r in rec["calls"].get(p, []):
            k = r["k"]
            if not len(r["ids"]):
                continue
            y = Y[np.searchsorted(grid, k)] if k in grid else np.full((Y.shape[1], 2), np.nan)
            D = np.nan_to_num(np.linalg.norm(r["states"][:, None, [0, 2]] - y[None], axis=-1),
                              nan=np.inf)
            j = D.argmin(axis=1) if D.shape[1] else np.zeros(len(D), dtype=np.int64)
            ok = D.min(axis=1, initial=np.inf) < NEAR
            for row in np.flatnonzero(~ok):
                lab = tuple(int(v) for v in r["ids"][row])
                far.append((p, k, lab, k - lab[1]))
            for row in np.flatnonzero(ok):
                lab, t = tuple(int(v) for v in r["ids"][row]), int(j[row])
                if t in held and held[t][1] == k - 1 and held[t][0] != lab:
                    changes.append((p, k, t, held[t][0], lab, change_kind(held[t][0], lab),
                                    k - int(born[t])))
                held[t] = (lab, k)
    return changes, far


def _fmt(d: dict) -> str:
    return " ".join(f"{k} {v:+.2f}" for k, v in d.items() if abs(v) >= 0.005)


def main(argv: list[str] | None = None) -> int:
    ap = cell_arguments("gap_trace", __doc__, "scenario override of the recorded run",
                        kinds="lmb")
    ap.add_argument("--variant", action="append", default=[], metavar="NAME=KEY=VALUE;...",
                    help="replay every recorded extraction through this variant")
    a = ap.parse_args(argv)
    runs = [int(x) for x in a.runs.split(",")]
    t0 = time.perf_counter()
    for g in a.graphs.split(","):
        for pd in (float(x) for x in a.pds.split(",")):
            over = {**RULES[a.rule], **_overrides(a.set or [])}
            scn = scenario_of(GRAPHS[g], "lmb", pd, 10.0, a.scans, over)
            gaps: dict = defaultdict(float)
            kinds: Counter = Counter()
            by_hop: dict = defaultdict(Counter)
            since: Counter = Counter()
            far = Counter()
            for run in runs:
                rec = record(scn, run)
                grid = np.unique(rec["T"].scan)
                row = {"twin": np.mean([ospa2_parts(rec["T"], t, C, P, WINDOW, grid)["total"]
                                        for t in rec["fused"].values()]),
                       "central": ospa2_parts(rec["T"], rec["central"], C, P, WINDOW,
                                              grid)["total"]}
                for name, v in map(parse_variant, a.variant):
                    tabs = replay(rec, scenario_of(GRAPHS[g], "lmb", pd, 10.0, a.scans,
                                                   {**over, **v}))
                    row[name] = np.mean([ospa2_parts(rec["T"], t, C, P, WINDOW, grid)["total"]
                                         for t in tabs.values()])
                print(f"{g} Pd {pd} run {run}: " + ", ".join(f"{k} {v:.2f}"
                                                              for k, v in row.items()),
                      flush=True)
                for key, v in gap_by(rec).items():
                    gaps[key] += v / len(runs)
                changes, rows = events(rec)
                peers = {p: i for i, p in enumerate(rec["names"])}
                seen = np.array([first_near(rec["local"][p], rec["T"].dense(grid)[1], grid)
                                 for p in rec["names"]])
                H = hops(rec["adjacency"])
                for p, _, t, _, _, kind, age in changes:
                    kinds[kind] += 1
                    since[age] += 1
                    first = np.flatnonzero(seen[:, t] == seen[:, t].min())
                    by_hop[int(H[peers[p], first].min())][kind] += 1
                far.update("young" if age <= YOUNG else "mature" for *_, age in rows)
            parts = defaultdict(float)
            phases, hop_rows = defaultdict(dict), defaultdict(dict)
            for (key, ph, h), v in gaps.items():
                if key == "pairs":
                    hop_rows[h]["share of pairs"] = v
                    continue
                parts[key] += v
                phases[ph][key] = phases[ph].get(key, 0.0) + v
                hop_rows[h][key] = hop_rows[h].get(key, 0.0) + v
            print(f"\n{g} Pd {pd} runs {a.runs}: fused - centralised OSPA(2) by part, m: "
                  f"{_fmt(parts)} (sum {sum(parts.values()):+.2f})")
            for ph in ("birth", "middle", "death", "-"):
                print(f"  phase {ph}: {_fmt(phases[ph])}")
            for h in sorted(hop_rows):
                print(f"  hops {h}: {_fmt(hop_rows[h])}")
            print(f"  id changes at a target: {dict(kinds)}; by hops "
                  f"{ {h: dict(c) for h, c in sorted(by_hop.items())} }; scans since birth "
                  f"{dict(sorted(since.items()))}")
            print(f"  extracted rows {NEAR:.0f} m or more from every live target: {dict(far)}")
    print(f"\n{time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
