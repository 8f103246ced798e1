"""The real-traffic study (issue 34 item 4, docs/real-traffic.md): GM-PHD peers with tags and
LMB peers on recorded aircraft, local vs fused vs the centralised reference, judged against
the aircraft.

For each kind, on the twin (:func:`sim.run.twin.run_twin`, the peers' own cores):

* ``local``: the twin without fusion (``fusion.rule = "none"``): each radar's own filter;
* ``fused``: the twin with the scenario's rule: each peer's fused tracks;
* ``centralised``: the labelled centralised reference of the kind over every radar's plots,
  at their own times (``--centralised async``, :mod:`.asynchronous`) or at the tick's
  (``--centralised tick``, :mod:`sim.studies.labelled.centralised`).

Per peer: OSPA per tick, OSPA(2) (window 10 ticks, mean over the windows), GOSPA per tick
(``alpha = 2``), HOTA (gate = the OSPA cut-off), identity switches; per aircraft visit (an
aircraft that leaves the region and comes back is two visits, :func:`.metrics.visits`) of at
least ``--min-scans`` ticks: continuity (the share of its ticks held by its single most often
matched track) and switches per hour present (:mod:`.metrics`). The distribution
over aircraft (pooled over peers for local and fused) is reported as the median, the 10th
percentile and the share >= 90 %. The twin's wall and CPU time per simulated second gives the
speed against real time.

``python -m sensornet.sim.studies.traffic.study [SCENARIO] [--file F] [--start S]
[--minutes M] [--set KEY=VALUE ...] [--kinds gmphd,lmb] [--centralised async|tick]
[--jobs 2] [--twin-workers 2] [--md FILE] [--csv FILE] [--plot DIR]``; another recording
runs through the same command with only ``--file``, ``--start`` (window) and the sites
(``--set sensors.NAME.site=[lat, lon]``) changed.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import resource
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from sensornet.sim.run.pool import map_runs
from sensornet.sim.run.twin import run_twin
from sensornet.sim.scenario import Scenario, ScenarioError, load_scenario, parse_overrides
from sensornet.sim.studies.labelled.centralised import (
    central_gmphd,
    central_lmb,
    run_central,
)
from sensornet.sim.studies.labelled.study import central_table, peer_tables, truth_table
from sensornet.sim.studies.traffic.asynchronous import (
    async_gmphd,
    async_lmb,
    plot_batches,
    run_async,
)
from sensornet.sim.studies.traffic.centralised import central_measurement_gmphd
from sensornet.sim.studies.traffic.metrics import (
    hota_sparse,
    ospa2_curve,
    per_aircraft,
    set_errors,
    visits,
)
from sensornet.sim.world import generate_run
from sensornet.tracking.metrics import ospa
from sensornet.tracking.track_metrics import TrackTable

KINDS = ("gmphd", "lmb")
ESTIMATES = ("local", "fused", "centralised")
REFERENCES = ("async", "tick")
"""The centralised reference: every radar's plots at their own times
(:mod:`.asynchronous`), or at the tick's (:mod:`sim.studies.labelled.centralised`)."""
WINDOW = 10
"""OSPA(2) window (ticks)."""
MIN_SCANS = 30
"""An aircraft present for fewer ticks (1 min at 2 s) is left out of the per-aircraft
distribution: it may clip the region's edge for a few ticks, shorter than a track takes to
confirm."""


@dataclass(frozen=True)
class Part:
    """One (kind, estimate) of the study: its per-peer rows and per-aircraft arrays."""

    kind: str
    estimate: str
    rows: list[dict]
    aircraft: dict[str, dict[str, np.ndarray]]
    """Per peer (``"central"`` for the reference) :func:`.metrics.per_aircraft`."""
    wall: float
    cpu: float
    sim_seconds: float
    tables: dict[str, TrackTable] = field(default_factory=dict)
    truth: TrackTable | None = None


def scenario_of(source: str, overrides: dict, kind: str, estimate: str) -> Scenario:
    """The study's scenario for a kind and estimate (``local``: fusion off)."""
    over = {**overrides, "network.filter": kind}
    if estimate == "local":
        over["fusion.rule"] = "none"
    return load_scenario(source, overrides=over)


