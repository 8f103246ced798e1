"""The labelled-tracking study (issue 33, docs/labelled-tracking.md): local / fused /
centralised track quality of GM-PHD peers with tags and LMB peers, per fusion rule.

For each graph (seed 000's full mesh of 3; 20 peers on a circulant graph of degree 4,
:func:`sim.world.graphs.network_scenario`), condition (Pd, clutter), peer kind and Monte Carlo
run, on the twin (:func:`sim.run.twin.run_twin`, the peers' own cores):

* ``local``: a twin without fusion (``fusion.rule = "none"``): each peer's own filter;
* ``fused``: a twin per fusion rule (hybrid, GCI, AA): each peer's fused tracks;
* ``centralised``: the labelled centralised reference of the kind over every sensor's scans
  (:mod:`.centralised`), on the same run's scans.

Per peer (then averaged over peers, then mean and 95 % interval over runs): OSPA (the peers'
own per-scan score), OSPA(2) (window 10, mean over the windows ending at each scan),
trajectory GOSPA per scan (switch cost ``gamma = c``, LP form), identity switches per 1,000
true target-scans (CLEAR MOT, gate ``c``; mean and worst peer), all from
:func:`tracking.track_metrics.track_report`; label agreement across peers
(:func:`tracking.track_metrics.label_agreement`, all and confirmed tracks); the first track's
delay (scans from a target's first scan to its first matched track, confirmed and all tracks:
:func:`tracking.track_metrics.first_match_delay`, what confirmation costs); tuples sent per
peer-scan (``PeerCore.cost``); CPU per peer-scan (the twin's process time over peers x scans:
local step, fusion, codec; centralised: the filter's CPU per scan for all sensors).

``python -m sensornet.sim.studies.labelled.study [--runs3 8] [--runs20 3] [--rounds20 1]
[--jobs 1] [--md FILE]``; progress on stderr.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from sensornet.sim.campaign.runners import scenario_source
from sensornet.sim.campaign.sweep import cost_columns
from sensornet.sim.run.pool import map_runs
from sensornet.sim.run.twin import TwinResult, run_twin
from sensornet.sim.scenario import Scenario, load_scenario
from sensornet.sim.studies.fusion.quality import interval
from sensornet.sim.studies.labelled.centralised import (
    Extracted,
    central_gmphd,
    central_lmb,
    run_central,
)
from sensornet.sim.world import Truth, generate_run
from sensornet.sim.world.graphs import network_scenario
from sensornet.tracking.metrics import ospa
from sensornet.tracking.track_metrics import (
    TrackTable,
    first_match_delay,
    label_agreement,
    track_report,
)

KINDS = ("gmphd", "lmb")
RULES = {"hybrid": {"fusion.rule": "hybrid"}, "gci": {"fusion.rule": "gci",
                                                      "fusion.cardinality": "separate"},
         "aa": {"fusion.rule": "aa"}}
CONDITIONS = ((0.99, 10.0), (0.9, 10.0))
WINDOW = 10
"""OSPA(2) window (scans)."""
METRICS = ("ospa", "ospa2", "tgospa", "switches", "switches_max", "switches_confirmed",
           "switches_confirmed_max", "agreement", "agreement_confirmed", "delay", "delay_all",
           "tuples", "cpu_ms")


@dataclass(frozen=True)
class Graph:
    name: str
    scenario: str
    """A shipped scenario name or ``circulant:N:D[:L]`` (``L`` consensus rounds a scan,
    default 1: :func:`sim.world.graphs.network_scenario`)."""
    runs: int


def scenario_of(graph: Graph, kind: str, pd: float, clutter: float, scans: int | None,
                extra: dict | None = None) -> Scenario:
    """The graph's scenario with the kind, condition and ``extra`` overrides."""
    over = {"network.filter": kind, "sensors.*.detection_probability": pd,
            "sensors.*.clutter_rate": clutter, **(extra or {})}
    if scans is not None:
        over["scenario.num_scans"] = scans
    if graph.scenario.startswith("circulant:"):
        n, d, *rounds = (int(x) for x in graph.scenario.split(":")[1:])
        L = rounds[0] if rounds else 1
        src = scenario_source(f"circulant-{n}-{d}{f'-{L}' if L != 1 else ''}.toml",
                              network_scenario(n, d, rounds=L))
    else:
        src = graph.scenario
    return load_scenario(src, overrides=over)


