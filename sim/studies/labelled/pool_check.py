"""Several fused-track design variants against one baseline (issue 33, docs/labelled-tracking.md,
"Why the LMB's fused OSPA(2) is not <= 0.5 x its local"): per cell (graph, kind, Pd) each
variant's fused row of :func:`sim.studies.labelled.design_check.fused_row` (OSPA(2), its parts,
all-track and confirmed switches per 1,000 true target-scans, mean and worst peer; tuples and
the twin's CPU ms per peer-scan), with its ratio to the local and the centralised OSPA(2)
(:func:`sim.studies.labelled.ospa2_floor.cell`, computed once per cell), mean over runs (worst:
over runs too). The baseline is computed once per cell, not once per variant as
``design_check`` does. ``--variant "L2=network.rounds=2"``: two consensus rounds a scan.

``python -m sensornet.sim.studies.labelled.pool_check --runs 100,101 --kinds lmb
--variant "B=fusion.existence_prior=0.01;lmb.tentative_threshold=0.1" [--jobs 2]``
"""

from __future__ import annotations

import time
from concurrent.futures import ProcessPoolExecutor

import numpy as np
from sensornet.sim.studies.labelled.design_check import fused_row
from sensornet.sim.studies.labelled.ospa2_floor import GRAPHS, _overrides, cell, cell_arguments
from sensornet.sim.studies.labelled.study import RULES, scenario_of

COLUMNS = ("ospa2", "late+missed", "dup", "false+extra", "switches", "switches_max",
           "switches_confirmed", "switches_confirmed_max", "agreement_confirmed", "tuples",
           "cpu_ms")


def parse_variant(text: str) -> tuple[str, dict]:
    """``NAME=key=value;key=value`` -> ``(NAME, {key: value})`` (an empty set: the baseline)."""
    name, _, rest = text.partition("=")
    if not name:
        raise ValueError(f"a variant needs a name: NAME=key=value;..., got {text!r}")
    return name, _overrides([kv for kv in rest.split(";") if kv])


def _fused(args: tuple) -> dict[str, float]:
    g, kind, pd, scans, over, run = args
    return fused_row(scenario_of(GRAPHS[g], kind, pd, 10.0, scans, over), run)


def _reference(args: tuple) -> dict[str, float]:
    g, kind, pd, scans, rule, run = args
    out = cell(GRAPHS[g], kind, pd, run, scans, rule)
    return {"local": out["local"]["total"], "central": out["central"]["total"]}


def main(argv: list[str] | None = None) -> int:
    ap = cell_arguments("pool_check", __doc__, None, kinds="lmb")
    ap.add_argument("--base", default="", metavar="KEY=VALUE;...",
                    help="the baseline's overrides, under each variant's too (default: none)")
    ap.add_argument("--variant", action="append", default=[], metavar="NAME=KEY=VALUE;...",
                    help="a named variant's overrides of the fused twin's scenario")
    ap.add_argument("--no-base", action="store_true", help="skip the baseline rows")
    ap.add_argument("--no-reference", action="store_true",
                    help="skip the local and centralised reference")
    ap.add_argument("--jobs", type=int, default=1, help="processes (runs side by side)")
    a = ap.parse_args(argv)
    runs = [int(x) for x in a.runs.split(",")]
    base = _overrides([kv for kv in a.base.split(";") if kv])
    variants = [] if a.no_base else [("base", base)]
    variants += [(name, {**base, **over}) for name, over in map(parse_variant, a.variant)]
    t0 = time.perf_counter()
    print("| graph | kind | Pd | variant | " + " | ".join(COLUMNS) + " | / local | / central |")
    print("|---|---|---:|---|" + "---:|" * (len(COLUMNS) + 2))
    with ProcessPoolExecutor(max(1, a.jobs)) as pool:
        for g in a.graphs.split(","):
            for kind in a.kinds.split(","):
                for pd in (float(x) for x in a.pds.split(",")):
                    ref = None
                    if not a.no_reference:
                        refs = list(pool.map(_reference, [(g, kind, pd, a.scans, a.rule, r)
                                                          for r in runs]))
                        ref = {k: float(np.mean([x[k] for x in refs])) for k in refs[0]}
                    for name, over in variants:
                        rows = list(pool.map(_fused, [
                            (g, kind, pd, a.scans, {**RULES[a.rule], **over}, r) for r in runs]))
                        r = {c: float(np.max([x[c] for x in rows]) if c.endswith("_max")
                                      else np.mean([x[c] for x in rows])) for c in COLUMNS}
                        rat = ("| - | - |" if ref is None else
                               f"| {r['ospa2'] / ref['local']:.2f} | "
                               f"{r['ospa2'] / ref['central']:.2f} |")
                        print(f"| {g} | {kind} | {pd} | {name} | "
                              + " | ".join(f"{r[c]:.3g}" for c in COLUMNS) + " " + rat,
                              flush=True)
                    if ref is not None:
                        print(f"| {g} | {kind} | {pd} | (local {ref['local']:.1f}, "
                              f"centralised {ref['central']:.1f}) |", flush=True)
    print(f"\nruns {a.runs}, variants {dict(variants)}, {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