def table_rows(truth: TrackTable, tables: dict[str, TrackTable], scn: Scenario,
               ospa_mean: dict[str, float], with_hota: bool) -> tuple[list[dict], dict]:
    """Per table its metrics row and its per-aircraft arrays."""
    c, p = scn.metrics.ospa_cutoff, scn.metrics.ospa_order
    grid = np.arange(1, scn.num_scans + 1)
    rows, aircraft = [], {}
    by_visit, owner = visits(truth, grid)
    for name, t in tables.items():
        _, g = set_errors(truth, t, grid, c, p)
        pa = per_aircraft(by_visit, t, c, grid, scn.scan_period)
        pa["aircraft"] = owner[pa["id"]]
        row = {"peer": name, "ospa": ospa_mean[name],
               "switches_all": int(per_aircraft(truth, t, c, grid, 1.0)["switches_total"]),
               "ospa2": float(ospa2_curve(truth, t, grid, c, p, WINDOW).mean()),
               "gospa": float(g.mean()), "switches": int(pa["switches_total"]),
               "track_ids": int(len(np.unique(t.id)))}
        if with_hota:
            row.update(hota_sparse(truth, t, c, grid))
        rows.append(row)
        aircraft[name] = pa
    return rows, aircraft


def _children_cpu() -> float:
    """CPU seconds of this process's reaped children (the twin's workers)."""
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def run_part(source: str, overrides: dict, kind: str, estimate: str, run: int,
             with_hota: bool = True, keep_tables: bool = False,
             reference: str = REFERENCES[0], workers: int = 1) -> Part:
    """One kind's ``estimate``: run it, then score every peer's (or the reference's) tracks;
    ``reference``: which centralised one (:data:`REFERENCES`); ``workers``: the twin's
    processes (:func:`sim.run.twin.run_twin`; the same tables, CPU counted over all)."""
    scn = scenario_of(source, overrides, kind, estimate)
    truth, scans = generate_run(scn, run)
    T = truth_table(truth)
    w0, c0 = time.perf_counter(), time.process_time() + _children_cpu()
    if estimate == "centralised" and reference == "async":
        tracks, _ = run_async(async_lmb(scn) if kind == "lmb" else async_gmphd(scn),
                              plot_batches(scn, run), scn.scan_period)
    elif estimate == "centralised":
        central = (central_lmb(scn) if kind == "lmb" else central_measurement_gmphd(scn)
                   if scn.birth.model == "measurements" else central_gmphd(scn))
        tracks, _ = run_central(central, scans)
    if estimate == "centralised":
        c, p = scn.metrics.ospa_cutoff, scn.metrics.ospa_order
        om = {"central": float(np.mean([ospa(e.states[:, [0, 2]], truth.states[k][:, [0, 2]],
                                             c, p) for k, e in enumerate(tracks)]))}
        tables = {"central": central_table(tracks)}
    else:
        twin = run_twin(scn, run, workers=workers)
        which = "local" if estimate == "local" else "fused"
        tables = peer_tables(twin, scn.sensor_names, which, {})
        om = {n: twin.mean_ospa(n, which) for n in scn.sensor_names}
    wall, cpu = time.perf_counter() - w0, time.process_time() + _children_cpu() - c0
    rows, aircraft = table_rows(T, tables, scn, om, with_hota)
    for r in rows:
        r.update(kind=kind, estimate=estimate)
    return Part(kind, estimate, rows, aircraft, wall, cpu, scn.num_scans * scn.scan_period,
                tables if keep_tables else {}, T if keep_tables else None)


def default_twin_workers(sim_seconds: float) -> int:
    """The study's twin processes: 2 (both cores of issue 34's 2-core machine) for a window
    of an hour or more on a machine of 2 cores or more, else 1 (a short window's fork and
    copy back are not worth it)."""
    return 2 if sim_seconds >= 3600 and (os.cpu_count() or 1) >= 2 else 1


def distribution(aircraft: dict[str, dict[str, np.ndarray]], min_scans: int) -> dict:
    """Per-aircraft numbers pooled over peers: continuity median, 10th percentile, share >=
    90 %; switches per aircraft-hour (all switches over all hours present), its per-aircraft
    median and 90th percentile, the share of aircraft without a switch; ``aircraft``: how many
    (per peer) were judged, ``short``: left out (present < ``min_scans`` ticks)."""
    cont, rate, sw, sc = [], [], [], []
    short = 0
    for pa in aircraft.values():
        keep = pa["scans"] >= min_scans
        short += int((~keep).sum())
        cont.append(pa["continuity"][keep])
        rate.append(pa["switches_per_hour"][keep])
        sw.append(pa["switches"][keep])
        sc.append(pa["scans"][keep])
    cont, rate, sw, sc = (np.concatenate(x) for x in (cont, rate, sw, sc))
    n_peers = max(len(aircraft), 1)
    if not len(cont):
        return {"aircraft": 0, "short": short // n_peers, **dict.fromkeys(
            ("cont_median", "cont_p10", "cont_ge90", "sw_per_hour", "sw_median", "sw_p90",
             "no_switch"), math.nan)}
    return {"aircraft": len(cont) // n_peers, "short": short // n_peers,
            "cont_median": float(np.median(cont)), "cont_p10": float(np.percentile(cont, 10)),
            "cont_ge90": float(np.mean(cont >= 0.9)),
            "sw_per_hour": float(sw.sum() / (sc.sum() * 1.0)),  # per tick; scaled by caller
            "sw_median": float(np.median(rate)), "sw_p90": float(np.percentile(rate, 90)),
            "no_switch": float(np.mean(sw == 0))}


