"""Step time of the seed-003 two-sensor fuzzy IMM (and the other PDA filters) against the code
before issue 12's speed work, in one run.

Target (issue 12): one step of the two-sensor fuzzy IMM (IMM mixing and prediction, then the
PDA update with sensor 1's returns and with sensor 2's) at most 0.2 ms; before: about 0.38 ms.
The machine is shared, so the current step and the one before (``benchmarks/pda_before.py``)
are timed interleaved on the same recorded scans, and their ratio is the number to compare
across runs. The scans are recorded from ``sim.studies.seed003.montecarlo`` runs (default: clutter
in each
filter's gate, 2 on average, the paper's setting; ``--region``: the region clutter a peer
network sees, where the IMM's wide CA gate holds hundreds of returns); both filters replay the
same returns, and the table says how far their final estimates differ. Medians over every
step of every repetition; the load average is printed. Run from the repository root:

    python benchmarks/bench_pda.py [--quick] [--region]
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np

if not __package__:  # `python benchmarks/bench_pda.py`: the repository root importable
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from sensornet.sim.studies.seed003 import montecarlo as seed003

from benchmarks.pda_before import ImmPdaBefore


def record(cfg: dict, method: str, run: int, n_sensors: int):
    """The returns each sensor update of ``method`` saw on run ``run`` and its start state."""
    seed = int(cfg["scenario"]["seed"])
    rng = np.random.default_rng([seed, run])
    X = seed003.truth(cfg)
    sens = seed003.sensors(cfg)[:n_sensors]
    target = [p[:n_sensors] for p in seed003.target_returns(X, seed003.sensors(cfg), rng)]
    m0, P0 = seed003.initial_state(cfg, X[0], rng)
    region = None
    if cfg["clutter"]["mode"] == "region":
        region = [r[:n_sensors] for r in seed003.region_clutter(cfg, X, seed003.sensors(cfg),
                                                               rng)]
    Zs: list[np.ndarray] = []
    flt = seed003.make_filter(cfg, method, m0, P0)
    seed003.run_filter(cfg, flt, sens, target, region,
                       np.random.default_rng([seed, run, 1000 + n_sensors]),
                       lambda Z, d, up, f: Zs.append(Z))
    scans = [Zs[i:i + n_sensors] for i in range(0, len(Zs), n_sensors)]
    return m0, P0, sens, scans


def before_filter(cfg: dict, method: str, m0, P0) -> ImmPdaBefore:
    now = seed003.make_filter(cfg, method, m0, P0)
    old = ImmPdaBefore.__new__(ImmPdaBefore)
    old.__dict__.update(now.__dict__)
    return old


def replay(flt, sens, scans) -> tuple[list[float], np.ndarray]:
    """Per-step seconds and the final estimate."""
    times = []
    clock = time.perf_counter
    for per in scans:
        t0 = clock()
        flt.predict()
        for s, Z in zip(sens, per, strict=True):
            flt.update(s, Z)
        times.append(clock() - t0)
    return times, flt.estimate()[0]


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--runs", type=int, default=3, help="seed-003 runs replayed")
    p.add_argument("--reps", type=int, default=15, help="repetitions of each run")
    p.add_argument("--quick", action="store_true", help="1 run, 3 repetitions")
    p.add_argument("--region", action="store_true", help="region clutter (the peers')")
    a = p.parse_args(argv)
    runs, reps = (1, 3) if a.quick else (a.runs, a.reps)
    cfg = seed003.load(overrides={"clutter.mode": "region"} if a.region else None)
    cases = [("fuzzy IMM", 2), ("fuzzy IMM", 1), ("IMM-PDAF", 2), ("PDAF", 2)]
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores; "
          f"{cfg['clutter']['mode']} clutter; {runs} runs x {reps} repetitions, interleaved")
    print("| filter | sensors | returns per update | step now ms | step before ms | "
          "before / now | max rel. diff |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    for method, n in cases:
        now_t: list[float] = []
        old_t: list[float] = []
        diff, returns = 0.0, []
        for run in range(runs):
            m0, P0, sens, scans = record(cfg, method, run, n)
            returns += [len(Z) for per in scans for Z in per]
            for _ in range(reps):
                t_new, x_new = replay(seed003.make_filter(cfg, method, m0, P0), sens, scans)
                t_old, x_old = replay(before_filter(cfg, method, m0, P0), sens, scans)
                now_t += t_new
                old_t += t_old
                diff = max(diff, float(np.max(np.abs(x_new - x_old) /
                                              np.maximum(np.abs(x_old), 1.0))))
        m_now, m_old = statistics.median(now_t) * 1e3, statistics.median(old_t) * 1e3
        print(f"| {method} | {n} | {statistics.mean(returns):.1f} | {m_now:.3f} | "
              f"{m_old:.3f} | {m_old / m_now:.2f} | {diff:.1e} |")
    print(f"(load average now {os.getloadavg()[0]:.1f}; the target is a fuzzy IMM two-sensor "
          f"step <= 0.2 ms against 0.38 ms before, i.e. a ratio >= 1.9)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
