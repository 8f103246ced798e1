"""A member lying about its own estimate, on the twin (docs/security.md, "What is not protected").

A member with a valid key may publish any well-formed estimate under its own name: the core's
checks (codec, dimensions, windows, rates) and secure mode pass it, and the neighbours fuse it.
This module measures what that costs the *honest* peers under each fusion rule. It is a test
and experiment hook of the twin only, not a network feature: :class:`LyingCore` is the liar's
:class:`peers.core.PeerCore` with every outgoing :class:`~protocol.messages.Estimate` replaced
by a lie just before it is encoded. The liar's own filter and fusion run on its real data; only
what it tells its neighbours is wrong (every round's estimate, when there are several rounds).

The lies (:data:`LIES`), each a well-formed message the core accepts:

- ``empty``: a mixture with no components ("there is nothing");
- ``shifted``: every component's position moved by :data:`SHIFT` metres along x, with a tight
  covariance (:data:`TIGHT` on every state variance): a confident wrong estimate;
- ``inflated``: the real estimate with every weight times :data:`INFLATE` (phantom mass);
- ``phantoms``: the real estimate plus three components of weight 1 at fixed points inside the
  region (10 % in from three of its corners), at rest, with the tight covariance.

``python -m sensornet.sim.studies.lying.study [--runs N] [--first-run R] [--out DIR]`` runs every
lie and the
clean run
under each GM-PHD fusion rule (:data:`RULES`) on seed 000 (3 peers, ``s2`` lies) and on the
seed-004 graph with GM-PHD peers (20 peers, one round, ``s15`` lies: 14 honest neighbours),
prints a markdown table of the honest peers' mean fused OSPA (their local OSPA, which no lie can
touch, is the no-fusion baseline) and writes ``lying-runs.csv``, ``lying-summary.csv`` and
``lying.png`` into ``--out`` (default ``runs/lying``). With the defence on (``+trust`` rules) it
also prints, per cell, the scans until every honest neighbour has the liar at weight <= 0.1 and
the share of (honest peer, honest neighbour, scan) triples in quarantine. ``--lies absent``
takes the liars' sensors out of the network instead: the best any defence that leaves a liar
out can give with the rule at hand; ``--lies central`` processes the honest sensors' scans
centrally (offline, the iterated-corrector GM-PHD of :mod:`sim.studies.seed000.montecarlo`): what
their
measurements can give, the reference for whether an *absent* cell's gap is the information's
or the fusion design's. Missing output is scored as a miss (the
scorer's cut-off), never dropped. The default runs 7000.. are used by nothing else: no setting
here was chosen on them. One run and its scores: :mod:`.scores`.
"""

from __future__ import annotations

import argparse
import csv
import math
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from sensornet.sim.report.report_plots import plt_module
from sensornet.sim.run.lies import (  # noqa: F401  (the lies live in sim.run.lies; named here as before)
    BIAS,
    INFLATE,
    LIES,
    SHIFT,
    TIGHT,
    Lie,
    LyingCore,
    make_lie,
    phantom_positions,
)
from sensornet.sim.run.pool import map_runs
from sensornet.sim.scenario import Scenario, ScenarioError, load_scenario
from sensornet.sim.studies.base import Outcome, Request, Study, experiment
from sensornet.sim.studies.lying.scores import (  # noqa: F401  (named here as before)
    ABSENT,
    CENTRAL,
    central_scores,
    honest_scores,
    run_with_liar,
    trust_scores,
    without,
)
from sensornet.sim.world.graphs import network_scenario


@dataclass(frozen=True)
class Setup:
    """A scenario to lie in: its name, overrides and the liar."""

    label: str
    scenario: str
    overrides: dict
    liar: str


SETUPS = (
    Setup("seed000", "seed000", {}, "s2"),
    Setup("seed004-gmphd", "seed004", {"network.filter": "gmphd", "network.rounds": 1}, "s15"),
    Setup("seed004-gmphd-2", "seed004", {"network.filter": "gmphd", "network.rounds": 1},
          "s15,s19"),
)
"""seed 000: 3 peers in a full mesh (s2 has 2 honest neighbours, Metropolis weight 1/3 each).
seed 004 with GM-PHD peers, one consensus round (four rounds fuse worse than one there, clean:
19.4 m against 11.3 m, run 0): s15 has the highest degree, 14 of the 19 honest peers; with
two liars s19 (degree 13) lies too."""

