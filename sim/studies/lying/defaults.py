"""Can the defence be on by default? Clean runs with ``fusion.trust`` off and on (issue 36 item 5).

The condition: on every shipped scenario the defence applies to (its peers fuse densities:
:attr:`sim.kinds.PeerKind.trust`) and on the lying study's graphs, the honest peers' fused
OSPA with the defence on within the 95 % interval of the mean with it off (mean ± 1.96 sd /
sqrt(runs), over the same runs), and honest quarantines (share of (peer, neighbour, scan)
triples a peer had a neighbour quarantined; every peer is honest here) at most 0.5 %.

    python -m sensornet.sim.studies.lying.defaults --runs 8 --first-run 7000

Nothing is chosen here: it measures the defence as it is.
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np
from sensornet.sim.run.twin import run_twin
from sensornet.sim.scenario import load_scenario
from sensornet.sim.studies.lying.study import _source

GRAPHS: dict[str, tuple[str, dict]] = {
    "seed000": ("seed000", {}),
    "seed002": ("seed002", {}),
    "paris": ("paris", {}),
    "paris-8": ("paris-8", {}),
    "seed001": ("seed001", {}),
    "seed004-gmphd": ("seed004", {"network.filter": "gmphd", "network.rounds": 1}),
    "circ4-20": ("circulant-20-4", {"network.rounds": 2}),
}
"""Label: (scenario, overrides). seed003 (PDA peers) and seed004 as shipped (flooding
peers) forward no density: the defence does not apply to them."""
LIMIT = 0.005
"""Largest share of honest quarantines (triples) the default may cost."""


def clean_run(name: str, overrides: dict, run: int, trust: bool) -> dict:
    """One clean twin run: the peers' mean fused OSPA and, with the defence, the quarantined
    share of (peer, neighbour, scan) triples."""
    scn = load_scenario(_source(name), overrides={**overrides, "fusion.trust": trust})
    t0 = time.perf_counter()
    res = run_twin(scn, run)
    fused = float(np.mean([p.mean_ospa("fused") for p in res.peers.values()]))
    seen = q = 0
    for p in res.peers.values():
        tr = p.consensus.trust
        for rec in (tr.n.values() if tr is not None else ()):
            seen += sum(rec.scans_in.values())
            q += rec.scans_in["quarantined"]
    return {"fused": fused, "quarantined": q / seen if seen else math.nan, "triples": seen,
            "seconds": time.perf_counter() - t0}


def measure(label: str, runs: range) -> dict:
    """Defence off and on over ``runs`` of graph ``label``: means, the off mean's 95 %
    interval and whether the on mean is inside it, the honest quarantines."""
    name, ov = GRAPHS[label]
    off = [clean_run(name, ov, r, False) for r in runs]
    on = [clean_run(name, ov, r, True) for r in runs]
    f_off = np.array([x["fused"] for x in off])
    f_on = np.array([x["fused"] for x in on])
    half = 1.96 * f_off.std(ddof=1) / math.sqrt(len(f_off)) if len(f_off) > 1 else math.inf
    q = float(sum(x["quarantined"] * x["triples"] for x in on)
              / max(sum(x["triples"] for x in on), 1))
    return {"graph": label, "runs": len(runs), "off": f_off.mean(), "half": half,
            "on": f_on.mean(), "inside": abs(f_on.mean() - f_off.mean()) <= half,
            "paired": float(np.mean(f_on - f_off)), "quarantined": q,
            "ok": abs(f_on.mean() - f_off.mean()) <= half and q <= LIMIT,
            "seconds": sum(x["seconds"] for x in off + on)}


def table(rows: list[dict]) -> str:
    lines = ["| graph | runs | fused off (95 % interval) | fused on | on - off (paired) | "
             "honest quarantines | met |", "|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['graph']} | {r['runs']} | {r['off']:.2f} ± {r['half']:.2f} | "
                     f"{r['on']:.2f} | {r['paired']:+.2f} | {100 * r['quarantined']:.2f} % | "
                     f"{'yes' if r['ok'] else 'no'} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m sensornet.sim.studies.lying.defaults",
                                description=__doc__.split("\n")[0])
    p.add_argument("--runs", type=int, default=8)
    p.add_argument("--first-run", type=int, default=7000)
    p.add_argument("--graphs", default=",".join(GRAPHS), help=", ".join(GRAPHS))
    a = p.parse_args(argv)
    rows = []
    for g in a.graphs.split(","):
        if g not in GRAPHS:
            p.error(f"unknown graph {g!r}; expected one of {', '.join(GRAPHS)}")
        rows.append(measure(g, range(a.first_run, a.first_run + a.runs)))
        print(rows[-1], flush=True)
    print(table(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