def summarise(parts: list[Part], scan_period: float, min_scans: int) -> list[dict]:
    """One line per (kind, estimate): metric means over peers (OSPA(2)'s range too), the
    per-aircraft distribution, speed (simulated seconds per wall and CPU second)."""
    out = []
    for pt in parts:
        rec: dict[str, Any] = {"kind": pt.kind, "estimate": pt.estimate,
                               "peers": len(pt.rows)}
        for m in ("ospa", "ospa2", "gospa", "hota", "deta", "assa", "switches", "track_ids"):
            vals = [r[m] for r in pt.rows if m in r]
            rec[m] = float(np.mean(vals)) if vals else math.nan
        o2 = [r["ospa2"] for r in pt.rows]
        rec["ospa2_min"], rec["ospa2_max"] = min(o2), max(o2)
        rec["ospa2_by_peer"] = {r["peer"]: r["ospa2"] for r in pt.rows}
        d = distribution(pt.aircraft, min_scans)
        d["sw_per_hour"] *= 3600.0 / scan_period
        rec.update(d)
        rec["speed_wall"] = pt.sim_seconds / pt.wall if pt.wall else math.nan
        rec["speed_cpu"] = pt.sim_seconds / pt.cpu if pt.cpu else math.nan
        out.append(rec)
    return out


def _f(x: float, digits: int = 1) -> str:
    return "–" if x is None or not np.isfinite(x) else f"{x:.{digits}f}"


def _pc(x: float) -> str:
    return "–" if x is None or not np.isfinite(x) else f"{100 * x:.0f} %"