def circ20(runs: int, rounds: int = 1) -> Graph:
    """The study's 20 peers of degree 4 with ``rounds`` consensus rounds a scan (named
    ``circ4-20`` at the default 1, ``circ4-20 L=rounds`` otherwise)."""
    if rounds == 1:
        return Graph("circ4-20", "circulant:20:4", runs)
    return Graph(f"circ4-20 L={rounds}", f"circulant:20:4:{rounds}", runs)


def truth_table(truth: Truth, pos=(0, 2)) -> TrackTable:
    """The truth as a track table (scan ``k`` = index + 1, id = target id)."""
    S = np.concatenate([np.full(len(i), k + 1) for k, i in enumerate(truth.ids)])
    ids = np.concatenate(truth.ids)
    X = np.concatenate([x[:, list(pos)] for x in truth.states]).reshape(-1, len(pos))
    return TrackTable(S, ids, X)


def peer_tables(twin: TwinResult, names: list[str], which: str, code: dict,
                confirmed: bool = False, pos: tuple[int, int] = (0, 2)
                ) -> dict[str, TrackTable]:
    """Per peer a table of its ``which`` (``"local"``/``"fused"``) tracks from its results
    table (positions: state indices ``pos``); labels coded to ints by ``code`` (shared by all
    peers, so equal labels get equal ids); a label twice in one scan keeps its first row (it
    can happen only for GM-PHD tags, Panta's rule applies above the extraction threshold
    only). A row without one id and one status per track is a ValueError."""
    out = {}
    for p in names:
        t = twin.peers[p].scorer.results.table(p)
        S, Id, X = [], [], []
        for k, e, tr, ids, st in zip(t["scan"], t["estimate"], t["tracks"], t["track_ids"],
                                     t["track_status"], strict=True):
            if e != which:
                continue
            seen: set = set()
            for x, i, s in zip(tr, ids, st, strict=True):
                key = tuple(i)
                if key in seen or (confirmed and not s):
                    continue
                seen.add(key)
                S.append(k)
                Id.append(code.setdefault(key, len(code)))
                X.append([x[pos[0]], x[pos[1]]])
        out[p] = TrackTable(np.array(S, dtype=np.int64), np.array(Id, dtype=np.int64),
                            np.array(X, dtype=float).reshape(-1, 2))
    return out


def central_table(tracks: list[Extracted], confirmed: bool = False) -> TrackTable:
    """The centralised filter's tracks as a table (``confirmed``: those only)."""
    code: dict = {}
    S, Id, X = [], [], []
    for k, e in enumerate(tracks, start=1):
        seen: set = set()
        for x, lab, st in zip(e.states, e.labels.tolist(), e.status, strict=True):
            if tuple(lab) in seen or (confirmed and not st):
                continue
            seen.add(tuple(lab))
            S.append(k)
            Id.append(code.setdefault(tuple(lab), len(code)))
            X.append([x[0], x[2]])
    return TrackTable(np.array(S, dtype=np.int64), np.array(Id, dtype=np.int64),
                      np.array(X, dtype=float).reshape(-1, 2))