CIRCULANT = Setup("circ4-20", "circulant-20-4", {"network.rounds": 2}, "p05")
"""The 20-peer circulant graph of degree 4 of the trust calibration (seed 000's targets and
sensors, :func:`sim.world.graphs.network_scenario`, two rounds), p05 lying: not in the default
study (``--setups circ4-20``)."""
ALL_SETUPS = (*SETUPS, CIRCULANT)


def _source(name: str) -> str:
    """A built-in scenario's name, or for ``circulant-N-D`` the path of its generated file
    (written once per machine, atomically: parallel workers may race to write it)."""
    if not name.startswith("circulant-"):
        return name
    n, d = (int(x) for x in name.split("-")[1:])
    path = Path(tempfile.gettempdir()) / f"sensornet-lying-{name}.toml"
    text = network_scenario(n, d)
    if not path.is_file() or path.read_text(encoding="utf-8") != text:
        tmp = path.with_suffix(f".{os.getpid()}.tmp")
        tmp.write_text(text, encoding="utf-8")
        os.replace(tmp, path)
    return str(path)


_OFF = {"fusion.trust": False}
"""The undefended rules pin the defence off (on by default since issue 36 item 5)."""
_EXCLUDE = {"fusion.trust": True, "fusion.trust_register": False, "fusion.trust_repair": False}
RULES: dict[str, dict] = {
    "default": {},
    "hybrid": {"fusion.rule": "hybrid", **_OFF},
    "hybrid+trust": {"fusion.rule": "hybrid", "fusion.trust": True},
    "hybrid+exclude": {"fusion.rule": "hybrid", **_EXCLUDE},
    "gci": {"fusion.rule": "gci", **_OFF},
    "gci+trust": {"fusion.rule": "gci", "fusion.trust": True},
    "gci+exclude": {"fusion.rule": "gci", **_EXCLUDE},
    "hybrid+register": {"fusion.rule": "hybrid", **_EXCLUDE, "fusion.trust_register": True},
    "gci+register": {"fusion.rule": "gci", **_EXCLUDE, "fusion.trust_register": True},
    "hybrid+repair": {"fusion.rule": "hybrid", "fusion.trust": True,
                      "fusion.trust_register": True, "fusion.trust_repair": True},
    "gci+repair": {"fusion.rule": "gci", "fusion.trust": True, "fusion.trust_register": True,
                   "fusion.trust_repair": True},
    "hybrid+trust+feedback": {"fusion.rule": "hybrid", "fusion.trust": True,
                              "network.feedback": True},
    "gci-emd": {"fusion.rule": "gci", "fusion.cardinality": "emd", **_OFF},
    "gci-chernoff": {"fusion.rule": "gci", "network.omega": "chernoff", **_OFF},
    "aa": {"fusion.rule": "aa", **_OFF},
    "aa+trust": {"fusion.rule": "aa", "fusion.trust": True},
}
"""The GM-PHD peers' fusion rules, each without and (``+trust``) with the neighbour defence
of :mod:`peers.trust` as it is by default (the test, registration of offsets and repair of
densities that still carry the liar's measurements); ``+exclude``: the test with neither
(a failing neighbour is only down-weighted and quarantined); ``+register``: with
registration only; ``+repair``: registration and repair named explicitly (= ``+trust``);
``hybrid+trust+feedback``: the defence with every peer's fused density as its next prior
(``network.feedback``; not under GCI, whose product with fed-back priors loses every track
on seed 000: 161 m clean, no liar); ``default``: no override (the scenario as shipped:
the hybrid with the defence, on by default since issue 36 item 5; the rules without
``+trust`` pin it off). The rules: the hybrid (the default), GCI with
Metropolis weights and the cardinality fused apart, GCI with the exact Poisson EMD mass,
GCI with each pair's weight chosen at the Chernoff point, and the arithmetic average (AA)."""


def scenario_for(setup: Setup, rule: str, scans: int | None = None) -> Scenario:
    ov = {**setup.overrides, **RULES[rule]}
    if scans is not None:
        ov["scenario.num_scans"] = scans
    return load_scenario(_source(setup.scenario), overrides=ov)


