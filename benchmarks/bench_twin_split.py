"""The twin in one process against the twin over worker processes (issue 34's speed target).

The traffic study's fused twin (``sim.studies.traffic.study``: its scenario, window and
``run_twin(scn, run)`` call) run twice per kind in one process, one process then
``--workers`` forked workers (``run_twin(..., workers=N)``, :mod:`sim.run.twin_split`), or the
other way round with ``--split-first``; per run the wall seconds, the CPU seconds (this
process's plus its reaped children's, ``resource.getrusage``), x real time on the wall and per
CPU second, whether the fused tracks are equal, then the ratio split / single. Both runs of a
kind are in one process run: under other load the ratio is the number to quote.

    python benchmarks/bench_twin_split.py --minutes 10 --kinds gmphd,lmb
    python benchmarks/bench_twin_split.py --file /work/shared/data/adsb/quickstart.json.gz \\
        --start 0 --minutes 180 --kinds lmb          # issue 34's 3 hours (quiet machine)

Target (issue 34): 8 radar peers over the full 3 hours: >= 20 x real time on 2 cores.
"""

from __future__ import annotations

import argparse
import os
import resource
import sys
import time
from pathlib import Path

import numpy as np

if not __package__:  # run as a script: this checkout's code, not the installed one
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from sensornet.sim.run.twin import run_twin
from sensornet.sim.studies.traffic.study import (
    add_window_arguments,
    scenario_of,
    window_scenario,
)


def _cpu() -> float:
    """This process's and its reaped children's user + system seconds."""
    me, kids = (resource.getrusage(w) for w in (resource.RUSAGE_SELF,
                                                resource.RUSAGE_CHILDREN))
    return me.ru_utime + me.ru_stime + kids.ru_utime + kids.ru_stime


def timed(scn, run: int, workers: int) -> tuple:
    """One twin run: its result, wall, CPU seconds and this process's CPU seconds."""
    w0, c0, p0 = time.perf_counter(), _cpu(), time.process_time()
    r = run_twin(scn, run, workers=workers)
    return r, time.perf_counter() - w0, _cpu() - c0, time.process_time() - p0


def same_tracks(a: dict, b: dict) -> bool:
    return a.keys() == b.keys() and all(
        a[p].keys() == b[p].keys() and all(np.array_equal(a[p][k], b[p][k]) for k in a[p])
        for p in a)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    add_window_arguments(ap)
    ap.add_argument("--kinds", default="gmphd,lmb")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--run", type=int, default=0)
    ap.add_argument("--split-first", action="store_true", help="run the split twin first")
    a = ap.parse_args(argv)
    over, base = window_scenario(a)
    sim = base.num_scans * base.scan_period
    print(f"{base.name}: {len(base.sensors)} peers, {base.num_scans} ticks ({sim / 60:.1f} min "
          f"simulated) from traffic.start = {base.traffic.start}; {os.cpu_count()} cores, load "
          f"{os.getloadavg()[0]:.1f} at start", flush=True)
    print("| kind | twin | wall (s) | CPU (s) | x real time wall | x real time CPU |")
    print("|---|---|---:|---:|---:|---:|")
    for kind in (k for k in a.kinds.split(",") if k):
        scn = scenario_of(a.scenario, over, kind, "fused")
        order = [a.workers, 1] if a.split_first else [1, a.workers]
        got = {}
        for w in order:
            got[w] = timed(scn, a.run, w)
            _, wall, cpu, _ = got[w]
            print(f"| {kind} | {'one process' if w == 1 else f'{w} workers'} | {wall:.1f} | "
                  f"{cpu:.1f} | {sim / wall:.1f} | {sim / cpu:.1f} |", flush=True)
        (r1, w1, c1, _), (rn, wn, cn, pn) = got[1], got[a.workers]
        print(f"| {kind} | split / single | {wn / w1:.2f} | {cn / c1:.2f} | {w1 / wn:.2f} x "
              f"faster | tracks equal: {'yes' if same_tracks(r1.tracks, rn.tracks) else '**no**'}"
              " |", flush=True)
        st = rn.split
        crit = st["critical_cpu"] + pn  # the slowest worker per wave, then the parent's
        print(f"  split: {st['instants']} instants, {st['waves']} waves, {st['messages']} "
              f"messages between workers; workers' CPU in waves {st['cpu']:.1f} s, the "
              f"slowest per wave summed {st['critical_cpu']:.1f} s, parent {pn:.1f} s: with a "
              f"free core per worker about {sim / crit:.1f} x real time on the wall "
              f"({c1 / crit:.2f} x the one process's CPU), groups {st['groups']}", flush=True)
    me, kid = (resource.getrusage(w).ru_maxrss / 1024 for w in (resource.RUSAGE_SELF,
                                                                resource.RUSAGE_CHILDREN))
    print(f"load {os.getloadavg()[0]:.1f} at the end; peak RSS {me:.0f} MB here, {kid:.0f} MB "
          "the largest worker")
    return 0


if __name__ == "__main__":
    sys.exit(main())