def format_markdown(summary: list[dict]) -> str:
    """The study's table: one line per kind and estimate."""
    lines = ["| kind | estimate | OSPA (m) | OSPA(2) w=10 (m), mean [range over peers] | "
             "GOSPA / tick (m) | HOTA | DetA | AssA | continuity median, p10, >= 90 % | "
             "switches / aircraft-hour (all; median, p90; none) | speed x real time "
             "(wall, CPU) |",
             "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in summary:
        rng = (f" [{_f(r['ospa2_min'])}-{_f(r['ospa2_max'])}]" if r["peers"] > 1 else "")
        lines.append(
            f"| {r['kind']} | {r['estimate']} | {_f(r['ospa'])} | {_f(r['ospa2'])}{rng} | "
            f"{_f(r['gospa'])} | {_f(r['hota'], 3)} | {_f(r['deta'], 3)} | "
            f"{_f(r['assa'], 3)} | {_pc(r['cont_median'])}, {_pc(r['cont_p10'])}, "
            f"{_pc(r['cont_ge90'])} | {_f(r['sw_per_hour'], 2)}; {_f(r['sw_median'], 2)}, "
            f"{_f(r['sw_p90'], 2)}; {_pc(r['no_switch'])} | "
            f"{_f(r['speed_wall'], 0)}, {_f(r['speed_cpu'], 0)} |")
    return "\n".join(lines) + "\n"


def targets(summary: list[dict]) -> str:
    """Issue 34's targets per kind: fused OSPA(2) <= 0.5 x local at every peer, <= 1.2 x the
    centralised reference, continuity >= 90 % (median and 10th percentile), <= 0.5 switches
    per aircraft-hour."""
    by = {(r["kind"], r["estimate"]): r for r in summary}

    def mark(ok: bool) -> str:
        return "yes" if ok else "**no**"

    def ratio(x: float, limit: float) -> str:  # an estimate not run: no ratio, not a "no"
        return "– (not run)" if math.isnan(x) else f"{x:.2f} {mark(x <= limit)}"
    lines = ["| kind | fused / local OSPA(2), worst peer (<= 0.5) | fused / centralised "
             "(<= 1.2) | fused continuity median, p10 (>= 90 %) | fused switches / "
             "aircraft-hour (<= 0.5) |", "|---|---:|---:|---:|---:|"]
    for kind in dict.fromkeys(r["kind"] for r in summary):
        loc, f, cen = (by.get((kind, e)) for e in ESTIMATES)
        if f is None:
            continue
        a = (max(f["ospa2_by_peer"][p] / loc["ospa2_by_peer"][p] for p in f["ospa2_by_peer"])
             if loc else math.nan)
        b = f["ospa2"] / cen["ospa2"] if cen else math.nan
        lines.append(
            f"| {kind} | {ratio(a, 0.5)} | {ratio(b, 1.2)} | "
            f"{_pc(f['cont_median'])}, {_pc(f['cont_p10'])} {mark(f['cont_p10'] >= 0.9)} | "
            f"{_f(f['sw_per_hour'], 2)} {mark(f['sw_per_hour'] <= 0.5)} |")
    return "\n".join(lines) + "\n"


def plot(parts: list[Part], out: Path, minutes: float, scan_period: float,
         min_scans: int) -> list[Path]:
    """``tracks.png``: the first peer's fused tracks of the first kind over the first
    ``minutes`` (one line per track id), the true paths grey; ``continuity.png``: histograms
    of per-aircraft continuity per kind and estimate."""
    import matplotlib  # heavy optional dependency: matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # heavy optional dependency: matplotlib

    out.mkdir(parents=True, exist_ok=True)
    paths = []
    fused = [pt for pt in parts if pt.estimate == "fused" and pt.tables]
    if fused:
        pt = fused[0]
        peer, tab = next(iter(pt.tables.items()))
        last = int(minutes * 60 / scan_period)
        fig, ax = plt.subplots(figsize=(6.4, 6.4), dpi=80)
        tr = pt.truth
        for i in np.unique(tr.id):
            s = (tr.id == i) & (tr.scan <= last)
            if s.any():
                ax.plot(tr.pos[s, 0] / 1e3, tr.pos[s, 1] / 1e3, color="0.75", lw=3, zorder=1)
        cmap = plt.get_cmap("tab20")
        for j, i in enumerate(np.unique(tab.id)):
            s = (tab.id == i) & (tab.scan <= last)
            if s.sum() > 1:
                ax.plot(tab.pos[s, 0] / 1e3, tab.pos[s, 1] / 1e3, color=cmap(j % 20), lw=1,
                        zorder=2)
        ax.set_aspect("equal")
        ax.set_xlabel("east (km)")
        ax.set_ylabel("north (km)")
        ax.set_title(f"{pt.kind} fused tracks at {peer} (colour: track id), true paths "
                     f"grey; first {minutes:g} min", fontsize=9)
        p = out / "traffic-tracks.png"
        fig.savefig(p, bbox_inches="tight")
        plt.close(fig)
        paths.append(p)
    kinds = list(dict.fromkeys(pt.kind for pt in parts))
    fig, axes = plt.subplots(1, len(kinds), figsize=(4.2 * len(kinds), 3.2), dpi=80,
                             squeeze=False)
    bins = np.linspace(0, 1, 21)
    for ax, kind in zip(axes[0], kinds, strict=True):
        for pt in parts:
            if pt.kind != kind:
                continue
            c = np.concatenate([a["continuity"][a["scans"] >= min_scans]
                                for a in pt.aircraft.values()])
            ax.hist(c, bins=bins, histtype="step", density=True, lw=1.5, label=pt.estimate)
        ax.axvline(0.9, color="k", ls=":", lw=1)
        ax.set_xlabel("continuity (share of a visit on its longest track)")
        ax.set_title(kind, fontsize=9)
        ax.legend(fontsize=8, loc="upper left")
    axes[0][0].set_ylabel("density over aircraft (x peers)")
    p = out / "traffic-continuity.png"
    fig.savefig(p, bbox_inches="tight")
    plt.close(fig)
    paths.append(p)
    return paths


def add_window_arguments(ap: argparse.ArgumentParser) -> None:
    """The scenario and its traffic window, alike in every traffic study's command line."""
    ap.add_argument("scenario", nargs="?", default="paris-8",
                    help="a shipped scenario name or a scenario file (default paris-8)")
    ap.add_argument("--file", help="state-vector file (traffic.file)")
    ap.add_argument("--start", help="window start (traffic.start: seconds after the file's "
                    "first report, or an ISO 8601 time)")
    ap.add_argument("--minutes", type=float, help="window length (sets scenario.num_scans)")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help="scenario override (e.g. sensors.cdg.site=[49.0, 2.5])")


