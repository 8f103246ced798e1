"""What the all-or-nothing step (peers.step_atomic) costs a labelled peer's local step, in one run.

Two estimators of one peer (the scenario's own, ``make_peer``) step through the same scans of
run 0, interleaved step by step so the machine's load falls on both alike: one through the
atomic ``step``, the other through the plain method underneath (``step.__wrapped__``). Prints
thread CPU ms per step of each, their ratio, the snapshot alone in microseconds, and checks
that both gave the same arrays (0 differences expected).

    python benchmarks/bench_step_atomic.py                       # seed000, GM-PHD and LMB
    python benchmarks/bench_step_atomic.py --scenario seed000 --repeats 5 --kinds lmb
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

if not __package__:  # `python benchmarks/bench_step_atomic.py`: the repository root importable
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from sensornet.peers.step_atomic import snapshot
from sensornet.sim.run.peers import make_peer
from sensornet.sim.scenario import load_scenario
from sensornet.sim.world import generate_run

from benchmarks.bench_network import load_average


def bench(scenario: str, kind: str, repeats: int) -> dict:
    over = {} if kind == "gmphd" else {"network.filter": kind}
    scn = load_scenario(scenario, overrides=over)
    _, scans = generate_run(scn, 0)
    name = scn.sensor_names[0]
    zs = scans[scn.sensor_names.index(name)]
    t_atomic = t_plain = t_snap = 0.0
    steps = diffs = 0
    for _ in range(repeats):
        a = make_peer(scn, name, 0).consensus.estimator
        b = make_peer(scn, name, 0).consensus.estimator
        plain = type(b).step.__wrapped__
        for k, z in enumerate(zs, start=1):
            a.begin_scan(k)
            b.begin_scan(k)
            t0 = time.thread_time()
            out_a = a.step(1, z)
            t1 = time.thread_time()
            out_b = plain(b, 1, z)
            t2 = time.thread_time()
            snapshot(a)
            t3 = time.thread_time()
            t_atomic += t1 - t0
            t_plain += t2 - t1
            t_snap += t3 - t2
            steps += 1
            same = (np.array_equal(out_a.density.means, out_b.density.means)
                    and np.array_equal(out_a.density.weights, out_b.density.weights)
                    and np.array_equal(out_a.density_labels, out_b.density_labels))
            diffs += not same
    return {"kind": kind, "steps": steps, "atomic_ms": 1e3 * t_atomic / steps,
            "plain_ms": 1e3 * t_plain / steps, "ratio": t_atomic / t_plain,
            "snapshot_us": 1e6 * t_snap / steps, "diffs": diffs}


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="seed000")
    ap.add_argument("--kinds", default="gmphd,lmb", help="comma-separated: gmphd, lmb")
    ap.add_argument("--repeats", type=int, default=3, help="passes over the run's scans")
    args = ap.parse_args(argv)
    print(f"load {load_average()}  scenario {args.scenario}  repeats {args.repeats}")
    for kind in args.kinds.split(","):
        r = bench(args.scenario, kind, args.repeats)
        print(f"{r['kind']:6s} {r['steps']} steps  atomic {r['atomic_ms']:.3f} ms  plain "
              f"{r['plain_ms']:.3f} ms  ratio {r['ratio']:.3f}  snapshot "
              f"{r['snapshot_us']:.1f} us  differing steps {r['diffs']}")


if __name__ == "__main__":
    main()
