"""IMM-PF step time (seed 001): vectorised filter vs a plain per-particle loop, and the IMM-EKF.

Targets (issue): one IMM-PF step (interaction, propagation, radar likelihood, model
probabilities, residual resampling, jitter) under 0.8 ms at 2 x 800 particles and under 8 ms at
2 x 10,000. Medians over many steps (the machine is shared and noisy); the per-particle loop is
timed on fewer steps. Run from the repository root:

    PYTHONPATH=. python benchmarks/bench_immpf.py [--quick]

OPENBLAS_CORETYPE is left as the environment sets it.
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from sim.seed001 import Seed001Scenario, measure, truth
from tracking.imm import IMMEKF, IMMParams, mixing, radar_log_likelihood
from tracking.particles import IMMParticleFilter, ParticleParams


def _median_ms(fn, steps: int) -> float:
    times = []
    for _ in range(steps):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return 1e3 * statistics.median(times)


def loop_step(X: np.ndarray, probs: np.ndarray, params: IMMParams, sensor, z,
              rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """The same IMM-PF step written one particle at a time (the reference for the speed-up)."""
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


class _Stepper:
    """One IMM-PF step per call, cycling through the scans."""

    def __init__(self, pf, state, sensor, Z, rng):
        self.pf, self.state, self.sensor, self.Z, self.rng, self.k = pf, state, sensor, Z, rng, 0

    def __call__(self) -> None:
        self.k = self.k % (len(self.Z) - 1) + 1
        z, sensor = self.Z[self.k], self.sensor
        self.state, _ = self.pf.step(self.state, lambda P: radar_log_likelihood(sensor, z, P),
                                     self.rng)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="fewer steps (CI smoke test)")
    a = ap.parse_args(argv)
    scn = Seed001Scenario()
    sensor = scn.sensors()[0]
    X = truth(scn)
    Z = measure(scn.sensors(), X, np.random.default_rng(0))[0]
    rows = []
    for n, target, steps, loop_steps in ((800, 0.8, 400, 3), (10_000, 8.0, 60, 1)):
        if a.quick:
            steps, loop_steps = max(steps // 10, 5), 1
        pf = IMMParticleFilter(IMMParams(), ParticleParams(n_particles=n))
        rng = np.random.default_rng(1)
        runner = _Stepper(pf, pf.initialise(X[0], scn.init_cov, rng), sensor, Z, rng)
        for _ in range(5):  # warm-up
            runner()
        vec_ms = _median_ms(runner, steps)
        Xl, pl = runner.state.particles.copy(), runner.state.probs.copy()
        loop_times = []
        for s in range(loop_steps):
            t0 = time.perf_counter()
            Xl, pl = loop_step(Xl, pl, IMMParams(), sensor, Z[runner.k + 1 + s], rng)
            loop_times.append(time.perf_counter() - t0)
        loop_ms = 1e3 * statistics.median(loop_times)
        rows.append((f"IMM-PF step, 2 x {n}", vec_ms, target, loop_ms))
    ekf = IMMEKF()
    se = ekf.initialise(X[0], scn.init_cov)
    holder = [se]
    kk = [0]

    def ekf_step():
        kk[0] = kk[0] % (len(Z) - 1) + 1
        holder[0] = ekf.step(holder[0], Z[kk[0]], sensor)

    ekf_ms = _median_ms(ekf_step, 50 if a.quick else 1000)
    print("| what | vectorised ms (median) | target ms | per-particle loop ms | speed-up | |")
    print("|---|---:|---:|---:|---:|---|")
    for name, v, t, loop in rows:
        print(f"| {name} | {v:.3f} | {t:.1f} | {loop:.1f} | {loop / v:.0f}x | "
              f"{'PASS' if v < t else 'FAIL'} |")
    print(f"| IMM-EKF step (2 models) | {ekf_ms:.3f} | - | - | - | |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