def lie_once(scn: Scenario, run: int, setup: Setup, rule: str, lie: str) -> dict:
    """One row: run ``run`` of ``scn`` with ``setup``'s liar telling ``lie`` (``"clean"``: none)."""
    if lie == CENTRAL:
        return {"setup": setup.label, "liar": setup.liar, "rule": rule, "lie": lie, "run": run,
                **central_scores(without(scn, setup.liar), run)}
    if lie == ABSENT:
        res = run_with_liar(without(scn, setup.liar), run, "", None)
    else:
        res = run_with_liar(scn, run, setup.liar, None if lie == "clean" else lie)
    return {"setup": setup.label, "liar": setup.liar, "rule": rule, "lie": lie, "run": run,
            **honest_scores(res, setup.liar)}


def measure(setups=SETUPS, rules=tuple(RULES), lies=LIES, runs: int = 5, first_run: int = 7000,
            scans: int | None = None, progress: bool = True, jobs: int = 1) -> list[dict]:
    """One row per setup, rule, lie (``"clean"`` for none) and run, in that order."""
    calls = [(scn, r, setup, rule, lie) for setup in setups for rule in rules
             for scn in [scenario_for(setup, rule, scans)] for lie in ("clean", *lies)
             for r in range(first_run, first_run + runs)]
    return map_runs(lie_once, calls, jobs, "twin runs (graph x rule x lie x run)", progress)


@dataclass(frozen=True)
class Plan:
    """The lying study's cells: graphs with their liars, rules, lies, scans per run."""

    setups: tuple[Setup, ...] = SETUPS
    rules: tuple[str, ...] = tuple(RULES)
    lies: tuple[str, ...] = LIES
    scans: int | None = None


def plan_of(req: Request) -> list[Plan]:
    """``options``: ``setups`` and ``rules`` (names), ``scans``; unknown names are refused."""
    o = req.options
    setups = tuple(s for s in ALL_SETUPS
                   if s.label in o.get("setups", [s.label for s in SETUPS]))
    rules = tuple(o.get("rules", RULES))
    lies = tuple(o.get("lies", LIES))
    if not setups or any(r not in RULES for r in rules) or any(
            lie not in (*LIES, ABSENT, CENTRAL) for lie in lies):
        raise ScenarioError("lying: need a known setup, known rules and known lies")
    return [Plan(setups, rules, lies, o.get("scans"))]


def run_plan(plan: Plan, run: int) -> list[dict]:
    """Run ``run`` of every cell (graph, rule, lie)."""
    return [lie_once(scenario_for(s, rule, plan.scans), run, s, rule, lie)
            for s in plan.setups for rule in plan.rules for lie in ("clean", *plan.lies)]


def summarise_plan(plan: Plan, per_run: list[list[dict]]) -> tuple[list[dict], list[dict]]:
    """``(rows, summary)``: the rows cell by cell (as :func:`measure` gives them)."""
    rows = [row for i in range(len(per_run[0])) for row in (run[i] for run in per_run)]
    return rows, summarise(rows)


def table(o: Outcome) -> str:
    plan, runs = o.setup, o.runs
    return (f"Honest peers' mean OSPA over {len(runs)} runs ({runs.start}..{runs.stop - 1}); "
            "liars: " + ", ".join(f"{s.label} {s.liar}" for s in plan.setups) + "\n\n"
            + markdown(o.summary[1]) + "\n\nCompact (honest peers' fused OSPA, m, mean ± sd "
            "over runs):\n\n" + compact(o.summary[1]) + "\n\nThe defence (rules with "
            "+trust): scans to detect the liar (weight <= 0.1; the worst honest neighbour and "
            "run) / honest neighbours quarantined (% of (peer, neighbour, scan)); caught: "
            "scans until its density is no longer fused as told (weight <= 0.1 or repaired); "
            "honest held: % of honest neighbours' rounds at weight 0 by the withheld-target "
            "hold:\n\n"
            + defence(o.summary[1]))