def track_columns(truth: TrackTable, tables: dict[str, TrackTable], scn: Scenario,
                  with_tgospa: bool = True, confirmed: dict[str, TrackTable] | None = None
                  ) -> dict[str, float]:
    """OSPA(2), trajectory GOSPA per scan and switches per 1,000 of each table (mean over the
    tables) and the worst table's switches; the switches of the ``confirmed`` tables too."""
    c = scn.metrics.ospa_cutoff
    grid = np.arange(1, scn.num_scans + 1)
    reps = [track_report(truth, t, c=c, p=scn.metrics.ospa_order, window=WINDOW, scans=grid,
                         with_hota=False, with_tgospa=with_tgospa) for t in tables.values()]
    sw = [r["switches_per_1000"] for r in reps]
    out = {"ospa2": float(np.mean([r["ospa2_mean"] for r in reps])),
           "tgospa": float(np.mean([r["tgospa_per_scan"] for r in reps])) if with_tgospa
           else math.nan,
           "switches": float(np.mean(sw)), "switches_max": float(np.max(sw))}
    out["delay_all"] = mean_delay(truth, tables, c, grid)
    if confirmed is not None:
        sw = [track_report(truth, t, c=c, scans=grid, with_hota=False,
                           with_tgospa=False)["switches_per_1000"] for t in confirmed.values()]
        out.update(switches_confirmed=float(np.mean(sw)), switches_confirmed_max=float(max(sw)),
                   delay=mean_delay(truth, confirmed, c, grid))
    return out


def mean_delay(truth: TrackTable, tables: dict[str, TrackTable], gate: float,
               grid: np.ndarray) -> float:
    """Scans from a target's first scan to its first matched track, mean over every (table,
    target) pair matched at all (:func:`tracking.track_metrics.first_match_delay`)."""
    d = np.concatenate([first_match_delay(truth, t, gate, grid) for t in tables.values()])
    return float(d.mean()) if d.size else math.nan


def twin_row(scn: Scenario, run: int, which: str, with_tgospa: bool) -> dict[str, float]:
    """One twin run's ``which`` (local or fused) row."""
    c0 = time.process_time()
    twin = run_twin(scn, run)
    cpu = time.process_time() - c0
    names = scn.sensor_names
    truth, _ = generate_run(scn, run)
    T = truth_table(truth)
    code: dict = {}
    tabs = peer_tables(twin, names, which, code)
    conf = peer_tables(twin, names, which, code, confirmed=True)
    row = {"ospa": float(np.mean([twin.mean_ospa(p, which) for p in names])),
           **track_columns(T, tabs, scn, with_tgospa, conf),
           "cpu_ms": 1e3 * cpu / (len(names) * scn.num_scans),
           "tuples": cost_columns([p.cost() for p in twin.peers.values()])[
               "tuples_per_peer_scan"]}
    if which == "fused":
        c = scn.metrics.ospa_cutoff
        row["agreement"] = label_agreement(tabs, T, gate=c)["agreement"]
        row["agreement_confirmed"] = label_agreement(conf, T, gate=c)["agreement"]
    return row


def central_row(scn: Scenario, run: int, kind: str, with_tgospa: bool) -> dict[str, float]:
    """The labelled centralised reference's row on run ``run``."""
    truth, scans = generate_run(scn, run)
    central = central_lmb(scn) if kind == "lmb" else central_gmphd(scn)
    tracks, cpu = run_central(central, scans)
    c, p = scn.metrics.ospa_cutoff, scn.metrics.ospa_order
    o = [ospa(e.states[:, [0, 2]], truth.states[k][:, [0, 2]], c, p)
         for k, e in enumerate(tracks)]
    return {"ospa": float(np.mean(o)),
            **track_columns(truth_table(truth), {"central": central_table(tracks)}, scn,
                            with_tgospa, {"central": central_table(tracks, True)}),
            "cpu_ms": 1e3 * cpu / scn.num_scans}


def one_run(graph: Graph, pd: float, clutter: float, kind: str, run: int, rules: tuple,
            scans: int | None, with_tgospa: bool) -> list[dict]:
    """Every estimate's row of one (graph, condition, kind, run)."""
    key = {"graph": graph.name, "pd": pd, "clutter": clutter, "kind": kind, "run": run}
    rows = [{**key, "estimate": "local", "rule": "none",
             **twin_row(scenario_of(graph, kind, pd, clutter, scans, {"fusion.rule": "none"}),
                        run, "local", with_tgospa)}]
    for r in rules:
        rows.append({**key, "estimate": "fused", "rule": r,
                     **twin_row(scenario_of(graph, kind, pd, clutter, scans, RULES[r]), run,
                                "fused", with_tgospa)})
    rows.append({**key, "estimate": "centralised", "rule": "–",
                 **central_row(scenario_of(graph, kind, pd, clutter, scans), run, kind,
                               with_tgospa)})
    return rows


