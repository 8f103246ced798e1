"""Seed 003 peer modes compared offline on the peers' own parts (docs/seed003.md).

Two single-target peers, one per sensor, each an IMM-PDAF (or fuzzy IMM) behind the
:class:`peers.contracts.LocalEstimator` contract (:class:`peers.pda_parts.PdaEstimator`):

* ``local``: each peer on its own sensor, no exchange;
* ``CI``: estimate sharing: each peer publishes its local posterior and fuses the other's
  by covariance intersection (:class:`peers.pda_parts.CiFuser`, the fuser a peer runs); the
  local filters run on (track-to-track fusion);
* ``CI+feedback``: the same, and each peer takes the fused estimate as its next prior (every
  IMM model restarts from the one fused Gaussian: the models' own states are lost);
* ``sequential``: measurement sharing: every peer applies sensor 1's returns, then sensor 2's,
  on the latest estimate (the paper's scheme, exact; both peers hold the same estimate).

The exchange is synchronous (every estimate arrives in its scan), so this is the table of
what the modes can do, not of the network; the process peers are ``sensornet run seed003``
(:mod:`sim.studies.seed003.network`). Clutter is the world's (``clutter.mode = "region"``: the same
clutter
for every mode, as sensors in a network see it), not drawn in each filter's gate.

``python -m sensornet.sim.studies.seed003.peers --runs 200 --jobs 2``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
from sensornet.peers.contracts import FusionInput
from sensornet.peers.pda_parts import CiFuser, PdaEstimator
from sensornet.sim import studies
from sensornet.sim.studies.seed003 import montecarlo as seed003
from sensornet.tracking.imm import POS, VEL

MODES = ("local", "CI", "CI+feedback", "sequential")


def run_once(cfg: Mapping, run: int, method: str = "IMM-PDAF") -> dict[str, np.ndarray]:
    """Position and velocity errors ``(K,)`` per (mode, peer) on run ``run``'s draws."""
    seed = int(cfg["scenario"]["seed"])
    rng = np.random.default_rng([seed, int(run)])
    X = seed003.truth(cfg)
    sens = seed003.sensors(cfg)
    target = seed003.target_returns(X, sens, rng)
    m0, P0 = seed003.initial_state(cfg, X[0], rng)
    region = seed003.region_clutter(cfg, X, sens, rng)
    scans = [[np.vstack([t[i], c[i]]) for i in range(len(sens))]
             for t, c in zip(target, region, strict=True)]
    names = [s["name"] for s in cfg["sensors"]]
    out: dict[str, np.ndarray] = {}

    def record(key: str, est: np.ndarray) -> None:
        d = est - X[1:]
        out[key] = np.stack([np.hypot(d[:, POS[0]], d[:, POS[1]]),
                             np.hypot(d[:, VEL[0]], d[:, VEL[1]])])

    for feedback, mode in ((False, "local"), (False, "CI"), (True, "CI+feedback")):
        peers = [PdaEstimator(seed003.make_filter(cfg, method, m0, P0), s, POS, feedback)
                 for s in sens]
        fusers = [CiFuser() for _ in sens]
        est = np.empty((len(names), len(scans), 6))
        for k, per in enumerate(scans):
            posts = [p.step(1, per[i]).published["posterior"] for i, p in enumerate(peers)]
            for i, p in enumerate(peers):
                if mode == "local":
                    fused = posts[i]
                else:
                    others = {names[j]: {"posterior": posts[j]} for j in range(len(peers))
                              if j != i}
                    fused = fusers[i].fuse(FusionInput(k, 0, posts[i], others,
                                                       [1.0 / len(peers)] * len(peers),
                                                       per[i]))
                p.adopt(fused)
                est[i, k] = p.extract(fused)[0]
        for i, n in enumerate(names):
            record(f"{mode} {n}", est[i])
    flt = seed003.make_filter(cfg, method, m0, P0)
    est, _ = seed003.run_filter(cfg, flt, sens, target, region, None)
    record("sequential s1+s2", est)
    return out


def summarise(cfg: Mapping, results: Sequence[dict[str, np.ndarray]]) -> list[dict]:
    bound, nscan = float(cfg["metrics"]["loss_bound"]), int(cfg["metrics"]["loss_scans"])
    rows = []
    for key in results[0]:
        flags = np.array([seed003.lost(r[key][0], bound, nscan) for r in results])
        kept = [r[key] for r, f in zip(results, flags, strict=True) if not f]
        n, nl = len(results), int(flags.sum())
        lo, hi = seed003.wilson(nl, n)
        rmse = ([float(np.sqrt(np.mean([e[j] ** 2 for e in kept]))) for j in (0, 1)] if kept
                else [float("nan")] * 2)
        rows.append({"mode": key, "runs": n, "lost": nl, "loss_lo": lo, "loss_hi": hi,
                     "rmse_pos": rmse[0], "rmse_vel": rmse[1]})
    return rows


def format_table(rows: Sequence[dict]) -> str:
    head = f"{'mode / peer':<18} {'lost':>9} {'loss rate [95% CI]':>22} {'RMSE pos m':>10} " \
           f"{'RMSE vel':>9}"
    lines = [head, "-" * len(head)]
    for r in rows:
        lines.append(f"{r['mode']:<18} {r['lost']:>4}/{r['runs']:<4} "
                     f"{r['lost'] / r['runs']:>6.1%} [{r['loss_lo']:5.1%},{r['loss_hi']:6.1%}] "
                     f"{r['rmse_pos']:>10.1f} {r['rmse_vel']:>9.1f}")
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m sensornet.sim.studies.seed003.peers``: the study's command line
    (:func:`sim.studies.seed003.peers_study.main`)."""
    return studies.main("seed003-peers", None if argv is None else list(argv))


if __name__ == "__main__":
    raise SystemExit(main())
