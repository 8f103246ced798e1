"""The fusion-quality study: which fusion rule, how many rounds, on which network.

A campaign file with a ``[study]`` table (``sim/campaigns/fusion-quality.toml``) expands here
into campaign cells, run by :func:`sim.campaign.run_campaign` (resumable, any worker count):

* for every condition (detection probability, clutter rate) and every graph it names, one twin
  cell per fusion rule and round count ``L`` (fused and local OSPA, cardinality error, tuples and
  bytes per peer per scan, averaged over the peers), one twin cell without fusion, and one
  ``experiment`` cell whose centralised iterated-corrector GM-PHD over every sensor's scans is
  the reference;
* graphs are shipped scenarios (``"seed000"``: a full mesh of 3; ``"seed004"``: its random
  geometric graph of 20) or generated circulant networks (``"circulant:N:D"``, a ring is
  ``D = 2``: :func:`sim.world.graphs.network_scenario`).

``python -m sensornet.sim.studies.fusion.quality report FOLDER`` writes the table (mean and 95 %
interval
over the
runs of each cell) and the figures: OSPA against ``L`` per rule and graph, and OSPA against
communication cost.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from sensornet.sim.campaign import Campaign, CampaignError, Cell, task_key
from sensornet.sim.campaign.results import ResultStore
from sensornet.sim.campaign.runners import code_version, scenario_hash, scenario_source
from sensornet.sim.report.report_plots import plt_module
from sensornet.sim.scenario import ScenarioError, builtin_scenarios, load_scenario
from sensornet.sim.world.graphs import network_scenario

STUDY_KIND = "fusion-quality"
NO_FUSION = "none"
CENTRALISED = "centralised"


@dataclass(frozen=True)
class Graph:
    name: str
    scenario: str
    """A shipped scenario name, a file next to the campaign, or ``circulant:N:D``."""
    runs: int
    overrides: dict
    pd_key: str = "sensors.*.detection_probability"
    clutter_key: str = "sensors.*.clutter_rate"
    """The keys a condition sets (seed 004's own format has one ``[sensors]`` table)."""


@dataclass(frozen=True)
class Rule:
    name: str
    overrides: dict
    max_peers: int | None = None
    """Leave this rule out on larger graphs (an expensive rule measured on small ones only)."""
    rounds: tuple[int, ...] | None = None
    """This rule's round counts (None: the study's)."""


def _fail(label: str, problem: str):
    return CampaignError(f"{label}: {problem}")


def _table_list(data: dict, key: str, label: str, required: tuple[str, ...],
                optional: tuple[str, ...]) -> list[dict]:
    items = data.get(key)
    if not isinstance(items, list) or not items or not all(isinstance(i, dict) for i in items):
        raise _fail(label, f"study.{key} must be a non-empty array of tables")
    for item in items:
        missing = [k for k in required if k not in item]
        unknown = sorted(set(item) - set(required) - set(optional))
        if missing or unknown:
            raise _fail(label, f"study.{key} entry {item!r}: "
                        + (f"needs {missing}" if missing else f"unknown key(s) {unknown}"))
    return items


def _scenario(spec: str, base: Path | None, label: str) -> tuple[str, str | None]:
    """``(name, text)`` of a graph's scenario, as campaign tasks carry it."""
    if spec.startswith("circulant:"):
        try:
            _, n, d = spec.split(":")
            n, d = int(n), int(d)
        except ValueError:
            raise _fail(label, f"graph scenario {spec!r}: expected circulant:N:D") from None
        if not (3 <= n <= 1000 and 2 <= d < n):
            raise _fail(label, f"graph scenario {spec!r}: need 3 <= N <= 1000, 2 <= D < N")
        name = f"circulant-{n}-{d}.toml"
        return name, network_scenario(n, d, name=f"circulant{n}d{d}")
    path = base / spec if base is not None else Path(spec)
    if path.is_file():
        return path.name, path.read_text(encoding="utf-8")
    if spec in builtin_scenarios():
        return spec, None
    raise _fail(label, f"graph scenario {spec!r}: not circulant:N:D, a file next to the "
                f"campaign, nor a shipped scenario ({', '.join(builtin_scenarios())})")


def _round_list(value, where: str, label: str) -> tuple[int, ...]:
    """A list of round counts, each in 1..16."""
    if not (isinstance(value, list) and value and all(
            isinstance(x, int) and not isinstance(x, bool) and 1 <= x <= 16 for x in value)):
        raise _fail(label, f"{where} must be a list of integers in 1..16, got {value!r}")
    return tuple(value)


def _head(data: dict, label: str, runs: int | None) -> tuple[dict, dict, int]:
    """``([campaign], [study], first_run)`` of a study file, their keys checked."""
    unknown = set(data) - {"campaign", "study"}
    if unknown:
        raise _fail(label, f"a study file has [campaign] and [study] only, not {sorted(unknown)}")
    head, study = data.get("campaign", {}), data["study"]
    bad = set(head) - {"name", "runs", "first_run"}
    if bad:
        raise _fail(label, f"unknown key(s) {sorted(bad)} in [campaign] of a study")
    if study.get("kind") != STUDY_KIND:
        raise _fail(label, f"study.kind must be {STUDY_KIND!r}, got {study.get('kind')!r}")
    bad = set(study) - {"kind", "graphs", "rules", "rounds", "conditions"}
    if bad:
        raise _fail(label, f"unknown key(s) {sorted(bad)} in [study]")
    if runs is not None and (not isinstance(runs, int) or runs < 1):
        raise _fail(label, f"runs must be an integer >= 1, got {runs!r}")
    first = head.get("first_run", 0)
    if not isinstance(first, int) or first < 0:
        raise _fail(label, f"campaign.first_run must be an integer >= 0, got {first!r}")
    return head, study, first


def _graphs(study: dict, label: str, runs: int | None, default_runs: int) -> dict[str, Graph]:
    """``study.graphs`` by name (``runs``, when given, overrides each graph's own)."""
    graphs = {}
    for g in _table_list(study, "graphs", label, ("name", "scenario"),
                         ("runs", "set", "pd_key", "clutter_key")):
        n_runs = runs if runs is not None else g.get("runs", default_runs)
        if not isinstance(n_runs, int) or n_runs < 1:
            raise _fail(label, f"graph {g['name']!r}: runs must be an integer >= 1")
        graphs[str(g["name"])] = Graph(str(g["name"]), str(g["scenario"]), n_runs,
                                       dict(g.get("set", {})),
                                       str(g.get("pd_key", Graph.pd_key)),
                                       str(g.get("clutter_key", Graph.clutter_key)))
    return graphs


def _rules(study: dict, label: str) -> tuple[list[Rule], list[dict]]:
    """``(study.rules, study.conditions)``, each condition's rules checked against the rules."""
    rules = [Rule(str(r["name"]), dict(r.get("set", {})), r.get("max_peers"),
                  _round_list(r["rounds"], f"rule {r['name']!r}: rounds", label)
                  if "rounds" in r else None)
             for r in _table_list(study, "rules", label, ("name",),
                                  ("set", "max_peers", "rounds"))]
    conditions = _table_list(study, "conditions", label, ("pd", "clutter"), ("graphs", "rules"))
    names = {r.name for r in rules}
    for cond in conditions:
        unknown = sorted(set(cond.get("rules", [])) - names)
        if unknown:
            raise _fail(label, f"condition {cond!r} names unknown rule(s) {unknown} "
                        f"(rules: {', '.join(sorted(names))})")
    return rules, conditions


def study_campaign(data: dict, path: Path | None, runs: int | None = None):
    """The :class:`sim.campaign.Campaign` of a study file (``runs``: every cell's run count)."""
    label = path.name if path is not None else "study"
    head, study, first = _head(data, label, runs)
    graphs = _graphs(study, label, runs, head.get("runs", 4))
    rounds = _round_list(study.get("rounds", [1, 2, 3, 4]), "study.rounds", label)
    rules, conditions = _rules(study, label)
    version = code_version()
    base = path.parent if path is not None else None
    cells: list[Cell] = []
    loaded: dict[tuple, Any] = {}
    for cond in conditions:
        for gname in cond.get("graphs", list(graphs)):
            if gname not in graphs:
                raise _fail(label, f"condition {cond!r} names an unknown graph {gname!r} "
                            f"(graphs: {', '.join(graphs)})")
            _add_cells(cells, loaded, label, graphs[gname], cond, rules, rounds, base, first,
                       version)
    return Campaign(str(head.get("name", path.stem if path else "fusion-quality")), path,
                    "(per cell)", None, "twin", max(g.runs for g in graphs.values()), first,
                    ("*",), cells, [], version)


def _add_cells(cells: list[Cell], loaded: dict[tuple, Any], label: str, g: Graph, cond: dict,
               rules: list[Rule], rounds: tuple[int, ...], base: Path | None, first: int,
               version: str) -> None:
    """Append to ``cells`` those of condition ``cond`` on graph ``g``: one per rule and round
    count, one without fusion, the centralised reference (``loaded``: scenarios by overrides,
    shared across calls)."""
    scen_name, scen_text = _scenario(g.scenario, base, label)
    common = {**g.overrides, g.pd_key: float(cond["pd"]), g.clutter_key: float(cond["clutter"])}
    plan: list[tuple[str, int | None, str, dict]] = []
    for rule in rules:
        if "rules" in cond and rule.name not in cond["rules"]:
            continue
        for L in rule.rounds or rounds:
            plan.append((rule.name, L, "twin", {**common, **rule.overrides,
                                                "network.rounds": L}))
    plan.append((NO_FUSION, None, "twin", {**common, "fusion.rule": "none"}))
    plan.append((CENTRALISED, None, "experiment", {**common, "fusion.rule": "none"}))
    for rule_name, L, runner, over in plan:
        key = (scen_name, json.dumps(over, sort_keys=True))
        try:
            if key not in loaded:
                loaded[key] = load_scenario(scenario_source(scen_name, scen_text),
                                            overrides=over)
        except (ScenarioError, ValueError) as exc:
            raise _fail(label, f"graph {g.name!r}, rule {rule_name!r}: {exc}") from None
        scn = loaded[key]
        peers = len(scn.sensors)
        limit = next((r.max_peers for r in rules if r.name == rule_name), None)
        if limit is not None and peers > limit:
            continue
        values = {"graph": g.name, "peers": peers, "rule": rule_name, "rounds": L,
                  "pd": float(cond["pd"]), "clutter": float(cond["clutter"])}
        cell_label = (f"{g.name} pd={cond['pd']} clutter={cond['clutter']} "
                      f"{rule_name}" + (f" L={L}" if L else ""))
        c = Cell(len(cells), cell_label, over, values, scenario=scen_name,
                 scenario_text=scen_text, runner=runner)
        c.hash = scenario_hash(scn)
        c.keys = [task_key(c.hash, runner, first + r, version) for r in range(g.runs)]
        cells.append(c)


# --------------------------------------------------------------------------------------------
# The table and the figures
# --------------------------------------------------------------------------------------------

def interval(x: np.ndarray) -> tuple[float, float]:
    """Mean and the half-width of its 95 % Student-t interval over the runs (nan for one run)."""
    # heavy dependency: scipy.stats (only the summary's intervals need it)
    from scipy.stats import t

    x = np.asarray(x, float)
    n = len(x)
    if n < 2:
        return float(x.mean()) if n else math.nan, math.nan
    return float(x.mean()), float(t.ppf(0.975, n - 1) * x.std(ddof=1) / math.sqrt(n))


def summarise(folder: Path) -> list[dict]:
    """One row per cell of the study in ``folder``: its values, runs, and each metric's mean
    and 95 % half-width over the runs (a cell's missing runs are reported, never averaged)."""
    manifest = json.loads((folder / "manifest.json").read_text())
    table = ResultStore(folder / "results").read().to_pylist()
    by_key = {r["key"]: r for r in table}
    out = []
    for cell in manifest["cells"]:
        rows = [by_key[k] for k in cell["keys"] if k in by_key]
        rec = {**cell["values"], "runs": len(rows), "runs_planned": len(cell["keys"])}
        if cell.get("runner") == "experiment":
            cols = {"fused_ospa": "mean_ospa.centralized",
                    "fused_card_error": "mean_card_error.centralized"}
        else:
            cols = {m: m for m in ("fused_ospa", "local_ospa", "fused_card_error",
                                   "local_card_error", "tuples_per_peer_scan",
                                   "bytes_per_peer_scan")}
        for name, col in cols.items():
            vals = np.array([r[col] for r in rows if r.get(col) is not None], float)
            rec[name], rec[f"{name}_ci"] = interval(vals) if len(vals) else (math.nan, math.nan)
        out.append(rec)
    return out


def _f(x: float, digits: int = 1) -> str:
    return "–" if x is None or not np.isfinite(x) else f"{x:.{digits}f}"


def format_markdown(rows: list[dict]) -> str:
    """The study's table: one line per (condition, graph, rule), the rounds side by side."""
    rounds = sorted({r["rounds"] for r in rows if r["rounds"]})
    head = ("| graph | peers | Pd | clutter | rule | "
            + " | ".join(f"fused OSPA L={L}" for L in rounds)
            + " | local OSPA | card. error (L=max) | tuples / peer / scan (L=max) | runs |")
    lines = [head, "|" + "---|" * 5 + "---:|" * (len(rounds) + 4)]
    groups: dict[tuple, list[dict]] = {}
    for r in rows:
        groups.setdefault((r["pd"], r["clutter"], r["graph"], r["peers"], r["rule"]),
                          []).append(r)
    for (pd, clutter, graph, peers, rule), rs in groups.items():
        by_l = {r["rounds"]: r for r in rs}
        last = by_l[max(by_l, key=lambda x: x or 0)]
        fused = [f"{_f(by_l[L]['fused_ospa'])} ± {_f(by_l[L]['fused_ospa_ci'])}"
                 if L in by_l else "" for L in rounds]
        if None in by_l:  # no fusion / centralised: one value, shown at L=1
            fused = [f"{_f(by_l[None]['fused_ospa'])} ± {_f(by_l[None]['fused_ospa_ci'])}"] + [
                ""] * (len(rounds) - 1)
        local = last.get("local_ospa", math.nan)
        lines.append(f"| {graph} | {peers} | {pd} | {clutter:g} | {rule} | " + " | ".join(fused)
                     + f" | {_f(local)} | {_f(last.get('fused_card_error', math.nan), 2)} | "
                     f"{_f(last.get('tuples_per_peer_scan', math.nan), 0)} | "
                     f"{min(r['runs'] for r in rs)}/{max(r['runs_planned'] for r in rs)} |")
    return "\n".join(lines) + "\n"


def plot(rows: list[dict], out: Path) -> list[Path]:
    """``fusion-study-rounds.png`` (OSPA against L per rule, a panel per graph, at the first
    condition) and ``fusion-study-cost.png`` (OSPA against tuples per peer per scan)."""
    plt = plt_module()

    out.mkdir(parents=True, exist_ok=True)
    first = (rows[0]["pd"], rows[0]["clutter"])
    base = [r for r in rows if (r["pd"], r["clutter"]) == first]
    graphs = list(dict.fromkeys(r["graph"] for r in base))
    rules = list(dict.fromkeys(r["rule"] for r in base if r["rounds"]))
    cols = min(4, len(graphs))
    nrows = math.ceil(len(graphs) / cols)
    fig, axes = plt.subplots(nrows, cols, figsize=(4.2 * cols, 3.4 * nrows), squeeze=False,
                             sharey=True)
    top = 1.05 * max((r["fused_ospa"] + np.nan_to_num(r["fused_ospa_ci"]) for r in base
                      if np.isfinite(r["fused_ospa"])), default=1.0)
    for ax, graph in zip(axes.flat, graphs, strict=False):
        g = [r for r in base if r["graph"] == graph]
        for rule in rules:
            rs = sorted((r for r in g if r["rule"] == rule), key=lambda r: r["rounds"])
            if rs:
                ax.errorbar([r["rounds"] for r in rs], [r["fused_ospa"] for r in rs],
                            yerr=[np.nan_to_num(r["fused_ospa_ci"]) for r in rs], marker="o",
                            capsize=3, label=rule)
        for name, style in ((NO_FUSION, ":"), (CENTRALISED, "--")):
            ref = [r for r in g if r["rule"] == name]
            if ref:
                ax.axhline(ref[0]["fused_ospa"], color="grey" if name == NO_FUSION else "k",
                           linestyle=style, label=f"{name} (no rounds)")
        ax.set_title(f"{graph} ({g[0]['peers']} peers)")
        ax.set_xlabel("consensus rounds L")
        ax.set_xticks(sorted({r["rounds"] for r in g if r["rounds"]}))
        ax.set_ylim(0, top)
    for ax in axes[:, 0]:
        ax.set_ylabel("mean fused OSPA (m)")
    for ax in list(axes.flat)[len(graphs):]:
        ax.set_visible(False)
    axes.flat[0].legend(fontsize=7)
    fig.suptitle(f"fused OSPA against rounds (Pd {first[0]}, clutter {first[1]:g}; "
                 "bars: 95 % interval over runs)")
    fig.tight_layout()
    p1 = out / "fusion-study-rounds.png"
    fig.savefig(p1, dpi=90)
    plt.close(fig)
    fig, ax = plt.subplots(figsize=(7, 4.5))
    markers = dict(zip(graphs, "osD^v<>ph*X", strict=False))
    colours = {rule: f"C{i}" for i, rule in enumerate(rules)}
    for r in base:
        if r["rounds"] and np.isfinite(r.get("tuples_per_peer_scan", np.nan)):
            ax.scatter(r["tuples_per_peer_scan"], r["fused_ospa"], color=colours[r["rule"]],
                       marker=markers.get(r["graph"], "o"), s=14 + 8 * r["rounds"], alpha=0.8)
    for rule, colour in colours.items():
        ax.scatter([], [], color=colour, label=rule)
    for graph, m in markers.items():
        ax.scatter([], [], color="grey", marker=m, label=graph)
    ax.set_xscale("log")
    ax.set_xlabel("tuples sent per peer per scan (log; 15 per 4-D component)")
    ax.set_ylabel("mean fused OSPA (m)")
    ax.set_ylim(bottom=0)
    ax.set_title("accuracy against communication (marker size: rounds L)")
    ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    p2 = out / "fusion-study-cost.png"
    fig.savefig(p2, dpi=90)
    plt.close(fig)
    return [p1, p2]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m sensornet.sim.studies.fusion.quality",
                                 description="the fusion-quality study's table and figures "
                                 "(run it with: sensornet campaign "
                                 "sim/campaigns/fusion-quality.toml --jobs 2)")
    sub = ap.add_subparsers(dest="cmd", required=True)
    rp = sub.add_parser("report", help="table (markdown) and figures of a study folder")
    rp.add_argument("folder")
    rp.add_argument("--md", help="write the table here too")
    rp.add_argument("--img", help="folder for the figures (default: FOLDER)")
    rp.add_argument("--csv", help="write one row per cell here")
    a = ap.parse_args(argv)
    folder = Path(a.folder)
    if not (folder / "manifest.json").is_file():
        print(f"{folder}: not a study folder (no manifest.json; run the campaign first)",
              file=sys.stderr)
        return 2
    rows = summarise(folder)
    text = format_markdown(rows)
    print(text)
    if a.md:
        Path(a.md).write_text(text)
    if a.csv:
        with open(a.csv, "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=list(rows[0]))
            w.writeheader()
            w.writerows(rows)
    for p in plot(rows, Path(a.img) if a.img else folder):
        print(f"wrote {p}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
