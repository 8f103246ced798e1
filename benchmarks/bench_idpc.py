"""Benchmark: IDPC and FTC clustering of one pooled seed-004 scan set, against the 0.5 ms target.

A pooled set as a peer holds it after complete flooding (docs/seed004.md): 20 sensors, 3
separated targets seen with Pd = 0.95 and sigma = 10 m per axis, Poisson clutter (mean 10 per
sensor, or ``--clutter``) uniform over (-1000, 1000]^2: about 260 points. Times
:func:`tracking.idpc.idpc` and :func:`tracking.idpc.ftc` (scikit-learn DBSCAN + k-means) as
medians over many calls on fresh sets, and prints the ratio to the issue's target (clustering
<= 0.5 ms per peer per scan) with PASS/FAIL.

Run from the repository root: ``python benchmarks/bench_idpc.py [--quick]``.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

if not __package__:  # run as a script: this checkout's code, not the installed one
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from sensornet.tracking.idpc import ClusterParams, ftc, idpc

TARGET_MS = 0.5
SENSORS = 20
TARGETS = np.array([[-100.0, -800.0], [-800.0, -500.0], [0.0, 950.0]])


def pooled_set(rng: np.random.Generator, clutter: float, pd: float = 0.95,
               sigma: float = 10.0) -> np.ndarray:
    """The union of ``SENSORS`` scans of the three targets plus clutter, ``(n, 2)``."""
    parts = []
    for _ in range(SENSORS):
        seen = TARGETS[rng.random(len(TARGETS)) < pd]
        parts.append(seen + sigma * rng.standard_normal(seen.shape))
        parts.append(rng.uniform(-1000.0, 1000.0, size=(rng.poisson(clutter), 2)))
    return np.concatenate(parts)


def time_calls(fn, sets, params, rng) -> tuple[float, float]:
    """Median and 90th percentile milliseconds per call over ``sets``."""
    times = []
    for pts in sets:
        t0 = time.perf_counter()
        fn(pts, SENSORS, params, rng)
        times.append((time.perf_counter() - t0) * 1e3)
    return float(np.median(times)), float(np.percentile(times, 90))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="50 sets instead of 1000")
    ap.add_argument("--clutter", type=float, default=10.0, help="clutter mean per sensor")
    args = ap.parse_args(argv)
    rng = np.random.default_rng(2004)
    sets = [pooled_set(rng, args.clutter) for _ in range(50 if args.quick else 1000)]
    params = ClusterParams()
    for fn in (idpc, ftc):  # warm-up (imports, caches)
        fn(sets[0], SENSORS, params, rng)
    npts = float(np.mean([len(s) for s in sets]))
    print(f"pooled points per set: {npts:.0f} (20 sensors, clutter {args.clutter:g}/sensor)")
    print("| clusterer | median ms | p90 ms | median / 0.5 ms | verdict |")
    print("|---|---|---|---|---|")
    for name, fn in (("IDPC", idpc), ("FTC (DBSCAN + k-means)", ftc)):
        med, p90 = time_calls(fn, sets, params, rng)
        verdict = "PASS" if med <= TARGET_MS else "FAIL"
        print(f"| {name} | {med:.3f} | {p90:.3f} | {med / TARGET_MS:.2f} | {verdict} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
