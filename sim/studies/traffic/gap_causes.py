"""What the fused LMB's excess over the asynchronous centralised reference is made of (issue
34, docs/real-traffic.md "The remaining gap taken apart").

Runs the fused twin (its peers give both their own, local, tracks and the fused ones) and the
reference (:mod:`.asynchronous`) on one window, keeps the tables (``--save`` / ``--load``, an
``.npz``) and splits each table's mean OSPA(2)^p exactly (:mod:`.ospa2_parts`' assignment per
window, Beard, Vo & Vo 2020 Sec. VI) per aircraft visit into :data:`CAUSES`: localisation, a
late start (the aircraft present, no track on it yet), a drop (no track on it after one was),
identity (another track holds it, or its track is elsewhere), a track lingering without its
aircraft, a second track on an aircraft, a false track. The fused minus reference parts say
which of them the 1.2 x target waits for; the visits are also split by where they start and
ranked, with each radar's own first track.

``python -m sensornet.sim.studies.traffic.gap_causes [SCENARIO] --file F --start S --minutes M
[--set KEY=VALUE ...] [--save F.npz | --load F.npz] [--fused fused:PEER]``
"""

from __future__ import annotations

import argparse
import sys

import numpy as np
from scipy.optimize import linear_sum_assignment
from sensornet.sim.run.twin import run_twin
from sensornet.sim.scenario import ScenarioError
from sensornet.sim.studies.labelled.study import peer_tables, truth_table
from sensornet.sim.studies.traffic.metrics import visits
from sensornet.sim.studies.traffic.study import (
    WINDOW,
    add_window_arguments,
    run_part,
    scenario_of,
    window_scenario,
)
from sensornet.sim.world import generate_run
from sensornet.tracking.track_metrics import TrackTable

CAUSES = ("loc", "late", "drop", "ident", "linger", "dup", "false")
"""The causes mean OSPA(2)^p is split into (module docstring)."""


def collect(a: argparse.Namespace) -> dict[str, TrackTable]:
    """``truth``, ``ref`` (the asynchronous centralised LMB), ``fused:PEER`` and
    ``local:PEER`` (the fused twin's own filters) for the window of ``a``."""
    over, _ = window_scenario(a)
    scn = scenario_of(a.scenario, over, "lmb", "fused")
    truth, _ = generate_run(scn, a.run)
    twin = run_twin(scn, a.run, workers=a.twin_workers)
    out = {"truth": truth_table(truth)}
    code: dict = {}
    for which in ("fused", "local"):
        for p, t in peer_tables(twin, scn.sensor_names, which, code).items():
            out[f"{which}:{p}"] = t
    out["ref"] = run_part(a.scenario, over, "lmb", "centralised", a.run, with_hota=False,
                          keep_tables=True).tables["central"]
    return out


