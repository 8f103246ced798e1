"""The LMB peers' label holder masks (``peers.label_support.LabelSupport``) against a git
revision's, on the 50-peer twin (issue 33).

Runs the twin of ``bench_fifty.py --twin --kinds lmb`` (50 peers, degree 4, L = 2, the host's
shared decode and batched fusions) alternately with this tree's ``LabelSupport`` and with
``--against REV``'s methods swapped in (REV at or after 99526bc: masks as words), the world's run
generated once outside the timed part. Prints each pair's CPU ms per peer-scan, the medians and
the pairs' ratios, both sides' mean fused OSPA and whether every peer's results table (fused
and local states, track ids, OSPA per scan) is the same. One process, so both sides share the
interpreter, the imports and the machine's minutes.

    python benchmarks/bench_label_support.py --against 99526bc
    python benchmarks/bench_label_support.py --against 99526bc --pairs 4 --scans 100
"""

from __future__ import annotations

import argparse
import os
import pickle
import statistics
import subprocess
import sys
import tempfile
import time
import types
from pathlib import Path

if not __package__:  # `python benchmarks/bench_label_support.py`: the repository root importable
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from sensornet.peers.host import SharedDecode
from sensornet.peers.label_support import LabelSupport
from sensornet.sim.run.peers import make_peer
from sensornet.sim.run.twin import run_twin
from sensornet.sim.scenario import load_scenario, parse_overrides
from sensornet.sim.world import generate_run

from benchmarks.bench_label_memory import module_at, use
from benchmarks.bench_network import load_average, scenario_text


def method_sets(rev: str) -> dict[str, dict[type, dict[str, object]]]:
    """``{"now": ..., "rev": ...}``: LabelSupport's functions defined in its class body."""
    def funcs(c: type) -> dict[str, object]:
        return {k: v for k, v in vars(c).items() if isinstance(v, types.FunctionType)}
    old = module_at(rev, "peers/label_support.py").LabelSupport
    return {"now": {LabelSupport: funcs(LabelSupport)}, "rev": {LabelSupport: funcs(old)}}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--against", metavar="REV", required=True, help="the git revision to compare")
    p.add_argument("--pairs", type=int, default=2, help="alternated pairs (default 2)")
    p.add_argument("--scans", type=int, default=100, help="scans per run (default 100)")
    p.add_argument("--peers", type=int, default=50)
    p.add_argument("--degree", type=int, default=4)
    p.add_argument("--set", dest="sets", action="append", default=[], metavar="KEY=VALUE",
                   help="a scenario override (repeatable), e.g. fusion.trust=false")
    args = p.parse_args(argv)
    try:
        sides = method_sets(args.against)
    except subprocess.CalledProcessError as exc:
        p.error(f"--against {args.against}: {exc.stderr.strip() or 'not a revision'}")
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "twin.toml"
        path.write_text(scenario_text(args.peers, args.degree, args.scans, rounds=2, speed=10.0))
        scn = load_scenario(str(path), overrides=parse_overrides(
            ["network.filter=lmb", *args.sets]))
    data = generate_run(scn, 0)
    n = args.peers
    print(f"## label holder masks, this tree against {args.against}: {n} LMB peers, degree "
          f"{args.degree}, 2 rounds, {args.scans} scans"
          f"{''.join(' --set ' + x for x in args.sets)}; load average {load_average()}\n")
    ms: dict[str, list[float]] = {"rev": [], "now": []}
    ospa: dict[str, float] = {}
    tables: dict[str, bytes] = {}
    try:
        for rep in range(args.pairs):
            for side in ("rev", "now") if rep % 2 == 0 else ("now", "rev"):
                use(sides[side], sides["now" if side == "rev" else "rev"])
                peers = {q: make_peer(scn, q, 0, network="twin") for q in scn.sensor_names}
                shared = SharedDecode()
                for core in peers.values():
                    core.decode = shared
                t0 = time.process_time()
                result = run_twin(scn, 0, peers=peers, batch=True, data=data)
                ms[side].append((time.process_time() - t0) * 1e3 / n / args.scans)
                ospa[side] = statistics.fmean(result.mean_ospa(q) for q in scn.sensor_names)
                tables[side] = pickle.dumps([core.scorer.results.table(q)
                                             for q, core in sorted(peers.items())])
            print(f"pair {rep + 1}: {args.against} {ms['rev'][-1]:.3f}, now {ms['now'][-1]:.3f} "
                  f"ms/peer-scan (load {os.getloadavg()[0]:.1f})", flush=True)
    finally:
        use(sides["now"], sides["rev"])
    a, b = statistics.median(ms["rev"]), statistics.median(ms["now"])
    ratios = ", ".join(f"{y / x:.3f}" for x, y in zip(ms["rev"], ms["now"], strict=True))
    print(f"\nmedian {args.against} {a:.3f}, now {b:.3f} ms/peer-scan: now/{args.against} "
          f"{b / a:.3f} (pairs {ratios}); fused OSPA {ospa['rev']:.6f} / {ospa['now']:.6f}; "
          f"every peer's results table the same: {tables['rev'] == tables['now']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
