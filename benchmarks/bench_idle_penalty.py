"""How much slower one peer's filter step runs after the process has been idle.

A peer at 10 scans/s sleeps about 95 ms between scans. On the machines this project is
measured on (2-core virtual machines), the first work after such a pause runs several times
slower than the same work back to back, which bounds the scan-to-track latency more than the
arithmetic does. This prints, in one run, the CPU time (``time.thread_time``) of one seed-000
GM-PHD step (predict, update, reduce, level-2 pruning) back to back and after pauses of
0.5 ms to 100 ms, as ratios to the back-to-back time.

    python benchmarks/bench_idle_penalty.py
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

if not __package__:  # run as a script: this checkout's code, not the installed one
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from sensornet.sim.run.peers import make_parts
from sensornet.sim.scenario import load_scenario, parse_overrides
from sensornet.sim.world import generate_run


def step_times(pause: float, scans: int) -> list[float]:
    """CPU seconds of each of ``scans`` filter steps of peer s1, ``pause`` seconds apart."""
    scn = load_scenario("seed000", overrides=parse_overrides(
        ["birth.model=truth", f"scenario.num_scans={scans}"]))
    _, z = generate_run(scn, 0)
    est, _ = make_parts(scn, "s1", 0)  # the peer's local estimator
    out = []
    for k in range(1, scans + 1):
        if pause:
            time.sleep(pause)
        t0 = time.thread_time()
        est.step(1, z[0][k - 1])
        out.append(time.thread_time() - t0)
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--scans", type=int, default=100, help="filter steps per pause length")
    args = p.parse_args(argv)
    step_times(0.0, 10)  # imports, first calls
    base = statistics.median(step_times(0.0, args.scans))
    print("| pause before each step | CPU per step, median (ms) | ratio to back to back |")
    print("|---:|---:|---:|")
    print(f"| none | {1e3 * base:.3f} | 1.00 |", flush=True)
    for pause in (0.0005, 0.002, 0.01, 0.03, 0.1):
        t = statistics.median(step_times(pause, args.scans))
        print(f"| {1e3 * pause:g} ms | {1e3 * t:.3f} | {t / base:.2f} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