def _dense(t: TrackTable, grid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(ids (n,), P (T, n, 2))`` of ``t`` on ``grid``, NaN where absent."""
    return t.dense(grid)


def truth_rows(Y: np.ndarray, E: np.ndarray, c: float) -> np.ndarray:
    """``(T, m)`` class of each truth cell: -1 absent, 0 held (a track of ``E`` within ``c``),
    1 not held before the first held scan of that truth (a late start), 2 not held after it
    (a drop, or the end of a visit)."""
    ty = ~np.isnan(Y).any(-1)
    d = np.linalg.norm(E[:, :, None, :] - Y[:, None, :, :], axis=-1)
    held = (np.nan_to_num(d, nan=np.inf) < c).any(axis=1) & ty
    T = len(Y)
    first = np.where(held.any(0), held.argmax(0), T)
    cls = np.where(held, 0, np.where(np.arange(T)[:, None] < first[None, :], 1, 2))
    return np.where(ty, cls, -1)


def attribute(E: np.ndarray, Y: np.ndarray, cls: np.ndarray, c: float, p: float,
              window: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """OSPA(2)^p of every window (:mod:`.ospa2_parts`) split by :data:`CAUSES` and charged to
    the truth (``(m, 7)``) or, for an extra estimate away from every truth, to the estimate
    (``(n,)``, cause ``false``); also ``(T,)`` OSPA(2)^p per window (the check).

    A pair's base: ``loc`` (both within ``c``), ``late`` / ``drop`` (the truth present, its
    estimate absent, the truth held by no track: ``cls`` 1 / 2), ``ident`` (the truth present
    and held by another track, or both present farther than ``c``), ``linger`` (the estimate
    present without its truth: before it came or after it left); an unassigned truth
    (``missing``) by its cells' classes alike; an unassigned estimate (``extra``) ``dup``
    when within ``c`` of a truth in the window (charged to the nearest), else ``false``.
    Each part divided by ``max(n, m)``."""
    T, n_all, m_all = E.shape[0], E.shape[1], Y.shape[1]
    ex, ty = ~np.isnan(E).any(-1), ~np.isnan(Y).any(-1)
    per_t, per_e, tot = np.zeros((m_all, len(CAUSES))), np.zeros(n_all), np.zeros(T)
    cp = c ** p
    for k in range(T):
        s, e = max(k + 1 - window, 0), k + 1
        xi = np.flatnonzero(ex[s:e].any(0))
        yj = np.flatnonzero(ty[s:e].any(0))
        n, m = len(xi), len(yj)
        if n == 0 and m == 0:
            continue
        big = max(n, m)
        if n == 0 or m == 0:
            tot[k] = cp
            if m:
                frac = _class_share(cls[s:e][:, yj])
                per_t[yj, 1:4] += cp * frac / big
            else:
                per_e[xi] += cp / big
            continue
        Ew, Yw, cw = E[s:e][:, xi], Y[s:e][:, yj], cls[s:e][:, yj]
        exw, tyw = ex[s:e][:, xi], ty[s:e][:, yj]
        D = np.linalg.norm(Ew[:, :, None, :] - Yw[:, None, :, :], axis=-1)
        both = exw[:, :, None] & tyw[:, None, :]
        near = both & (np.nan_to_num(D, nan=np.inf) < c)
        either = exw[:, :, None] | tyw[:, None, :]
        U = either.sum(0)
        t_only = tyw[:, None, :] & ~exw[:, :, None]
        parts = np.stack([
            np.where(near, D, 0.0).sum(0),
            c * (t_only & (cw == 1)[:, None, :]).sum(0),
            c * (t_only & (cw == 2)[:, None, :]).sum(0),
            c * ((t_only & (cw == 0)[:, None, :]) | (both & ~near)).sum(0),
            c * (exw[:, :, None] & ~tyw[:, None, :]).sum(0)], axis=-1) / U[..., None]
        base = parts.sum(-1)
        B = base ** p
        r, q = linear_sum_assignment(B)
        share = np.divide(parts[r, q], base[r, q, None], out=np.zeros((len(r), 5)),
                          where=base[r, q, None] > 0)
        per_t[yj[q], :5] += B[r, q, None] * share / big
        tot[k] = B[r, q].sum() / big + cp * abs(n - m) / big
        if m > n:
            lost = np.setdiff1d(np.arange(m), q)
            per_t[yj[lost], 1:4] += cp * _class_share(cw[:, lost]) / big
        elif n > m:
            spare = np.setdiff1d(np.arange(n), r)
            dmin = np.nan_to_num(D[:, spare], nan=np.inf).min(0)  # (len(spare), m)
            close = dmin.min(1) < c
            np.add.at(per_t[:, 5], yj[dmin[close].argmin(1)], cp / big)
            per_e[xi[spare[~close]]] += cp / big
    return per_t / T, per_e / T, tot


def _class_share(cw: np.ndarray) -> np.ndarray:
    """``(m, 3)`` the share of each truth's present cells in a window of class 1 (late), 2
    (drop) and 0 (held by some track: an identity cost), for a truth without an estimate."""
    cnt = np.stack([(cw == 1).sum(0), (cw == 2).sum(0), (cw == 0).sum(0)], axis=1)
    return cnt / np.maximum(cnt.sum(1, keepdims=True), 1)


def decompose(tables: dict[str, TrackTable], grid: np.ndarray, c: float, p: float,
              window: int) -> dict[str, dict]:
    """Per estimate table (every name but ``truth``): :func:`attribute` over the visits of
    ``truth`` (``per_visit (v, 7)``, ``false`` (scalar), ``ospa2`` mean, ``first (v,)`` the
    first tick after a visit's start a track holds it, ``cls (T, v)``); ``visits``: the
    visits' aircraft, start, length."""
    by_visit, owner = visits(tables["truth"], grid)
    vid, Y = _dense(by_visit, grid)
    out = {"visits": {"aircraft": owner[vid], "start": grid[(~np.isnan(Y[..., 0])).argmax(0)],
                      "scans": (~np.isnan(Y[..., 0])).sum(0), "Y": Y}}
    for name, t in tables.items():
        if name == "truth":
            continue
        _, E = _dense(t, grid)
        cls = truth_rows(Y, E, c)
        pt, pe, tot = attribute(E, Y, cls, c, p, window)
        first = np.where((cls == 0).any(0), (cls == 1).sum(0), (cls >= 0).sum(0))
        out[name] = {"per_visit": pt, "false": float(pe.sum()), "ospa2": float(
            (tot ** (1 / p)).mean()), "msq": float(tot.mean()), "first": first, "cls": cls}
    return out


def report(dec: dict[str, dict], fused: str, sites: dict[str, np.ndarray],
           top: int = 15) -> str:
    """The decomposition's tables: every estimate's causes (m^p), the fused excess over
    ``ref`` per cause, by where visits start and by how late, the visits that carry most of
    it, and per radar which held the aircraft the fused tracks started late on."""
    V = dec["visits"]
    names = [n for n in dec if n != "visits"]
    hdr = "estimate: OSPA(2) mean; mean OSPA(2)^p = " + " + ".join(CAUSES)
    lines = [hdr]
    for n in names:
        d = dec[n]
        tot = d["per_visit"].sum(0)
        tot[6] += d["false"]
        lines.append(f"  {n}: {d['ospa2']:.1f}; {d['msq']:.0f} = "
                     + " + ".join(f"{x:.0f}" for x in tot))
    f, r = dec[fused], dec["ref"]
    dv = f["per_visit"] - r["per_visit"]
    ex = dv.sum(0)
    ex[6] += f["false"] - r["false"]
    lines.append(f"excess of {fused} over ref: {f['msq'] - r['msq']:.0f} = "
                 + ", ".join(f"{c} {x:.0f}" for c, x in zip(CAUSES, ex, strict=True)))
    per = dv.sum(1)
    order = np.argsort(-per)
    cum = np.cumsum(per[order]) / max(per.sum(), 1e-12)
    k10 = int(np.ceil(0.1 * len(per)))
    lines.append(f"visits: {len(per)}; the {k10} with most excess carry "
                 f"{100 * cum[k10 - 1]:.0f} % of it; visits with excess < 0: "
                 f"{int((per < 0).sum())} ({per[per < 0].sum():.0f})")
    Y = V["Y"]
    cols = np.arange(Y.shape[1])
    p0 = Y[(~np.isnan(Y[..., 0])).argmax(0), cols]  # where each visit starts
    r0 = np.linalg.norm(p0, axis=-1)
    cold = V["start"] == V["start"].min()
    for label, sel in (("present at the first tick", cold),
                       ("appearing at the edge (>= 60 km)", ~cold & (r0 >= 60e3)),
                       ("appearing inside (< 60 km)", ~cold & (r0 < 60e3))):
        e = dv[sel].sum(0)
        lines.append(f"  {label}: {int(sel.sum())} visits, excess {e.sum():.0f} = "
                     + ", ".join(f"{c} {x:.0f}" for c, x in zip(CAUSES, e, strict=True)))
    lag = f["first"] - r["first"]
    lines.append(f"first held, fused minus ref (ticks): median {np.median(lag):.0f}, "
                 f"p90 {np.percentile(lag, 90):.0f}, max {lag.max()}; "
                 f"ref first held median {np.median(r['first']):.0f}")
    local = [n for n in names if n.startswith("local:")]
    lines.append(f"top {top} visits by excess (aircraft, start tick, scans, start radius km, "
                 "excess, " + "/".join(CAUSES) + "; first held ref/fused/"
                 + ",".join(n.split(":", 1)[1] for n in local) + ")")
    for j in order[:top]:
        lines.append(f"  {V['aircraft'][j]:06x} {V['start'][j]} {V['scans'][j]} "
                     f"{r0[j] / 1e3:.0f} {per[j]:.0f} "
                     + "/".join(f"{x:.0f}" for x in dv[j]) + f"; {r['first'][j]}/"
                     f"{f['first'][j]}/" + ",".join(str(dec[n]['first'][j]) for n in local))
    if local:
        late = f["cls"] == 1
        ref_held = r["cls"] == 0
        cells = late & ref_held
        lines.append(f"fused late cells the ref holds: {int(cells.sum())}; by peers' local "
                     "tracks holding then: " + _count_line(
                         np.sum([dec[n]["cls"] == 0 for n in local], axis=0)[cells],
                         len(local)))
        parts = []
        for n in local:
            nm = n.split(":", 1)[1]
            rng = np.linalg.norm(Y - sites[nm], axis=-1)[cells]
            h = (dec[n]["cls"] == 0)[cells]
            parts.append(f"{nm} holds {100 * h.mean():.0f} % (range km median "
                         f"{np.median(rng) / 1e3:.0f}); local first held median "
                         f"{np.median(dec[n]['first']):.0f}")
        lines.append("  per radar: " + "; ".join(parts))
    return "\n".join(lines)


def _count_line(x: np.ndarray, n: int) -> str:
    cnt = np.bincount(x, minlength=n + 1)
    return ", ".join(f"{j}: {cnt[j]}" for j in range(n + 1))


def save(path: str, tables: dict[str, TrackTable]) -> None:
    """The tables as one ``.npz`` (``NAME/scan``, ``NAME/id``, ``NAME/pos``)."""
    np.savez_compressed(path, **{f"{n}/{f}": getattr(t, f) for n, t in tables.items()
                                 for f in ("scan", "id", "pos")})


def load(path: str) -> dict[str, TrackTable]:
    """:func:`save`'s tables."""
    z = np.load(path)
    names = dict.fromkeys(k.rsplit("/", 1)[0] for k in z.files)
    return {n: TrackTable(z[f"{n}/scan"], z[f"{n}/id"], z[f"{n}/pos"]) for n in names}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m sensornet.sim.studies.traffic.gap_causes",
                                 description=__doc__.split("\n\n")[0])
    add_window_arguments(ap)
    ap.add_argument("--run", type=int, default=0)
    ap.add_argument("--twin-workers", type=int, default=1)
    ap.add_argument("--save", help="write the tables here (.npz)")
    ap.add_argument("--load", help="read the tables from here instead of running (the same "
                    "start; a longer run's are scored on this window's first ticks)")
    ap.add_argument("--fused", help="the fused table to take apart (default the first peer's)")
    a = ap.parse_args(argv)
    try:
        tables = load(a.load) if a.load else collect(a)
    except (ScenarioError, ValueError, OSError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    if a.save:
        save(a.save, tables)
    over, scn = window_scenario(a)
    grid = np.arange(1, scn.num_scans + 1)
    # a longer run's tables scored on its first ticks (each window looks back only)
    tables = {n: TrackTable(t.scan[t.scan <= grid[-1]], t.id[t.scan <= grid[-1]],
                            t.pos[t.scan <= grid[-1]]) for n, t in tables.items()}
    dec = decompose(tables, grid, scn.metrics.ospa_cutoff, scn.metrics.ospa_order, WINDOW)
    sites = {s.name: np.asarray(s.position[:2], float) for s in scn.sensors}
    print(report(dec, a.fused or f"fused:{scn.sensor_names[0]}", sites))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
