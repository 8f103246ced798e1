"""Benchmark: GCI fusion of two 4-D Gaussian mixtures, batched against a plain per-pair loop.

Times :func:`tracking.fusion.gci_pair` on 50x50 and 100x100 components (random SPD covariances,
means spread over the surveillance region) beside a per-pair Python loop written here with
``numpy.linalg`` (the formulas of docs/algorithms.md "GCI fusion", one pair at a time), checks that
both give the same mixture (largest relative difference), and prints PASS/FAIL against the issue's
targets: gci_pair under 0.6 ms at 50x50 and under 2 ms at 100x100.

Times are medians over many repeats (this machine is a shared VM: single timings are noisy).
Run from the repository root: ``python benchmarks/bench_gci.py [--quick]``.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

if not __package__:  # run as a script: this checkout's code, not the installed one
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from sensornet.tracking.fusion import gci_pair
from sensornet.tracking.mixture import GaussianMixture

CASES = ((50, 0.6), (100, 2.0))  # (components per mixture, target ms)
OMEGA = 0.5
DIM = 4


def random_mixture(rng: np.random.Generator, n: int) -> GaussianMixture:
    """``n`` 4-D components: weights in (0.05, 1), means over [-1000, 1000] (positions) and
    [-30, 30] m/s (velocities), covariances ``L L^T`` with position std ~ 5-50 m."""
    scale = np.array([1000.0, 30.0, 1000.0, 30.0])
    means = rng.uniform(-1.0, 1.0, (n, DIM)) * scale
    std = rng.uniform(5.0, 50.0, (n, 1)) * np.array([1.0, 0.3, 1.0, 0.3])
    L = rng.normal(size=(n, DIM, DIM)) * 0.3 + np.eye(DIM)
    covs = (L * std[:, :, None]) @ np.swapaxes(L * std[:, :, None], 1, 2) + np.eye(DIM)
    return GaussianMixture(rng.uniform(0.05, 1.0, n), means, covs)


def gci_pair_loop(Di: GaussianMixture, Dj: GaussianMixture, omega: float) -> GaussianMixture:
    """GCI by a plain loop over pairs, ``numpy.linalg`` per pair (docs/algorithms.md "GCI fusion"):

    ``P_ab = [(1-w) P_a^-1 + w P_b^-1]^-1``, ``m_ab = P_ab [(1-w) P_a^-1 m_a + w P_b^-1 m_b]``,
    ``w_ab = w_a^(1-w) w_b^w kappa(1-w, P_a) kappa(w, P_b) N(m_a - m_b; 0, P_a/(1-w) + P_b/w)``,
    ``kappa(w, P) = det(2 pi P / w)^(1/2) / det(2 pi P)^(w/2)``.
    """
    d = Di.dim

    def kappa(o, P):
        return np.sqrt(np.linalg.det(2 * np.pi * P / o)) / np.linalg.det(2 * np.pi * P) ** (o / 2)

    def normal(x, P):
        return np.exp(-0.5 * x @ np.linalg.solve(P, x)) / np.sqrt(np.linalg.det(2 * np.pi * P))

    weights, means, covs = [], [], []
    for wa, ma, Pa in zip(Di.weights, Di.means, Di.covs, strict=True):
        Ya = np.linalg.inv(Pa)
        ka = kappa(1 - omega, Pa)
        for wb, mb, Pb in zip(Dj.weights, Dj.means, Dj.covs, strict=True):
            Yb = np.linalg.inv(Pb)
            P = np.linalg.inv((1 - omega) * Ya + omega * Yb)
            means.append(P @ ((1 - omega) * Ya @ ma + omega * Yb @ mb))
            covs.append(P)
            weights.append(wa ** (1 - omega) * wb**omega * ka * kappa(omega, Pb)
                           * normal(ma - mb, Pa / (1 - omega) + Pb / omega))
    return GaussianMixture(np.array(weights), np.array(means).reshape(-1, d),
                           np.array(covs).reshape(-1, d, d))


def median_ms(fn, repeats: int) -> float:
    fn()  # warm-up
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return 1e3 * float(np.median(times))


def max_rel_diff(a: GaussianMixture, b: GaussianMixture) -> tuple[float, float, float]:
    """Largest ``|a - b| / max|b|`` of the weights, means and covariances."""
    return tuple(float(np.max(np.abs(x - y)) / np.max(np.abs(y)))
                 for x, y in ((a.weights, b.weights), (a.means, b.means), (a.covs, b.covs)))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=300,
                    help="timed calls of gci_pair per case (default 300)")
    ap.add_argument("--loop-repeats", type=int, default=3,
                    help="timed calls of the per-pair loop per case (default 3)")
    ap.add_argument("--seed", type=int, default=0, help="seed of the random mixtures")
    ap.add_argument("--quick", action="store_true", help="CI smoke test: few repeats")
    args = ap.parse_args(argv)
    if args.quick:
        args.repeats, args.loop_repeats = 30, 1
    rng = np.random.default_rng(args.seed)

    print(f"GCI of two 4-D mixtures, omega = {OMEGA}: tracking.fusion.gci_pair vs a per-pair "
          f"numpy.linalg loop; median of {args.repeats} (batched) / {args.loop_repeats} (loop) "
          f"calls")
    head = (f"{'pairs':<9} {'gci_pair ms':>11} {'loop ms':>9} {'speed-up':>9} {'target':>8}  "
            f"{'max rel diff w / m / P':>26}  result")
    print(head)
    print("-" * len(head))
    ok = True
    for n, target in CASES:
        Di, Dj = random_mixture(rng, n), random_mixture(rng, n)
        fast = median_ms(lambda Di=Di, Dj=Dj: gci_pair(Di, Dj, OMEGA), args.repeats)
        slow = median_ms(lambda Di=Di, Dj=Dj: gci_pair_loop(Di, Dj, OMEGA), args.loop_repeats)
        diff = max_rel_diff(gci_pair(Di, Dj, OMEGA), gci_pair_loop(Di, Dj, OMEGA))
        passed = fast < target and max(diff) < 1e-9
        ok &= passed
        print(f"{f'{n}x{n}':<9} {fast:11.3f} {slow:9.1f} {slow / fast:8.0f}x {f'<{target:g} ms':>8}"
              f"  {' / '.join(f'{x:.1e}' for x in diff):>26}  {'PASS' if passed else 'FAIL'}")
    print("overall:", "PASS" if ok else "FAIL")
    return 0


if __name__ == "__main__":
    sys.exit(main())
