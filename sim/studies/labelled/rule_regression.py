"""Which LMB default moved the GCI and AA rules (issue 33, docs/labelled-tracking.md, "The GCI
and AA rules under the LMB defaults"): per rule, Pd and named variant (a set of scenario
overrides; the first, ``base``, none) the fused OSPA, OSPA(2) and every part of it
(:func:`sim.studies.labelled.ospa2_floor.ospa2_parts`: late, missed, gap, dup, loc, false,
extra), mean over peers and runs, and each run's OSPA(2), so variants compare run by run.
Runs the same in a checkout of an older commit (it imports only what b58e150 has), which is
how a default that ``--set`` cannot turn off is bisected.

``python -m sensornet.sim.studies.labelled.rule_regression --runs 100,101,102,103
--rules gci,aa --pds 0.99,0.9 --variant "mature0=fusion.existence_mature=0"
[--graph full3] [--kind lmb] [--scans N]``
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from sensornet.sim.run.twin import run_twin
from sensornet.sim.studies.labelled.ospa2_floor import GRAPHS, _overrides, ospa2_parts
from sensornet.sim.studies.labelled.study import (
    RULES,
    WINDOW,
    peer_tables,
    scenario_of,
    truth_table,
)
from sensornet.sim.world import generate_run

PARTS = ("late", "missed", "gap", "dup", "loc", "false", "extra")
COLUMNS = ("ospa", "ospa2", *PARTS)


def parse_variant(text: str) -> tuple[str, dict]:
    """``NAME=key=value;key=value`` -> ``(NAME, {key: value})``; a bad one: a one-line
    ValueError."""
    name, _, rest = text.partition("=")
    if not name or (rest and "=" not in rest):
        raise ValueError(f"a variant is NAME=key=value;..., got {text!r}")
    return name, _overrides([kv for kv in rest.split(";") if kv])


def fused_parts(scn, run: int) -> dict[str, float]:
    """One twin run's fused OSPA and OSPA(2) parts, mean over peers."""
    twin = run_twin(scn, run)
    names = scn.sensor_names
    truth, _ = generate_run(scn, run)
    T = truth_table(truth)
    tabs = peer_tables(twin, names, "fused", {})
    grid = np.arange(1, scn.num_scans + 1)
    c, p = scn.metrics.ospa_cutoff, scn.metrics.ospa_order
    parts = [ospa2_parts(T, t, c, p, WINDOW, grid) for t in tabs.values()]
    out = {k: float(np.mean([x[k] for x in parts])) for k in (*PARTS, "total")}
    out["ospa2"] = out.pop("total")
    out["ospa"] = float(np.mean([twin.mean_ospa(q, "fused") for q in names]))
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m sensornet.sim.studies.labelled.rule_regression",
                                 description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs", default="100,101,102,103", help="training runs (100 on)")
    ap.add_argument("--graph", default="full3", choices=sorted(GRAPHS))
    ap.add_argument("--kind", default="lmb")
    ap.add_argument("--rules", default="gci,aa")
    ap.add_argument("--pds", default="0.99,0.9")
    ap.add_argument("--scans", type=int, default=None)
    ap.add_argument("--variant", action="append", default=[], metavar="NAME=KEY=VALUE;...")
    ap.add_argument("--no-base", action="store_true", help="skip the baseline (no overrides)")
    a = ap.parse_args(argv)
    try:
        runs = [int(x) for x in a.runs.split(",")]
        pds = [float(x) for x in a.pds.split(",")]
        variants = ([] if a.no_base else [("base", {})]) + [parse_variant(v) for v in a.variant]
    except ValueError as e:
        ap.error(str(e))
    rules = a.rules.split(",")
    if bad := [r for r in rules if r not in RULES]:
        ap.error(f"unknown rule(s) {bad}; known: {sorted(RULES)}")
    t0 = time.perf_counter()
    print("| rule | Pd | variant | " + " | ".join(COLUMNS) + " | OSPA(2) per run |")
    print("|---|---:|---|" + "---:|" * len(COLUMNS) + "---|")
    for rule in rules:
        for pd in pds:
            for name, over in variants:
                rows = [fused_parts(scenario_of(GRAPHS[a.graph], a.kind, pd, 10.0, a.scans,
                                                {**RULES[rule], **over}), r) for r in runs]
                mean = {c: float(np.mean([x[c] for x in rows])) for c in COLUMNS}
                print(f"| {rule} | {pd} | {name} | "
                      + " | ".join(f"{mean[c]:.2f}" for c in COLUMNS) + " | "
                      + " ".join(f"{x['ospa2']:.1f}" for x in rows) + " |", flush=True)
    print(f"\n{a.graph} {a.kind}, runs {a.runs}, variants {dict(variants)}, "
          f"{time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
