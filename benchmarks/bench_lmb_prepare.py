"""Co-hosted LMB peers' local steps stacked (``LmbEstimator.prepare_many``,
``tracking.lmb_batch.step_many``) against one by one, in one run (issue 33, "50 labelled peers
in real time": "stacked across co-hosted peers like the GM-PHD").

Two parts, each interleaving the two ways so the machine's load falls on both alike:

* the filter steps: runs the twin of bench_fifty's network (``--peers`` LMB peers, circulant
  graph of degree 4, 2 rounds), records every ``LmbFilter.step`` call (copies of the filter,
  its Generator included, and of the state, the scan, the scan index), groups each scan's calls
  into hosts of ``--host`` peers, and replays every host's steps stacked and one by one: thread
  CPU ms per peer-scan of each, their ratio, and how many steps did not give the same state and
  Generator to the bit (0 expected);
* the whole peers' logic: the twin itself with the LMB steps prepared together (as a peer host
  does since this change) and without (``prepare_many`` hidden), ``--repeats`` pairs: process
  CPU ms per peer-scan, their ratio, and whether every peer's mean fused OSPA is the same.

    python benchmarks/bench_lmb_prepare.py                       # 50 peers, hosts of 25
    python benchmarks/bench_lmb_prepare.py --peers 20 --scans 60 --repeats 3
"""

from __future__ import annotations

import argparse
import copy
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

if not __package__:  # `python benchmarks/bench_lmb_prepare.py`: the repository root importable
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from sensornet.peers.host import SharedDecode
from sensornet.peers.lmb_estimator import LmbEstimator
from sensornet.sim.run.peers import make_peer
from sensornet.sim.run.twin import run_twin
from sensornet.sim.scenario import load_scenario, parse_overrides
from sensornet.tracking.lmb_batch import step_many

from benchmarks.bench_lmb_step import _same, record
from benchmarks.bench_network import load_average, scenario_text


def replay(calls: list, host: int, repeats: int) -> tuple[float, float, int, int]:
    """Thread CPU ms per peer-scan of the recorded steps stacked per host and one by one
    (alternating which goes first), the steps not equal to the bit, and the steps replayed."""
    by_k: dict[int, list] = {}
    for c in calls:
        by_k.setdefault(c[3], []).append(c)
    hosts = [group[i:i + host] for group in by_k.values() for i in range(0, len(group), host)]
    t_stack = t_one = 0.0
    differ = count = 0
    for rep in range(repeats):
        for i, h in enumerate(hosts):
            a_f = [copy.copy(f) for f, *_ in h]
            b_f = [copy.copy(f) for f, *_ in h]
            for f, g, (orig, *_) in zip(a_f, b_f, h, strict=True):
                f._rng, g._rng = copy.deepcopy(orig._rng), copy.deepcopy(orig._rng)
            states, scans, ks = [c[1] for c in h], [c[2] for c in h], [c[3] for c in h]

            def stacked(a_f=a_f, states=states, scans=scans, ks=ks):
                return step_many(a_f, states, scans, ks)

            def alone(b_f=b_f, states=states, scans=scans, ks=ks):
                return [f.step(s, z, k) for f, s, z, k in zip(b_f, states, scans, ks,
                                                                strict=True)]

            first_stack = (i + rep) % 2 == 0
            t0 = time.thread_time()
            got = stacked() if first_stack else alone()
            t1 = time.thread_time()
            other = alone() if first_stack else stacked()
            t2 = time.thread_time()
            if not first_stack:
                got, other = other, got
            t_stack += (t1 - t0) if first_stack else (t2 - t1)
            t_one += (t2 - t1) if first_stack else (t1 - t0)
            for r, want, g in zip(got, other, b_f, strict=True):
                differ += (r is None or not _same(r[0], want)
                           or r[1] != g._rng.bit_generator.state)
            count += len(h)
    return t_stack * 1e3 / count, t_one * 1e3 / count, differ, count


def twin_pairs(n: int, degree: int, scans: int, repeats: int) -> list[tuple[str, float, list]]:
    """``repeats`` pairs of twin runs, LMB steps prepared together and not (alternating which
    first): ``(way, process CPU ms per peer-scan, each peer's mean fused OSPA)``."""
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "twin.toml"
        path.write_text(scenario_text(n, degree, scans, rounds=2, speed=10.0))
        scn = load_scenario(str(path), overrides=parse_overrides(["network.filter=lmb"]))
    prepare = LmbEstimator.__dict__["prepare_many"]
    out = []
    for rep in range(repeats):
        for way in (("stacked", "one by one") if rep % 2 == 0 else ("one by one", "stacked")):
            if way == "one by one":
                del LmbEstimator.prepare_many  # peers.batching then skips LMB peers
            try:
                peers = {q: make_peer(scn, q, 0, network="twin") for q in scn.sensor_names}
                shared = SharedDecode()
                for core in peers.values():
                    core.decode = shared
                t0 = time.process_time()
                result = run_twin(scn, 0, peers=peers, batch=True)
                ms = (time.process_time() - t0) * 1e3 / n / scans
            finally:
                if way == "one by one":
                    LmbEstimator.prepare_many = prepare
            out.append((way, ms, [result.mean_ospa(q) for q in scn.sensor_names]))
            print(f"| {way} | {rep + 1} | {ms:.2f} | {np.mean(out[-1][2]):.2f} | "
                  f"{load_average()} |", flush=True)
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--peers", type=int, default=50, help="LMB peers (default 50)")
    p.add_argument("--host", type=int, default=25, help="peers per host (default 25)")
    p.add_argument("--degree", type=int, default=4, help="graph degree (default 4)")
    p.add_argument("--scans", type=int, default=40, help="scans of the twin runs (default 40)")
    p.add_argument("--repeats", type=int, default=3,
                   help="replays of the recorded steps, and pairs of twin runs (default 3)")
    args = p.parse_args(argv)
    calls, _ = record(args.peers, args.degree, args.scans, [])
    t_stack, t_one, differ, count = replay(calls, args.host, args.repeats)
    print(f"## LMB local steps of {args.peers} peers in hosts of {args.host}, degree "
          f"{args.degree}, {args.scans} scans ({count} steps); load average {load_average()}\n")
    print("| filter steps | CPU ms / peer-scan |\n|---|---:|")
    print(f"| one by one | {t_one:.3f} |\n| stacked | {t_stack:.3f} |")
    print(f"\nstacked / one by one: {t_stack / t_one:.3f}; steps not equal to the bit: "
          f"{differ} of {count}\n")
    print(f"## the twin (all of the peers' logic, every instant's scans as one host), "
          f"{args.repeats} pairs\n")
    print("| LMB steps | pair | logic CPU ms / peer-scan | fused OSPA | load avg |\n"
          "|---|---:|---:|---:|---:|", flush=True)
    runs = twin_pairs(args.peers, args.degree, args.scans, args.repeats)
    med = {w: statistics.median(ms for way, ms, _ in runs if way == w)
           for w in ("stacked", "one by one")}
    same = all(o == runs[0][2] for _, _, o in runs)
    print(f"\nstacked / one by one (medians): {med['stacked'] / med['one by one']:.3f}; "
          f"every run's fused OSPA the same per peer: {same}")
    return 0 if differ == 0 and same else 1


if __name__ == "__main__":
    raise SystemExit(main())
