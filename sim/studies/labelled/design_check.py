"""What a fused-track design variant does (issue 33, docs/labelled-tracking.md, "Fused vs
centralised: where the gap is"): per cell the fused OSPA, OSPA(2) and its parts
(:mod:`sim.studies.labelled.ospa2_floor`), confirmed switches per 1,000 true target-scans
(mean and worst peer), confirmed label agreement, mean scans to a first confirmed track and
tuples per peer-scan, baseline (the rule's scenario) against the variant (``--set``
overrides), mean over peers and runs; the guard metrics as
:func:`sim.studies.labelled.study.twin_row` computes them.

``python -m sensornet.sim.studies.labelled.design_check --runs 100,101 --set fusion.support=2
[--graphs full3,circ20] [--kinds gmphd,lmb] [--pds 0.99,0.9] [--rule hybrid]``
"""

from __future__ import annotations

import time

import numpy as np
from sensornet.sim.campaign.sweep import cost_columns
from sensornet.sim.run.twin import run_twin
from sensornet.sim.studies.labelled.ospa2_floor import (
    GRAPHS,
    _overrides,
    cell_arguments,
    ospa2_parts,
)
from sensornet.sim.studies.labelled.study import (
    RULES,
    WINDOW,
    peer_tables,
    scenario_of,
    track_columns,
    truth_table,
)
from sensornet.sim.world import generate_run
from sensornet.tracking.track_metrics import label_agreement

COLUMNS = ("ospa", "ospa2", "late+missed", "gap", "dup", "false+extra", "switches_confirmed",
           "switches_confirmed_max", "agreement_confirmed", "delay", "tuples")


def fused_row(scn, run: int, peers: dict | None = None) -> dict[str, float]:
    """One twin run's fused row: :func:`sim.studies.labelled.study.twin_row`'s guard
    metrics and :mod:`sim.studies.labelled.ospa2_floor`'s parts (mean over peers), and the
    twin's CPU ms per peer-scan (``cpu_ms``, as ``twin_row``'s: what more rounds cost).
    ``peers``: the twin's peer cores, if not the scenario's (e.g. one that lies)."""
    c0 = time.process_time()
    twin = run_twin(scn, run, peers=peers)
    cpu = time.process_time() - c0
    names = scn.sensor_names
    truth, _ = generate_run(scn, run)
    T = truth_table(truth)
    code: dict = {}
    tabs = peer_tables(twin, names, "fused", code)
    conf = peer_tables(twin, names, "fused", code, confirmed=True)
    c, p = scn.metrics.ospa_cutoff, scn.metrics.ospa_order
    grid = np.arange(1, scn.num_scans + 1)
    parts = [ospa2_parts(T, t, c, p, WINDOW, grid) for t in tabs.values()]
    part = {k: float(np.mean([x[k] for x in parts])) for k in parts[0]}
    return {"ospa": float(np.mean([twin.mean_ospa(q, "fused") for q in names])),
            **track_columns(T, tabs, scn, False, conf),
            "late+missed": part["late"] + part["missed"], "gap": part["gap"],
            "dup": part["dup"], "false+extra": part["false"] + part["extra"],
            "agreement_confirmed": label_agreement(conf, T, gate=c)["agreement"],
            "tuples": cost_columns([q.cost() for q in twin.peers.values()])[
                "tuples_per_peer_scan"],
            "cpu_ms": 1e3 * cpu / (len(names) * scn.num_scans)}


def check(graph: str, kind: str, pd: float, runs: list[int], rule: str, extra: dict,
          scans: int | None = None) -> dict[str, dict[str, float]]:
    """``{"base": row, "variant": row}``: each :data:`COLUMNS` value's mean over ``runs``
    (``switches_confirmed_max``: the worst over runs too)."""
    out = {}
    for name, over in (("base", RULES[rule]), ("variant", {**RULES[rule], **extra})):
        rows = [fused_row(scenario_of(GRAPHS[graph], kind, pd, 10.0, scans, over), r)
                for r in runs]
        out[name] = {c: float(np.max([x[c] for x in rows]) if c.endswith("_max")
                              else np.mean([x[c] for x in rows])) for c in COLUMNS}
    return out


def main(argv: list[str] | None = None) -> int:
    ap = cell_arguments("design_check", __doc__,
                        "the variant's overrides of the fused twin's scenario")
    a = ap.parse_args(argv)
    extra = _overrides(a.set)
    runs = [int(x) for x in a.runs.split(",")]
    t0 = time.perf_counter()
    print("| graph | kind | Pd | estimate | " + " | ".join(COLUMNS) + " |")
    print("|---|---|---:|---|" + "---:|" * len(COLUMNS))
    for g in a.graphs.split(","):
        for kind in a.kinds.split(","):
            for pd in (float(x) for x in a.pds.split(",")):
                res = check(g, kind, pd, runs, a.rule, extra, a.scans)
                for name, r in res.items():
                    print(f"| {g} | {kind} | {pd} | {name} | "
                          + " | ".join(f"{r[c]:.3g}" for c in COLUMNS) + " |", flush=True)
    print(f"\nruns {a.runs}, variant {extra}, {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
