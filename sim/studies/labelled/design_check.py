"""What a fused-track design variant does to the labelled study's guard metrics (issue 33,
docs/labelled-tracking.md, "Fused vs centralised: where the gap is"): per cell the fused
OSPA, OSPA(2), confirmed switches per 1,000 true target-scans (mean and worst peer), confirmed
label agreement and tuples per peer-scan, baseline (the rule's scenario) against the variant
(``--set`` overrides), mean over runs; :func:`sim.studies.labelled.study.twin_row`'s numbers.

``python -m sensornet.sim.studies.labelled.design_check --runs 100,101 --set fusion.support=2
[--graphs full3,circ20] [--kinds gmphd,lmb] [--pds 0.99,0.9] [--rule hybrid]``
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from sensornet.sim.studies.labelled.ospa2_floor import GRAPHS, _overrides
from sensornet.sim.studies.labelled.study import RULES, scenario_of, twin_row

COLUMNS = ("ospa", "ospa2", "switches_confirmed", "switches_confirmed_max",
           "agreement_confirmed", "delay", "tuples")


def check(graph: str, kind: str, pd: float, runs: list[int], rule: str, extra: dict,
          scans: int | None = None) -> dict[str, dict[str, float]]:
    """``{"base": row, "variant": row}``: each :data:`COLUMNS` value's mean over ``runs``
    (``switches_confirmed_max``: the worst over runs too)."""
    out = {}
    for name, over in (("base", RULES[rule]), ("variant", {**RULES[rule], **extra})):
        rows = [twin_row(scenario_of(GRAPHS[graph], kind, pd, 10.0, scans, over), r, "fused",
                         False) for r in runs]
        out[name] = {c: float(np.max([x[c] for x in rows]) if c.endswith("_max")
                              else np.mean([x[c] for x in rows])) for c in COLUMNS}
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m sensornet.sim.studies.labelled.design_check",
                                 description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs", default="100,101", help="runs (training: 100, 101)")
    ap.add_argument("--scans", type=int, help="scans per run (default: the scenario's)")
    ap.add_argument("--graphs", default="full3,circ20")
    ap.add_argument("--kinds", default="gmphd,lmb")
    ap.add_argument("--pds", default="0.99,0.9")
    ap.add_argument("--rule", default="hybrid", choices=sorted(RULES))
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help="the variant's overrides of the fused twin's scenario")
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