def summarise(rows: list[dict]) -> list[dict]:
    """Mean and spread over runs per setup, rule and lie, with the change from the clean run."""
    keys = list(dict.fromkeys((r["setup"], r["rule"], r["lie"]) for r in rows))
    out = []
    for setup, rule, lie in keys:
        sel = [r for r in rows if (r["setup"], r["rule"], r["lie"]) == (setup, rule, lie)]
        clean = [r for r in rows if (r["setup"], r["rule"], r["lie"]) == (setup, rule, "clean")]
        f = np.array([r["fused"] for r in sel])
        row = {"setup": setup, "rule": rule, "lie": lie, "runs": len(sel),
               "fused": f.mean(), "fused_sd": f.std(ddof=1) if len(f) > 1 else 0.0,
               "fused_min": f.min(), "fused_max": f.max(),
               "fused_neighbours": np.mean([r["fused_neighbours"] for r in sel]),
               "local": np.mean([r["local"] for r in sel]),
               "clean": np.mean([r["fused"] for r in clean]) if clean else math.nan,
               "rejected": sum(r["rejected"] for r in sel),
               "honest_quarantined": np.mean([r["honest_quarantined"] for r in sel]),
               "detect_scans": np.max([r["detect_scans"] for r in sel]),
               "caught_scans": np.max([r.get("caught_scans", math.nan) for r in sel]),
               "honest_held": np.mean([r.get("honest_held", math.nan) for r in sel]),
               "repair_scans": np.max([r.get("repair_scans", math.nan) for r in sel]),
               "liar_repaired": np.mean([r.get("liar_repaired", math.nan) for r in sel]),
               "honest_repaired": np.mean([r.get("honest_repaired", math.nan) for r in sel])}
        row["change"] = row["fused"] - row["clean"]
        out.append(row)
    return out


def markdown(summary: list[dict]) -> str:
    lines = ["| graph | rule | lie | honest fused OSPA (m), mean ± sd [min, max] | vs clean | "
             "liar's neighbours, fused | honest local (no fusion) |",
             "|---|---|---|---|---|---|---|"]
    for s in summary:
        change = "" if s["lie"] == "clean" else f"{s['change']:+.1f}"
        lines.append(f"| {s['setup']} | {s['rule']} | {s['lie']} | {s['fused']:.1f} ± "
                     f"{s['fused_sd']:.1f} [{s['fused_min']:.1f}, {s['fused_max']:.1f}] | "
                     f"{change} | {s['fused_neighbours']:.1f} | {s['local']:.1f} |")
    return "\n".join(lines)


def compact(summary: list[dict]) -> str:
    """The same means as one row per graph and rule, one column per lie (± the sd over runs)."""
    lies = list(dict.fromkeys(s["lie"] for s in summary))
    lines = ["| graph | rule | " + " | ".join(lies) + " | honest local |",
             "|---|---|" + "---|" * (len(lies) + 1)]
    for setup, rule in dict.fromkeys((s["setup"], s["rule"]) for s in summary):
        sel = {s["lie"]: s for s in summary if (s["setup"], s["rule"]) == (setup, rule)}
        cells = [f"{sel[lie]['fused']:.1f} ± {sel[lie]['fused_sd']:.1f}" if lie in sel else ""
                 for lie in lies]
        local = np.mean([s["local"] for s in sel.values()])
        lines.append(f"| {setup} | {rule} | " + " | ".join(cells) + f" | {local:.1f} |")
    return "\n".join(lines)


