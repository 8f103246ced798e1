"""What OSPA(2) charges on real traffic (issue 34): localisation, gaps, or the track count.

OSPA(2) on a window (Beard, Vo & Vo 2020, Sec. VI; :func:`tracking.track_metrics.ospa2_dense`)
is ``((sum_pairs B + c^p |n - m|) / max(n, m))^(1/p)`` over ``n`` estimated and ``m`` true
tracks present in the window, ``B = base^p`` with ``base`` a pair's mean over the scans where
either exists of ``min(c, d)`` (both exist) or ``c`` (one exists). Its ``p``-th power splits
exactly into

* ``loc``: the pairs' base from scans where both exist and ``d < c`` (localisation),
* ``gap``: the pairs' base from scans where one exists or ``d >= c`` (a track starting late or
  ending early inside the window, a miss),
* ``card``: ``c^p |n - m|`` (tracks without a partner), split by its sign: ``missing``
  (``m > n``: aircraft in the window without a track) and ``extra`` (``n > m``: more track
  ids than aircraft: a switch or a fragment gives an aircraft two ids in one window, or a
  false track),

each pair's ``B`` shared between ``loc`` and ``gap`` in proportion to their parts of its base.
Per window the parts are divided by ``max(n, m)``; their means over windows (``p``-th power
units, m^2 for ``p = 2``) add up to the mean of OSPA(2)^p. So a fusion that halves the
localisation error cannot halve OSPA(2) if ``card`` dominates it.

``python -m sensornet.sim.studies.traffic.ospa2_parts [SCENARIO] --file F --start S --minutes
M [--kinds gmphd,lmb] [--estimates local,fused,centralised] [--set KEY=VALUE ...]``: per
kind, local (each peer), fused (first peer) and centralised: OSPA(2) mean, its RMS
(``mean(OSPA(2)^p)^(1/p)``) and the four shares.
"""

from __future__ import annotations

import argparse
import sys

import numpy as np
from scipy.optimize import linear_sum_assignment
from sensornet.sim.scenario import ScenarioError
from sensornet.sim.studies.traffic.metrics import by_chunks
from sensornet.sim.studies.traffic.study import (
    WINDOW,
    add_window_arguments,
    run_part,
    window_scenario,
)
from sensornet.tracking.track_metrics import TrackTable, _pair_dist

PARTS = ("loc", "gap", "missing", "extra")
"""The parts of OSPA(2)^p (module docstring)."""


def ospa2_parts_dense(E: np.ndarray, Y: np.ndarray, c: float, p: float, window: int
                      ) -> np.ndarray:
    """``(T, 5)`` per window ending at each scan: ``loc``, ``gap``, ``missing``, ``extra``
    (each already divided by ``max(n, m)``) and OSPA(2), for dense estimates ``E (T, n, d)``
    and truth ``Y (T, m, d)`` (NaN rows absent). ``loc + gap + missing + extra ==
    OSPA(2)^p``."""
    T = E.shape[0]
    ex, ty = ~np.isnan(E).any(-1), ~np.isnan(Y).any(-1)
    D = _pair_dist(E, Y)
    either = ex[:, :, None] | ty[:, None, :]
    near = ~np.isnan(D) & (np.nan_to_num(D, nan=np.inf) < c)
    Cl = np.where(near, D, 0.0)  # the localisation part of each scan's cost
    Cg = np.where(near, 0.0, np.where(either, c, 0.0))  # c where one exists or d >= c

    def cum(a: np.ndarray) -> np.ndarray:
        return np.concatenate([np.zeros((1, *a.shape[1:])), np.cumsum(a, axis=0)])

    cL, cG, cU = cum(Cl), cum(Cg), cum(either.astype(float))
    cx, cy = cum(ex.astype(float)), cum(ty.astype(float))
    out = np.zeros((T, 5))
    for k in range(T):
        s, e = max(k + 1 - window, 0), k + 1
        xi, yj = np.nonzero(cx[e] - cx[s])[0], np.nonzero(cy[e] - cy[s])[0]
        n, m = len(xi), len(yj)
        if n == 0 or m == 0:
            out[k] = (0.0, 0.0, c**p * (m > n), c**p * (n > m), 0.0 if n == m else c)
            continue
        sub = np.ix_(xi, yj)
        U = cU[e][sub] - cU[s][sub]
        bl, bg = (cL[e][sub] - cL[s][sub]) / U, (cG[e][sub] - cG[s][sub]) / U
        B = (bl + bg) ** p
        r, q = linear_sum_assignment(B)
        share = np.divide(bl[r, q], bl[r, q] + bg[r, q], out=np.zeros(len(r)),
                          where=(bl[r, q] + bg[r, q]) > 0)
        big = max(n, m)
        loc, gap = (B[r, q] * share).sum() / big, (B[r, q] * (1 - share)).sum() / big
        card = c**p * abs(n - m) / big
        out[k] = (loc, gap, card * (m > n), card * (n > m), (loc + gap + card) ** (1.0 / p))
    return out


def ospa2_parts(truth: TrackTable, est: TrackTable, grid: np.ndarray, c: float, p: float,
                window: int, chunk: int = 400) -> np.ndarray:
    """:func:`ospa2_parts_dense` on a long run, ``chunk`` scans at a time (each window looks
    back ``window - 1`` scans only): ``(T, 5)`` over ``grid (T,)`` (sorted scans)."""
    return by_chunks(lambda E, T: ospa2_parts_dense(E, T, c, p, window), truth, est, grid,
                     window, chunk, shape=(5,))


def summary(parts: np.ndarray, p: float) -> dict[str, float]:
    """Mean OSPA(2), its RMS and the shares of ``loc``, ``gap``, ``missing``, ``extra`` in
    mean OSPA(2)^p."""
    tot = parts[:, :4].sum(axis=1).mean()
    sh = parts[:, :4].mean(axis=0) / tot if tot > 0 else np.zeros(4)
    return {"ospa2": float(parts[:, 4].mean()), "rms": float(tot ** (1.0 / p)),
            **{n: float(v) for n, v in zip(PARTS, sh, strict=True)}}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m sensornet.sim.studies.traffic.ospa2_parts",
                                 description=__doc__.split("\n\n")[0])
    add_window_arguments(ap)
    ap.add_argument("--kinds", default="gmphd,lmb")
    ap.add_argument("--estimates", default="local,fused,centralised")
    ap.add_argument("--run", type=int, default=0)
    a = ap.parse_args(argv)
    try:
        over, scn = window_scenario(a)
    except (ScenarioError, ValueError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    c, p = scn.metrics.ospa_cutoff, scn.metrics.ospa_order
    grid = np.arange(1, scn.num_scans + 1)
    print("kind estimate peer: OSPA(2) mean, rms; shares of mean OSPA(2)^p: loc gap missing "
          "extra")
    for kind in a.kinds.split(","):
        for est in a.estimates.split(","):
            part = run_part(a.scenario, over, kind, est, a.run, with_hota=False,
                            keep_tables=True)
            names = list(part.tables)[:1] if est == "fused" else list(part.tables)
            for name in names:
                s = summary(ospa2_parts(part.truth, part.tables[name], grid, c, p, WINDOW), p)
                print(f"{kind} {est} {name}: {s['ospa2']:.1f}, {s['rms']:.1f}; "
                      + " ".join(f"{s[n]:.2f}" for n in PARTS), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
