"""Why honest peers are quarantined: per quarantine of a clean run, the check that fired, at
what scan, and the values that led to it (issue 36 item 5; docs/security.md "On by
default?").

Every peer is honest here, so every quarantine is a false alarm. For each (peer, neighbour)
and each scan at which the neighbour entered quarantine, the last ``--before`` scans'
round-0 statistic (the divergence test before the once-a-scan tests), score, the offset
test's values (chi-square per window, then its CUSUM) and the withheld-target CUSUM, and
the check that crossed its limit at the onset: ``withheld`` (the withheld-target CUSUM
above :attr:`TrustConfig.withhold_threshold`), ``offset`` (a window or the CUSUM above its
limit, registration off), else ``divergence`` (the score of the divergence test). How
long it stayed quarantined, and the share of triples.

    python -m sensornet.sim.studies.lying.quarantines seed001 --runs 4 --first-run 9000
"""

from __future__ import annotations

import argparse
from collections import defaultdict

from sensornet.peers.trust_record import alarm_limits
from sensornet.sim.run.peers import make_peer
from sensornet.sim.run.twin import run_twin
from sensornet.sim.scenario import load_scenario
from sensornet.sim.studies.lying.defaults import GRAPHS
from sensornet.sim.studies.lying.study import _source


def quarantines(label: str, run: int, before: int = 4) -> dict:
    """One clean run of graph ``label`` with the defence on: ``{"triples", "quarantined",
    "onsets"}``, each onset ``{"peer", "neighbour", "k", "check", "scans", "lead"}``,
    ``lead`` the last ``before`` scans' ``(k, statistic, score, values)``."""
    name, ov = GRAPHS[label]
    scn = load_scenario(_source(name), overrides={**ov, "fusion.trust": True})
    peers = {n: make_peer(scn, n, run) for n in scn.sensor_names}
    for p in peers.values():
        if p.consensus.trust is not None:
            p.consensus.trust.history, p.consensus.trust.trace = [], []
    run_twin(scn, run, peers=peers)
    out = {"triples": 0, "quarantined": 0, "onsets": []}
    for me, p in peers.items():
        tr = p.consensus.trust
        if tr is None:
            continue
        limits = alarm_limits(tr.cfg)
        rounds = defaultdict(dict)  # neighbour -> k -> (statistic, score, values), round 0
        for k, s, stat, score, values in tr.history:
            rounds[s].setdefault(k, (stat, score, values))
        states = defaultdict(list)
        for t in tr.trace:
            states[t["neighbour"]].append((t["k"], t["state"]))
        for s, seq in states.items():
            out["triples"] += len(seq)
            out["quarantined"] += sum(st == "quarantined" for _, st in seq)
            for i, (k, st) in enumerate(seq):
                if st != "quarantined" or (i and seq[i - 1][1] == "quarantined"):
                    continue
                n = next((j for j in range(i, len(seq)) if seq[j][1] != "quarantined"),
                         len(seq)) - i
                lead = [(a, *rounds[s][a]) for a in range(k - before + 1, k + 1)
                        if a in rounds[s]]
                out["onsets"].append({"peer": me, "neighbour": s, "k": k, "scans": n,
                                      "check": _check(tr.cfg, lead, limits), "lead": lead})
    return out


def _check(cfg, lead: list, limits: tuple[float, ...]) -> str:
    """Which check crossed its limit in the scans before an onset (module docstring)."""
    for _, _, _, values in reversed(lead):
        if not values:
            continue
        if cfg.withhold and len(values) == len(limits) and values[-1] > limits[-1]:
            return "withheld"
        offset = values[:-1] if cfg.withhold and len(values) == len(limits) else values
        if not cfg.register and any(v > t for v, t in zip(offset, limits, strict=False)):
            return "offset"
    return "divergence"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m sensornet.sim.studies.lying.quarantines",
                                description=__doc__.split("\n")[0])
    p.add_argument("graph", choices=list(GRAPHS))
    p.add_argument("--runs", type=int, default=4)
    p.add_argument("--first-run", type=int, default=9000)
    p.add_argument("--before", type=int, default=4, help="scans shown before each onset")
    a = p.parse_args(argv)
    total = q = 0
    checks: dict[str, int] = defaultdict(int)
    for r in range(a.first_run, a.first_run + a.runs):
        res = quarantines(a.graph, r, a.before)
        total, q = total + res["triples"], q + res["quarantined"]
        print(f"run {r}: {res['quarantined']} of {res['triples']} triples quarantined")
        for o in res["onsets"]:
            checks[o["check"]] += 1
            print(f"  {o['peer']} <- {o['neighbour']}: scan {o['k']}, {o['check']}, "
                  f"{o['scans']} scans")
            for k, stat, score, values in o["lead"]:
                vals = ", ".join(f"{v:.1f}" for v in values)
                print(f"    scan {k}: statistic {stat:.2f}, score {score:.2f}"
                      + (f", offset/withheld [{vals}]" if values else ""))
    share = q / total if total else float("nan")
    print(f"{a.graph}: {q} of {total} triples quarantined ({100 * share:.2f} %); onsets by "
          f"check: {dict(checks) or 'none'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
