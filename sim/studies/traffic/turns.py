"""Where the tracking error of real traffic is: straight vs turning aircraft (issue 34 item 3).

For each peer, estimate (local, fused), tick ``k`` and true aircraft present at ``k - 1``,
``k`` and ``k + 1``: its turn rate ``|heading(k + 1) - heading(k - 1)| / 2T`` (heading of the
truth's velocity, wrapped to 180 degrees) and the x-y distance to the nearest track at ``k``,
capped at the OSPA cut-off ``c`` (farther: a miss). Binned by turn rate, this bounds what a
turn model (an IMM of CV and CT) could win: the error if turning aircraft were tracked as
straight ones. Read from a run folder's ``results.parquet`` (``sensornet run ... --sim``)::

    python -m sensornet.sim.studies.traffic.turns RUN_DIR [--period 2] [--cutoff 1000]

Measured numbers: docs/real-traffic.md ("Motion and the LMB's birth").
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pandas as pd

EDGES = (0.5, 1.5)
"""Turn-rate bin edges (deg/s): straight below the first, turning above the last."""


def turn_errors(results: pd.DataFrame, period: float, cutoff: float = 1000.0) -> pd.DataFrame:
    """One row per (peer, estimate, tick, aircraft) with neighbours on both sides: ``peer``,
    ``estimate``, ``scan``, ``turn_rate`` (deg/s), ``distance`` (m, capped at ``cutoff``),
    ``miss`` (nearest track farther than ``cutoff``)."""
    if period <= 0 or cutoff <= 0:
        raise ValueError(f"period and cutoff must be > 0, got {period}, {cutoff}")
    out = []
    for (peer, est), g in results.groupby(["peer", "estimate"]):
        g = g.sort_values("scan")
        heading = {}
        for k, truth, ids in zip(g.scan, g.truth, g.truth_ids, strict=True):
            x = np.asarray(list(truth), float).reshape(-1, 4)
            for i, h in zip(ids, np.arctan2(x[:, 3], x[:, 1]), strict=True):
                heading[(int(i), int(k))] = h
        for k, truth, ids, tracks in zip(g.scan, g.truth, g.truth_ids, g.tracks, strict=True):
            x = np.asarray(list(truth), float).reshape(-1, 4)
            t = np.asarray(list(tracks), float).reshape(-1, 4)
            d = (np.hypot(x[:, None, 0] - t[None, :, 0], x[:, None, 2] - t[None, :, 2])
                 .min(axis=1) if len(t) else np.full(len(x), np.inf))
            for i, dist in zip(ids, d, strict=True):
                a, b = heading.get((int(i), int(k) - 1)), heading.get((int(i), int(k) + 1))
                if a is None or b is None:
                    continue
                rate = abs((np.degrees(b - a) + 180.0) % 360.0 - 180.0) / (2 * period)
                out.append((peer, est, int(k), rate, min(dist, cutoff), dist > cutoff))
    return pd.DataFrame(out, columns=["peer", "estimate", "scan", "turn_rate", "distance",
                                      "miss"])


def by_turn_rate(errors: pd.DataFrame) -> pd.DataFrame:
    """Per estimate and turn-rate bin (:data:`EDGES`): aircraft-ticks ``n``, mean capped
    ``distance`` and ``miss`` share."""
    bins = pd.cut(errors.turn_rate, [-np.inf, *EDGES, np.inf], right=False,
                  labels=[f"< {EDGES[0]:g}", f"{EDGES[0]:g}-{EDGES[1]:g}", f">= {EDGES[1]:g}"])
    return (errors.assign(turn=bins)
            .groupby(["estimate", "turn"], observed=True)
            .agg(n=("distance", "size"), distance=("distance", "mean"), miss=("miss", "mean")))


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("run", type=Path, help="a run folder holding results.parquet")
    p.add_argument("--period", type=float, default=2.0, help="tick period T (s)")
    p.add_argument("--cutoff", type=float, default=1000.0, help="OSPA cut-off c (m)")
    a = p.parse_args(argv)
    errors = turn_errors(pd.read_parquet(a.run / "results.parquet"), a.period, a.cutoff)
    print(by_turn_rate(errors).round(3).to_string())


if __name__ == "__main__":
    main()