def run_study(graphs: list[Graph], first_run: int = 0, rules: tuple = tuple(RULES),
              kinds: tuple = KINDS, conditions=CONDITIONS, scans: int | None = None,
              jobs: int = 1, progress: bool = True, with_tgospa: bool = True) -> list[dict]:
    """Every run's rows (:func:`one_run`), runs ``first_run ..`` of each graph."""
    calls = [(g, pd, cl, kind, first_run + i, rules, scans, with_tgospa)
             for g in graphs for pd, cl in conditions for kind in kinds for i in range(g.runs)]
    done = map_runs(one_run, calls, jobs, "labelled study (graph x condition x kind x run)",
                    progress)
    return [r for rows in done for r in rows]


def summarise(rows: list[dict]) -> list[dict]:
    """One row per (graph, Pd, clutter, kind, estimate, rule): each metric's mean over runs
    and its 95 % half-width (``NAME_ci``); ``runs``."""
    groups: dict[tuple, list[dict]] = {}
    for r in rows:
        groups.setdefault((r["graph"], r["pd"], r["clutter"], r["kind"], r["estimate"],
                           r["rule"]), []).append(r)
    out = []
    for (g, pd, cl, kind, est, rule), rs in groups.items():
        rec = {"graph": g, "pd": pd, "clutter": cl, "kind": kind, "estimate": est,
               "rule": rule, "runs": len(rs)}
        for m in METRICS:
            vals = np.array([r[m] for r in rs if m in r and np.isfinite(r[m])], float)
            rec[m], rec[f"{m}_ci"] = interval(vals) if len(vals) else (math.nan, math.nan)
        for m in ("switches_max", "switches_confirmed_max"):  # worst peer and run
            rec[m] = float(max(r[m] for r in rs))
        out.append(rec)
    return out


def _f(x: float, digits: int = 1) -> str:
    return "–" if x is None or not np.isfinite(x) else f"{x:.{digits}f}"


def format_markdown(summary: list[dict]) -> str:
    """The study's table (one line per graph, condition, kind, estimate and rule)."""
    head = ("| graph | Pd | kind | estimate | rule | OSPA | OSPA(2) w=10 | tGOSPA / scan | "
            "switches / 1,000 (mean, worst peer) | confirmed: switches / 1,000 (mean, worst) | "
            "label agreement (all, confirmed) | first track, scans after birth (confirmed, all) "
            "| tuples / peer-scan | CPU ms / peer-scan | runs |")
    lines = [head, "|---|---:|---|---|---|" + "---:|" * 10]
    for r in summary:
        agree = ("–" if not np.isfinite(r["agreement"]) else
                 f"{100 * r['agreement']:.1f} %, {100 * r['agreement_confirmed']:.1f} %")
        cpu = _f(r["cpu_ms"], 2) + (" (whole filter)" if r["estimate"] == "centralised" else "")
        lines.append(
            f"| {r['graph']} | {r['pd']} | {r['kind']} | {r['estimate']} | {r['rule']} | "
            f"{_f(r['ospa'])} | {_f(r['ospa2'])} ± {_f(r['ospa2_ci'])} | {_f(r['tgospa'])} | "
            f"{_f(r['switches'])}, {_f(r['switches_max'])} | "
            f"{_f(r['switches_confirmed'])}, {_f(r['switches_confirmed_max'])} | {agree} | "
            f"{_f(r['delay'], 2)}, {_f(r['delay_all'], 2)} | {_f(r['tuples'], 0)} | "
            f"{cpu} | {r['runs']} |")
    return "\n".join(lines) + "\n"