def defence(summary: list[dict]) -> str:
    """Per graph and rule with the defence on, per lie: the scans to detect (the worst
    neighbour and run; "never" if one did not) and the honest quarantines (% of triples);
    with repair, the scans to the liar's first repair and the share of its rounds repaired
    (clean: the share of honest neighbours' rounds repaired)."""
    sel_all = [s for s in summary if not math.isnan(s["honest_quarantined"])]
    lies = list(dict.fromkeys(s["lie"] for s in sel_all))
    lines = ["| graph | rule | " + " | ".join(lies) + " |", "|---|---|" + "---|" * len(lies)]
    for setup, rule in dict.fromkeys((s["setup"], s["rule"]) for s in sel_all):
        sel = {s["lie"]: s for s in sel_all if (s["setup"], s["rule"]) == (setup, rule)}
        cells = []
        for lie in lies:
            if lie not in sel:
                cells.append("")
                continue
            d = sel[lie]["detect_scans"]
            det = "–" if lie == "clean" else ("never" if math.isnan(d) else f"{d:.0f}")
            cell = f"{det} / {100 * sel[lie]['honest_quarantined']:.2f} %"
            c, h = sel[lie].get("caught_scans", math.nan), sel[lie].get("honest_held")
            if lie != "clean" and not (math.isnan(c) and math.isnan(d)):
                cell += f"; caught {'never' if math.isnan(c) else f'{c:.0f}'}"
            if h is not None and not math.isnan(h):
                cell += f"; honest held {100 * h:.2f} %"
            if not math.isnan(sel[lie]["honest_repaired"]):  # with repair
                r = sel[lie]["repair_scans"]
                cell += (f"; honest repaired {100 * sel[lie]['honest_repaired']:.1f} %"
                         if lie == "clean" else
                         f"; repaired {'never' if math.isnan(r) else f'{r:.0f}'}, "
                         f"{100 * sel[lie]['liar_repaired']:.0f} % of rounds")
            cells.append(cell)
        lines.append(f"| {setup} | {rule} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def write(rows: list[dict], summary: list[dict], folder: Path) -> list[Path]:
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for name, data in (("lying-runs.csv", rows), ("lying-summary.csv", summary)):
        path = folder / name
        with path.open("w", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=list(data[0]))
            w.writeheader()
            w.writerows(data)
        paths.append(path)
    paths.append(_plot(summary, folder / "lying.png"))
    return paths


def _plot(summary: list[dict], path: Path) -> Path:
    plt = plt_module()

    setups = list(dict.fromkeys(s["setup"] for s in summary))
    fig, axes = plt.subplots(len(setups), 1, figsize=(9, 3.6 * len(setups)), squeeze=False)
    for ax, setup in zip(axes[:, 0], setups, strict=True):
        sel = [s for s in summary if s["setup"] == setup]
        rules = list(dict.fromkeys(s["rule"] for s in sel))
        lies = list(dict.fromkeys(s["lie"] for s in sel))
        width = 0.8 / len(lies)
        x = np.arange(len(rules))
        for j, lie in enumerate(lies):
            vals = [next(s for s in sel if s["rule"] == r and s["lie"] == lie) for r in rules]
            ax.bar(x + (j - (len(lies) - 1) / 2) * width, [v["fused"] for v in vals], width,
                   yerr=[v["fused_sd"] for v in vals], capsize=2, label=lie)
        local = np.mean([s["local"] for s in sel])
        ax.axhline(local, color="k", ls="--", lw=1, label="honest local (no fusion)")
        ax.set_xticks(x, rules)
        ax.set_ylabel("honest peers' fused OSPA (m)")
        ax.set_title(f"{setup}: one peer ({_liar(setup)}) lies, "
                     f"{sel[0]['runs']} runs")
        ax.grid(axis="y", alpha=0.3)
        ax.legend(fontsize=7, ncol=3)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def _liar(label: str) -> str:
    return next((s.liar for s in SETUPS if s.label == label), "?")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(
        prog="python -m sensornet.sim.studies.lying.study", description=__doc__.split("\n")[0])
    p.add_argument("--runs", type=int, default=5, help="Monte Carlo runs per cell (default 5)")
    p.add_argument("--first-run", type=int, default=7000,
                   help="first run index (default 7000: runs no tuning used)")
    p.add_argument("--out", type=Path, default=Path("runs/lying"))
    p.add_argument("--setups", default=",".join(s.label for s in SETUPS),
                   help="comma-separated: " + ", ".join(s.label for s in ALL_SETUPS)
                        + f" (default: all but {CIRCULANT.label})")
    p.add_argument("--rules", default=",".join(RULES), help="comma-separated: " + ", ".join(RULES))
    p.add_argument("--scans", type=int, default=None, help="scans per run (default: scenario's)")
    p.add_argument("--jobs", type=int, default=1, help="worker processes (default 1)")
    p.add_argument("--lies", default=",".join(LIES),
                   help=f"comma-separated, of: {', '.join(LIES)}, {ABSENT} (the liars' sensors "
                        "taken out: the best a defence that leaves them out can give with "
                        f"this fusion), {CENTRAL} (the honest sensors' scans processed "
                        "centrally, offline: what their measurements can give)")
    a = p.parse_args(argv)
    req = Request("lying", runs=a.runs, jobs=max(a.jobs, 1), first_run=a.first_run, out=a.out,
                  options={"setups": a.setups.split(","), "lies": a.lies.split(","),
                           "rules": [r for r in a.rules.split(",") if r], "scans": a.scans})
    try:
        plans = plan_of(req)
    except ScenarioError:
        plans = []
    if a.runs < 1 or not plans:
        p.error("need --runs >= 1, a known setup and known rules")
    experiment(STUDY, req, plans)
    return 0


STUDY = Study(
    name="lying", about="a member lying about its estimate: what each rule costs the honest",
    load=plan_of, run_once=run_plan, summarise=summarise_plan, table=table,
    figures=lambda o, folder: write(*o.summary, folder), label=lambda plan: "twin runs "
    "(every graph, rule and lie)")


if __name__ == "__main__":
    raise SystemExit(main())
