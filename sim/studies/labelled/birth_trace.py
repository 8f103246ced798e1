"""When fused LMB tracks start, against the local and centralised ones, and what each peer's
inputs held while its fused extraction had no track of a target the centralised filter had
(issue 33, docs/labelled-tracking.md "Where the fused LMB's latency is, and what did not
close it").

One twin run per cell with every peer's fused extraction recorded
(:func:`sim.studies.labelled.gap_trace.record`), then:

* each target's first-track lag: the scans from its birth to the first scan a track of the
  centralised LMB, of each peer's local tracks, of each peer's fused tracks is within
  :data:`~sim.studies.labelled.gap_trace.NEAR` (``c/4``) of it (mean over targets and peers;
  a target never reached is left out and counted);
* every fused-late target-scan: a peer's fused extraction holds no track within ``c/4`` of a
  live target that the centralised filter holds one of, by how many of the round's inputs
  (own density and neighbours' posteriors) hold mass within ``c/4`` of it, whether the heaviest
  holds more than 0.5, and by the target's age (scans since birth).

``python -m sensornet.sim.studies.labelled.birth_trace --runs 100,101 --graphs full3 --pds 0.9
[--set lmb.tentative_threshold=0.01]`` (training runs only: choices are made there).
"""

from __future__ import annotations

import time
from collections import Counter

import numpy as np
from sensornet.sim.studies.labelled.gap_trace import NEAR, first_near, record
from sensornet.sim.studies.labelled.ospa2_floor import GRAPHS, _overrides, cell_arguments
from sensornet.sim.studies.labelled.study import RULES, scenario_of


def lags(rec: dict) -> dict[str, np.ndarray]:
    """First-track lags (scans after birth; module docstring) of ``"central"`` ``(m,)``,
    ``"local"`` and ``"fused"`` ``(peers, m)``; a target never reached: NaN (not a lag counted
    from the run's end, which a late-born target would keep below the run's length)."""
    grid = np.unique(rec["T"].scan)
    Y = rec["T"].dense(grid)[1]
    born = (~np.isnan(Y).any(-1)).argmax(0)

    def lag(first: np.ndarray) -> np.ndarray:
        return np.where(first < len(grid), first - born, np.nan)

    return {"central": lag(first_near(rec["central"], Y, grid)),
            **{w: lag(np.array([first_near(rec[w][p], Y, grid) for p in rec["names"]]))
               for w in ("local", "fused")}}


def held_near(mixes: list, y: np.ndarray) -> np.ndarray:
    """``(I, m)`` each input mixture's mass within :data:`NEAR` of each point ``y (m, 2)``."""
    out = np.zeros((len(mixes), len(y)))
    for i, mix in enumerate(mixes):
        if len(mix):
            d = np.linalg.norm(mix.means[:, None, [0, 2]] - y[None], axis=-1)  # (c, m)
            out[i] = (mix.weights[:, None] * (d < NEAR)).sum(axis=0)
    return out


def late_cases(rec: dict) -> tuple[Counter, Counter]:
    """Fused-late target-scans (module docstring) by ``(inputs holding, heaviest > 0.5)`` and
    by the target's age."""
    grid = np.unique(rec["T"].scan)
    Y = rec["T"].dense(grid)[1]
    alive = ~np.isnan(Y).any(-1)
    born = grid[alive.argmax(0)]
    C = np.nan_to_num(rec["central"].dense(grid)[1], nan=np.inf)
    by_held, by_age = Counter(), Counter()
    for calls in rec["calls"].values():
        for r in calls:
            k = r["k"]
            i = np.searchsorted(grid, k)
            if i >= len(grid) or grid[i] != k or not alive[i].any():
                continue
            t = np.flatnonzero(alive[i])
            y = Y[i, t]
            fused = (np.linalg.norm(r["states"][:, None, [0, 2]] - y[None], axis=-1) < NEAR
                     ).any(axis=0) if len(r["states"]) else np.zeros(len(t), bool)
            central = (np.linalg.norm(C[i][:, None] - y[None], axis=-1) < NEAR).any(axis=0)
            late = central & ~fused
            if not late.any() or r["mixes"] is None:
                continue
            mass = held_near(r["mixes"], y[late])
            for n, top, age in zip((mass > 0).sum(axis=0), mass.max(axis=0) > 0.5,
                                   k - born[t[late]], strict=True):
                by_held[(int(n), bool(top))] += 1
                by_age[int(age)] += 1
    return by_held, by_age


def main(argv: list[str] | None = None) -> int:
    ap = cell_arguments("birth_trace", __doc__, "scenario override of the recorded run",
                        kinds="lmb")
    a = ap.parse_args(argv)
    runs = [int(x) for x in a.runs.split(",")]
    t0 = time.perf_counter()
    for g in a.graphs.split(","):
        for pd in (float(x) for x in a.pds.split(",")):
            scn = scenario_of(GRAPHS[g], "lmb", pd, 10.0, a.scans,
                              {**RULES[a.rule], **_overrides(a.set or [])})
            got: dict[str, list] = {"central": [], "local": [], "fused": []}
            held, age = Counter(), Counter()
            for run in runs:
                rec = record(scn, run)
                for w, v in lags(rec).items():
                    got[w].append(np.ravel(v))
                h, a_ = late_cases(rec)
                held.update(h)
                age.update(a_)
            text = []
            for w, v in got.items():
                v = np.concatenate(v)
                ok = ~np.isnan(v)
                text.append(f"{w} {v[ok].mean():.2f} ({(~ok).sum()} never)")
            print(f"{g} Pd {pd} runs {a.runs}: first-track lag after birth, scans: "
                  + ", ".join(text))
            total = sum(held.values())
            print(f"  fused-late target-scans (peer has none, centralised has one): {total}; "
                  "by (inputs holding, heaviest > 0.5): "
                  + ", ".join(f"{n} {'>' if top else '<='}.5: {c}"
                              for (n, top), c in sorted(held.items())))
            print(f"  by age (scans since birth): {dict(sorted(age.items()))}", flush=True)
    print(f"\n{time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