def targets(summary: list[dict], rule: str = "hybrid") -> str:
    """The issue's targets per (graph, Pd, kind) for ``rule``: fused OSPA(2) <= 0.5 x local,
    <= 1.2 x centralised, worst peer <= 1 switch per 1,000, confirmed agreement >= 99 %."""
    by = {(r["graph"], r["pd"], r["kind"], r["estimate"], r["rule"]): r for r in summary}
    lines = ["| graph | Pd | kind | fused / local OSPA(2) (<= 0.5) | fused / centralised "
             "(<= 1.2) | worst peer switches / 1,000 (<= 1; all, confirmed) | confirmed "
             "agreement (>= 99 %) |", "|---|---:|---|---:|---:|---:|---:|"]
    for (g, pd, kind, est, ru), f in by.items():
        if est != "fused" or ru != rule:
            continue
        loc, cen = by.get((g, pd, kind, "local", "none")), by.get((g, pd, kind, "centralised",
                                                                   "–"))
        a = f["ospa2"] / loc["ospa2"] if loc else math.nan
        b = f["ospa2"] / cen["ospa2"] if cen else math.nan

        def mark(ok: bool) -> str:
            return "yes" if ok else "**no**"
        lines.append(f"| {g} | {pd} | {kind} | {a:.2f} {mark(a <= 0.5)} | {b:.2f} "
                     f"{mark(b <= 1.2)} | {f['switches_max']:.1f} "
                     f"{mark(f['switches_max'] <= 1)}, {f['switches_confirmed_max']:.1f} "
                     f"{mark(f['switches_confirmed_max'] <= 1)} | "
                     f"{100 * f['agreement_confirmed']:.1f} % "
                     f"{mark(f['agreement_confirmed'] >= 0.99)} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m sensornet.sim.studies.labelled.study",
                                 description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs3", type=int, default=8, help="runs on seed 000's 3 peers")
    ap.add_argument("--runs20", type=int, default=3, help="runs on 20 peers of degree 4")
    ap.add_argument("--rounds20", type=int, default=1,
                    help="consensus rounds a scan on the 20 peers (network.rounds; default 1)")
    ap.add_argument("--first-run", type=int, default=0,
                    help="first run index (evaluation: 0..; the training runs were 100, 101)")
    ap.add_argument("--scans", type=int, help="scans per run (default: the scenario's)")
    ap.add_argument("--rules", default=",".join(RULES), help="fused rules, comma-separated")
    ap.add_argument("--kinds", default=",".join(KINDS))
    ap.add_argument("--no-tgospa", action="store_true", help="skip trajectory GOSPA")
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--md", help="write the table and the targets here too")
    ap.add_argument("--csv", help="write every run's rows here")
    a = ap.parse_args(argv)
    rules = tuple(x for x in a.rules.split(",") if x)
    bad = sorted(set(rules) - set(RULES)) + sorted(set(a.kinds.split(",")) - set(KINDS))
    if bad:
        print(f"unknown rule or kind: {', '.join(bad)}", file=sys.stderr)
        return 2
    if a.rounds20 < 1:
        print(f"--rounds20 must be >= 1, got {a.rounds20}", file=sys.stderr)
        return 2
    graphs = [g for g in (Graph("full-3 (seed 000)", "seed000", a.runs3),
                          circ20(a.runs20, a.rounds20)) if g.runs > 0]
    t0 = time.perf_counter()
    rows = run_study(graphs, a.first_run, rules, tuple(a.kinds.split(",")), scans=a.scans,
                     jobs=a.jobs, with_tgospa=not a.no_tgospa)
    summary = summarise(rows)
    text = (format_markdown(summary) + "\nTargets (hybrid):\n\n" + targets(summary)
            + f"\n{len(rows)} rows, {time.perf_counter() - t0:.0f} s\n")
    print(text)
    if a.md:
        Path(a.md).write_text(text)
    if a.csv:
        keys = sorted({k for r in rows for k in r})
        with open(a.csv, "w") as f:
            f.write(",".join(keys) + "\n")
            for r in rows:
                f.write(",".join(str(r.get(k, "")) for k in keys) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
