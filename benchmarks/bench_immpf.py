"""IMM-PF and IMM-EKF step times (seed 001) against the code before issue 15, in one run.

Targets (issue 15): one IMM-PF step (interaction, propagation, radar likelihood, model
probabilities, residual resampling, jitter) at most 0.3 ms at 2 x 800 particles and 3 ms at
2 x 10,000; one IMM-EKF step at most 60 us. The machine is shared, so the current step and the
one before (``benchmarks/filters_before.py``) are timed interleaved, step for step, on the same
scans, and their ratio is the number to compare across runs (also printed: the ratio of the
fastest steps of each, less sensitive to other processes). Also printed: nanoseconds per
particle per step, and the floor no NumPy rewrite of the same filter can go below: the time of
its random draws alone (8 normals and a few uniforms per particle, the same stream). Medians
over many steps; the load average is printed. Run from the repository root:

    python benchmarks/bench_immpf.py [--quick] [--loop]

``--loop`` adds the per-particle Python loop of the same step (slow; the original reference).
Both filters start from the same state and random stream each step, and the table says
whether their outputs are identical (or the largest relative difference).
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np

if not __package__:  # `python benchmarks/bench_immpf.py`: the repository root importable
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from sensornet.sim.studies.seed001.montecarlo import Seed001Scenario, measure, truth
from sensornet.tracking.imm import IMMEKF, IMMParams, mixing, radar_log_likelihood
from sensornet.tracking.particles import IMMParticleFilter, ParticleParams

from benchmarks.filters_before import IMMEKFBefore, IMMParticleFilterBefore
from benchmarks.filters_before import radar_log_likelihood as radar_log_likelihood_before


def loop_step(X: np.ndarray, probs: np.ndarray, params: IMMParams, sensor, z,
              rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """The same IMM-PF step written one particle at a time (the original reference)."""
    models = params.models()
    M, N, d = X.shape
    c, mu = mixing(probs, params.P)
    out = np.empty_like(X)
    log_lam = np.empty(M)
    for j, model in enumerate(models):
        lw = np.empty(N)
        for n in range(N):
            i = 0 if rng.random() < mu[0, j] else 1
            x = X[i, rng.integers(N)]
            x = model.F @ x + model.sigma * (model.G @ rng.standard_normal(2))
            out[j, n] = x
            lw[n] = float(radar_log_likelihood(sensor, z, x))
        top = lw.max()
        w = np.exp(lw - top)
        log_lam[j] = np.log(w.mean()) + top
        w /= w.sum()
        counts = np.floor(N * w).astype(int)
        rest = N * w - counts
        left = N - counts.sum()
        if left:
            extra = rng.choice(N, size=left, p=rest / rest.sum())
            for e in extra:
                counts[e] += 1
        new = []
        for n in range(N):
            for _ in range(counts[n]):
                new.append(out[j, n])
        out[j] = np.array(new)
    a = np.log(c) + log_lam
    p = np.exp(a - a.max())
    return out, p / p.sum()


def _rel_diff(a, b) -> float:
    a, b = np.asarray(a), np.asarray(b)
    return float(np.max(np.abs(a - b)) / max(np.max(np.abs(a)), 1e-300))


def compare_pf(n: int, steps: int, scn, sensor, X, Z) -> dict:
    """Interleaved step times of the current and the previous IMM-PF from the same states and
    random streams (each step starts both from the current filter's last posterior)."""
    params, pp = IMMParams(), ParticleParams(n_particles=n)
    new, old = IMMParticleFilter(params, pp), IMMParticleFilterBefore(params, pp)
    rng = np.random.default_rng(1)
    state = new.initialise(X[0], scn.init_cov, rng)
    t_new, t_old, diff, same = [], [], 0.0, True
    k = 0
    for s in range(steps + 5):
        k = k % (len(Z) - 1) + 1
        z = Z[k]
        seed = 1000 + s
        start = type(state)(np.array(state.particles), state.probs, state.means, state.covs)
        order = (0, 1) if s % 2 else (1, 0)
        for which in order:
            r = np.random.default_rng(seed)
            if which == 0:
                t0 = time.perf_counter()
                post, _ = new.step(start, lambda P, z=z: radar_log_likelihood(sensor, z, P), r)
                dt = time.perf_counter() - t0
                if s >= 5:
                    t_new.append(dt)
            else:
                t0 = time.perf_counter()
                ref, _ = old.step(start, lambda P, z=z: radar_log_likelihood_before(sensor, z, P),
                                  r)
                dt = time.perf_counter() - t0
                if s >= 5:
                    t_old.append(dt)
        same &= bool(np.array_equal(post.particles, ref.particles)
                     and np.array_equal(post.means, ref.means)
                     and np.array_equal(post.covs, ref.covs)
                     and np.array_equal(post.probs, ref.probs))
        diff = max(diff, _rel_diff(ref.means, post.means), _rel_diff(ref.covs, post.covs),
                   _rel_diff(ref.particles, post.particles))
        state = post
    # the random draws of one step alone: the floor of any NumPy version of this filter
    r = np.random.default_rng(7)
    t_rng = []
    for _ in range(max(steps // 2, 5)):
        t0 = time.perf_counter()
        r.random(2)
        r.standard_normal((2, n, 2))
        r.random(2)
        r.standard_normal((2, n, 6))
        t_rng.append(time.perf_counter() - t0)
    return dict(new=statistics.median(t_new), old=statistics.median(t_old),
                ratio_min=min(t_old) / min(t_new), rng=statistics.median(t_rng), same=same,
                diff=diff, state=state)


def compare_ekf(steps: int, scn, sensor, X, Z) -> dict:
    new, old = IMMEKF(), IMMEKFBefore()
    s_new = s_old = new.initialise(X[0], scn.init_cov)
    t_new, t_old, same, diff = [], [], True, 0.0
    for s in range(steps):
        z = Z[s % (len(Z) - 1) + 1]
        for which in ((0, 1) if s % 2 else (1, 0)):
            t0 = time.perf_counter()
            if which == 0:
                s_new = new.step(s_new, z, sensor)
                t_new.append(time.perf_counter() - t0)
            else:
                s_old = old.step(s_old, z, sensor)
                t_old.append(time.perf_counter() - t0)
        for a, b in ((s_new.means, s_old.means), (s_new.covs, s_old.covs),
                     (s_new.probs, s_old.probs)):
            same &= bool(np.array_equal(a, b))
            diff = max(diff, _rel_diff(b, a))
    return dict(new=statistics.median(t_new), old=statistics.median(t_old),
                ratio_min=min(t_old) / min(t_new), same=same, diff=diff)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="fewer steps (CI smoke test)")
    ap.add_argument("--loop", action="store_true",
                    help="also time the per-particle Python loop (slow)")
    a = ap.parse_args(argv)
    scn = Seed001Scenario()
    sensor = scn.sensors()[0]
    X = truth(scn)
    Z = measure(scn.sensors(), X, np.random.default_rng(0))[0]
    print(f"load average {os.getloadavg()[0]:.2f} {os.getloadavg()[1]:.2f} on "
          f"{os.cpu_count()} cores; medians, current and before interleaved step for step")
    print()
    print("| what | now ms | before ms | before / now | (fastest steps) | target ms | | "
          "ns per particle | random draws alone ms | outputs |")
    print("|---|---:|---:|---:|---:|---:|---|---:|---:|---|")
    loops = []
    for n, target, steps in ((800, 0.3, 400), (10_000, 3.0, 60)):
        if a.quick:
            steps = 5
        r = compare_pf(n, steps, scn, sensor, X, Z)
        outputs = "identical" if r["same"] else f"max rel. diff {r['diff']:.1e}"
        print(f"| IMM-PF step, 2 x {n} | {1e3 * r['new']:.3f} | {1e3 * r['old']:.3f} | "
              f"{r['old'] / r['new']:.2f} | {r['ratio_min']:.2f} | {target:g} | "
              f"{'PASS' if 1e3 * r['new'] <= target else 'FAIL'} | "
              f"{1e9 * r['new'] / (2 * n):.1f} | {1e3 * r['rng']:.3f} | {outputs} |")
        if a.loop:
            st = r["state"]
            rng = np.random.default_rng(3)
            t0 = time.perf_counter()
            loop_step(st.particles, st.probs, IMMParams(), sensor, Z[1], rng)
            loops.append((n, time.perf_counter() - t0, r["new"]))
    e = compare_ekf(50 if a.quick else 2000, scn, sensor, X, Z)
    outputs = "identical" if e["same"] else f"max rel. diff {e['diff']:.1e}"
    print(f"| IMM-EKF step (2 models) | {1e3 * e['new']:.4f} | {1e3 * e['old']:.4f} | "
          f"{e['old'] / e['new']:.2f} | {e['ratio_min']:.2f} | 0.06 | "
          f"{'PASS' if 1e3 * e['new'] <= 0.06 else 'FAIL'} "
          f"| - | - | {outputs} |")
    for n, t_loop, t_new in loops:
        print(f"per-particle loop, 2 x {n}: {1e3 * t_loop:.1f} ms ({t_loop / t_new:.0f}x the "
              f"current step)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
