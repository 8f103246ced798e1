"""Benchmark: the LMB filter's step (tracking/lmb.py) against the GM-PHD step on the same scans.

Targets move in straight lines (CV model, sigma_w = 1 m/s^2) over a square sized so that they
stay apart (2 km wide at 10 targets, 6 km at 100), a linear position sensor (sigma_r = 10 m,
Pd = 0.95) and Poisson clutter uniform over the square. Both filters step through the same
scans, interleaved (GM-PHD then LMB on each scan, so both see the same machine load): the
GM-PHD (``tracking.gmphd.GMPHDFilter``, births at the targets' start points, weight 0.03 each)
and the LMB (adaptive births with ``lambda_B = 1``, ``method="auto"``). Medians per step over
the scans after a warm-up. Targets (the LMB issue): LMB / GM-PHD <= 3 at 10 targets and clutter
10; LMB step <= 20 ms at 100 targets and clutter 50. Also prints the mean numbers of LMB
tracks, of extracted tracks (``r >= 0.5``) and of confirmed ones, as a check that the LMB
tracks the targets.

Run from the repository root: ``python benchmarks/bench_lmb.py [--quick] [--scans N]``.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np
from sensornet.tracking.gmphd import GMPHDFilter, SensorParams
from sensornet.tracking.lmb import LmbFilter
from sensornet.tracking.mixture import GaussianMixture
from sensornet.tracking.models import ConstantVelocity, LinearPosition

SETTINGS = ((10, 10.0, 1000.0, "ratio", 3.0), (100, 50.0, 3000.0, "ms", 20.0))
"""(targets, clutter mean per scan, half-width of the square in m, measure, target)."""


def scenario(n: int, clutter: float, half: float, scans: int, rng: np.random.Generator):
    """Start states ``(n, 4)`` on a grid inside the square and the scans (list of ``(m, 2)``)."""
    motion, sensor = ConstantVelocity(sigma_w=1.0), LinearPosition(sigma_r=10.0)
    side = int(np.ceil(np.sqrt(n)))
    grid = (np.arange(side) + 0.5) / side * 2 * half * 0.8 - 0.8 * half
    gx, gy = np.meshgrid(grid, grid)
    x0 = np.zeros((n, 4))
    x0[:, 0], x0[:, 2] = gx.ravel()[:n], gy.ravel()[:n]
    x0[:, [1, 3]] = rng.uniform(-5, 5, size=(n, 2))
    x, out = x0.copy(), []
    for _ in range(scans):
        x = motion.sample(x, rng)
        seen = sensor.measure(x[rng.random(n) < 0.95], rng)
        noise = rng.uniform(-half, half, size=(rng.poisson(clutter), 2))
        out.append(rng.permutation(np.concatenate((seen, noise))))
    return x0, out


def run(n: int, clutter: float, half: float, scans: int, warmup: int,
        rng: np.random.Generator) -> dict:
    x0, Zs = scenario(n, clutter, half, scans, rng)
    motion = ConstantVelocity(sigma_w=1.0)
    sensor = SensorParams(LinearPosition(sigma_r=10.0), 0.95, clutter / (2 * half) ** 2)
    birth_cov = np.tile(np.diag([100.0, 100.0, 100.0, 100.0]), (n, 1, 1))
    phd = GMPHDFilter(motion, [sensor], GaussianMixture(np.full(n, 0.03), x0, birth_cov))
    lmb = LmbFilter(motion, sensor, birth_rate=1.0)
    mix, state = phd.initial(), lmb.initial()
    t_phd, t_lmb, tracks, extracted, confirmed = [], [], [], [], []
    clock = time.perf_counter
    for k, Z in enumerate(Zs):
        t0 = clock()
        mix = phd.step(mix, Z)
        t1 = clock()
        state = lmb.step(state, Z)
        t2 = clock()
        if k >= warmup:
            t_phd.append(t1 - t0)
            t_lmb.append(t2 - t1)
            tracks.append(len(state.tracks))
            out = lmb.extract(state)
            extracted.append(len(out))
            confirmed.append(int(out.status.sum()))
    return {"phd": 1e3 * float(np.median(t_phd)), "lmb": 1e3 * float(np.median(t_lmb)),
            "tracks": float(np.mean(tracks)), "extracted": float(np.mean(extracted)),
            "confirmed": float(np.mean(confirmed))}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scans", type=int, default=200, help="scans per setting")
    ap.add_argument("--quick", action="store_true", help="40 scans per setting")
    ap.add_argument("--seed", type=int, default=2014)
    args = ap.parse_args(argv)
    scans = 40 if args.quick else args.scans
    warmup = min(20, scans // 2)
    rng = np.random.default_rng(args.seed)
    print(f"load average {os.getloadavg()[0]:.2f}; {scans} scans, first {warmup} not timed")
    print("| targets | clutter | GM-PHD ms | LMB ms | LMB / GM-PHD | LMB tracks | extracted "
          "| confirmed | target | verdict |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for n, clutter, half, measure, target in SETTINGS:
        r = run(n, clutter, half, scans, warmup, rng)
        ratio = r["lmb"] / r["phd"]
        value = ratio if measure == "ratio" else r["lmb"]
        goal = f"ratio <= {target:g}" if measure == "ratio" else f"<= {target:g} ms"
        print(f"| {n} | {clutter:g} | {r['phd']:.3f} | {r['lmb']:.3f} | {ratio:.2f} | "
              f"{r['tracks']:.1f} | {r['extracted']:.1f} | {r['confirmed']:.1f} | {goal} | "
              f"{'PASS' if value <= target else 'FAIL'} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
