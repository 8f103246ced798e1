"""Benchmark: the LMB update's association methods against the exact one (tracking/lmb.py,
tracking/lmb_association.py): existence error and cost, in one run.

Cases are :func:`tests.lmb_cases.random_case` (tracks within 120 m of each other, measurements
among them, Pd, kappa and existences drawn so that miss, detection and clutter all weigh):
the 200 small cases of tests/test_lmb.py (<= 4 tracks x <= 4 measurements, seed 2014, the very
same draws) and ``--large`` cases of each fixed shape (5x5, 6x6, 7x7: exact still feasible,
7x7 has 130,922 hypotheses). For each method, the update's existence ``r'`` against the exact
update's: the largest error per case, then its max and mean over the cases, and the number of
cases above 0.02 (the issue's target for the scalable method); then the median CPU time of
one update per method and its ratio to LBP's, interleaved case by case. Gibbs
(:func:`marginals_gibbs`) draws from one Generator (``--gibbs-seed``) across the cases.

Run from the repository root: ``python benchmarks/bench_lmb_association.py [--large N]``.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

if not __package__:  # `python benchmarks/bench_lmb_association.py`: the repository root
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from sensornet.tracking.lmb import update

from tests.lmb_cases import random_case

METHODS = (("auto", {"method": "auto"}), ("lbp", {"method": "lbp"}),
           ("gibbs", {"method": "gibbs"}),
           ("gibbs 300", {"method": "gibbs", "samples": 300}),
           ("gibbs 3000", {"method": "gibbs", "samples": 3000}))
"""(row name, keyword arguments of ``update``); ``gibbs`` uses the default sample count;
``auto`` is the filter's path (exact up to ``exact_limit``, then thinned, then Gibbs)."""


def measure(cases: list, rng: np.random.Generator) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Per method: the existence error per case ``(N,)`` and the time per update ``(N,)``."""
    err = {name: np.zeros(len(cases)) for name, _ in METHODS}
    sec = {name: np.zeros(len(cases)) for name, _ in METHODS}
    sec["exact"] = np.zeros(len(cases))
    clock = time.thread_time  # CPU time: the machine is often shared
    for k, (tracks, Z, sensor) in enumerate(cases):
        t0 = clock()
        ref, _ = update(tracks, Z, sensor, method="exact")
        sec["exact"][k] = clock() - t0
        for name, kw in METHODS:
            t0 = clock()
            post, _ = update(tracks, Z, sensor, rng=rng, **kw)
            sec[name][k] = clock() - t0
            err[name][k] = np.abs(post.existence - ref.existence).max(initial=0.0)
    return {name: (err.get(name, np.zeros(len(cases))), sec[name]) for name in sec}


def table(title: str, cases: list, rng: np.random.Generator) -> None:
    res = measure(cases, rng)
    lbp_ms = 1e3 * float(np.median(res["lbp"][1]))
    print(f"\n{title}: {len(cases)} cases")
    print("| method | max error | mean error | cases > 0.02 | median ms | / LBP |")
    print("|---|---|---|---|---|---|")
    for name, (e, s) in res.items():
        ms = 1e3 * float(np.median(s))
        errs = ("(reference)", "", "") if name == "exact" else (
            f"{e.max():.2g}", f"{e.mean():.2g}", str(int((e > 0.02).sum())))
        print(f"| {name} | {' | '.join(errs)} | {ms:.3f} | {ms / lbp_ms:.2f} |")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--large", type=int, default=20, help="cases per large shape")
    ap.add_argument("--gibbs-seed", type=int, default=1)
    args = ap.parse_args(argv)
    rng = np.random.default_rng(args.gibbs_seed)
    print(f"load average {os.getloadavg()[0]:.2f}")
    cases_rng = np.random.default_rng(2014)
    table("tests/test_lmb.py cases (<= 4 x <= 4, seed 2014)",
          [random_case(cases_rng) for _ in range(200)], rng)
    for n in (5, 6, 7):
        shape_rng = np.random.default_rng(n)
        table(f"{n} tracks x {n} measurements (seed {n})",
              [random_case(shape_rng, shape=(n, n)) for _ in range(args.large)], rng)
    return 0


if __name__ == "__main__":
    sys.exit(main())