def window_scenario(a: argparse.Namespace, over: dict | None = None) -> tuple[dict, Scenario]:
    """The overrides (``over`` first, then ``--set``, file, start, window) and the scenario
    of :func:`add_window_arguments`' arguments; raises ScenarioError / ValueError."""
    over = {**(over or {}), **parse_overrides(a.set)}
    if a.file:
        over["traffic.file"] = str(Path(a.file).resolve())
    if a.start is not None:
        over["traffic.start"] = parse_overrides([f"v={a.start}"])["v"]
        if isinstance(over["traffic.start"], int):
            over["traffic.start"] = float(over["traffic.start"])
    base = load_scenario(a.scenario, overrides=over)
    if a.minutes is not None:
        over["scenario.num_scans"] = int(round(a.minutes * 60 / base.scan_period))
        base = load_scenario(a.scenario, overrides=over)
    return over, base


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m sensornet.sim.studies.traffic.study",
                                 description=__doc__.split("\n\n")[0])
    add_window_arguments(ap)
    ap.add_argument("--kinds", default=",".join(KINDS))
    ap.add_argument("--estimates", default=",".join(ESTIMATES))
    ap.add_argument("--centralised", choices=REFERENCES, default=REFERENCES[0],
                    help="the centralised reference: plots at their own times (async) or at "
                    "the tick's (tick)")
    ap.add_argument("--run", type=int, default=0, help="the radars' noise seed")
    ap.add_argument("--min-scans", type=int, default=MIN_SCANS,
                    help="ticks an aircraft must be present to be judged per aircraft")
    ap.add_argument("--no-hota", action="store_true")
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--twin-workers", type=int,
                    help="the twin's processes per kind (sim.run.twin_split: the same "
                    "tables); default 2 on a machine of 2 cores or more for a window of an "
                    "hour or more, else 1")
    ap.add_argument("--md", help="write the table and the targets here too")
    ap.add_argument("--json", help="write the summary here")
    ap.add_argument("--csv", help="write the per-peer rows here")
    ap.add_argument("--plot", help="write traffic-tracks.png and traffic-continuity.png here")
    ap.add_argument("--plot-minutes", type=float, default=20.0)
    ap.add_argument("--quiet", action="store_true", help="no progress line")
    a = ap.parse_args(argv)
    kinds = tuple(k for k in a.kinds.split(",") if k)
    ests = tuple(e for e in a.estimates.split(",") if e)
    bad = sorted(set(kinds) - set(KINDS)) + sorted(set(ests) - set(ESTIMATES))
    if bad:
        print(f"unknown kind or estimate: {', '.join(bad)}", file=sys.stderr)
        return 2
    try:
        over, base = window_scenario(a)
    except (ScenarioError, ValueError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    if a.twin_workers is None:
        a.twin_workers = default_twin_workers(base.num_scans * base.scan_period)
    if a.twin_workers < 1:
        print(f"--twin-workers must be >= 1, got {a.twin_workers}", file=sys.stderr)
        return 2
    calls = [(a.scenario, over, k, e, a.run, not a.no_hota, bool(a.plot), a.centralised,
              a.twin_workers) for k in kinds for e in ests]
    t0 = time.perf_counter()
    parts = map_runs(run_part, calls, a.jobs, "traffic study (kind x estimate)", not a.quiet)
    summary = summarise(parts, base.scan_period, a.min_scans)
    hours = base.num_scans * base.scan_period / 3600
    text = (f"{base.name}: {len(base.sensors)} radars, {base.num_scans} ticks of "
            f"{base.scan_period:g} s ({hours:.2f} h) from traffic.start = "
            f"{base.traffic.start}, run {a.run}; per-aircraft numbers over the aircraft "
            f"visits >= {a.min_scans} ticks ({summary[0]['aircraft']} judged, "
            f"{summary[0]['short']} shorter)\n\n" + format_markdown(summary)
            + "\nTargets:\n\n" + targets(summary)
            + f"\n{time.perf_counter() - t0:.0f} s wall (the twin in {a.twin_workers} "
            f"process{'es' if a.twin_workers > 1 else ''})\n")
    print(text)
    if a.md:
        Path(a.md).write_text(text)
    if a.json:
        Path(a.json).write_text(json.dumps(summary, indent=1, default=float))
    if a.csv:
        rows = [r for pt in parts for r in pt.rows]
        keys = list(dict.fromkeys(k for r in rows for k in r))
        with open(a.csv, "w") as f:
            f.write(",".join(keys) + "\n")
            for r in rows:
                f.write(",".join(str(r.get(k, "")) for k in keys) + "\n")
    if a.plot:
        for p in plot(parts, Path(a.plot), a.plot_minutes, base.scan_period, a.min_scans):
            print(f"wrote {p}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
