"""What a padding member costs its neighbours (issue 36 items 1-2): time per peer-scan, padded
against honest, with the defence (``fusion.trust``) on and off, in one run.

Seed 000 on the twin (3 peers, full mesh, virtual clock): s2 sends its real estimate padded
with negligible-weight components (weight 1e-4, spread over the region) up to ``--pad``
components (the codec's 2,000 by default), one estimate per scan, inside its message rate.
The time is what the honest peers s1 and s3 spend in their core (``receive`` and ``tick``:
decoding, admission, the budget's reduction, trust tests, fusion), summed and divided by
their peer-scans; nothing else of the twin is timed. Also the components that reached the
trust test's divergence (largest call) and the estimates refused for their size or reduced.
``--no-budget`` runs the same without :mod:`peers.budget` (the byte budget and the reduction
off: what the issue measured).

    python benchmarks/bench_padding.py [--scans 40] [--pad 2000] [--repeat 3] [--no-budget]

Prints one row per (trust, case) and the ratio padded / honest per trust setting (the issue's
target: a fixed small multiple).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402
import sensornet.peers.core as core_mod  # noqa: E402
import sensornet.peers.trust as trust_mod  # noqa: E402
import sensornet.peers.trust_checks as checks_mod  # noqa: E402
import sensornet.tracking.divergence as divergence  # noqa: E402
from sensornet.sim.run.lies import LyingCore  # noqa: E402
from sensornet.sim.run.peers import make_peer  # noqa: E402
from sensornet.sim.run.twin import run_twin  # noqa: E402
from sensornet.sim.scenario import load_scenario  # noqa: E402
from sensornet.tracking.mixture import GaussianMixture  # noqa: E402

HONEST = ("s1", "s3")


def padding(n: int, region, rng: np.random.Generator):
    """The lie: the real mixture plus negligible-weight components up to ``n``."""
    (x0, x1), (y0, y1) = region

    def lie(mix: GaussianMixture, k: int = 0) -> GaussianMixture:
        m = max(0, n - len(mix))
        means = np.zeros((m, mix.dim))
        means[:, 0], means[:, 2] = rng.uniform(x0, x1, m), rng.uniform(y0, y1, m)
        extra = GaussianMixture(np.full(m, 1e-4), means, np.tile(100.0 * np.eye(mix.dim),
                                                                 (m, 1, 1)))
        return GaussianMixture.concatenate([mix, extra])
    return lie




def one(scn, pad: int | None, seed: int) -> dict:
    """One twin run (``pad`` None: honest); the honest peers' core time and counts."""
    calls: list[int] = []
    orig = divergence.log_overlaps

    def counted(mixes):
        calls.append(sum(len(m) for m in mixes))
        return orig(mixes)

    checks_mod.log_overlaps = trust_mod.log_overlaps = counted
    spent = [0.0]
    peers = {n: make_peer(scn, n, 0) for n in scn.sensor_names}
    for n in HONEST:
        core = peers[n]
        for name in ("receive", "tick"):
            f = getattr(core, name)

            def timed(*a, _f=f, **kw):
                t = time.perf_counter()
                try:
                    return _f(*a, **kw)
                finally:
                    spent[0] += time.perf_counter() - t
            setattr(core, name, timed)
    if pad is not None:
        peers["s2"] = LyingCore(peers["s2"], padding(pad, scn.region,
                                                     np.random.default_rng(seed)))
    try:
        res = run_twin(scn, 0, peers=peers)
    finally:
        checks_mod.log_overlaps = trust_mod.log_overlaps = orig
    sums = [res.summary(n) for n in HONEST]
    scans = sum(s["scans"] for s in sums)
    b = [s["budget"] for s in sums]
    return {"ms": 1e3 * spent[0] / max(scans, 1), "largest": max(calls, default=0),
            "ospa": float(np.mean([res.mean_ospa(n) for n in HONEST])),
            "deadline": sum(s["stats"]["deadline_fusions"] for s in sums),
            "refused": sum(sum(x["refused"].values()) for x in b),
            "reduced": sum(sum(x["reduced"].values()) for x in b)}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scans", type=int, default=40)
    ap.add_argument("--pad", type=int, default=2000)
    ap.add_argument("--repeat", type=int, default=3, help="runs per cell (the median kept)")
    ap.add_argument("--no-budget", action="store_true",
                    help="without peers.budget (no byte budget, no reduction)")
    a = ap.parse_args(argv)
    if a.no_budget:
        core_mod.EstimateBudget.of = staticmethod(lambda *args: None)
    print(f"seed 000 twin, {a.scans} scans, s2 padded to {a.pad} components, "
          f"budget {'off' if a.no_budget else 'on'}; time in s1+s3's core per peer-scan "
          f"(median of {a.repeat})")
    print("| trust | case | ms / peer-scan | largest divergence call (components) | "
          "fused OSPA | deadline fusions | refused (bytes) | reduced |")
    print("|---|---|---:|---:|---:|---:|---:|---:|")
    ratios = {}
    for trust in (False, True):
        scn = load_scenario("seed000", overrides={
            "fusion.rule": "hybrid", "fusion.trust": trust, "scenario.num_scans": a.scans,
            "birth.model": "truth"})
        row = {}
        for case, pad in (("honest", None), ("padded", a.pad)):
            runs = [one(scn, pad, 100 + r) for r in range(a.repeat)]
            r = dict(runs[0])
            r["ms"] = float(np.median([x["ms"] for x in runs]))
            row[case] = r
            print(f"| {'on' if trust else 'off'} | {case} | {r['ms']:.2f} | {r['largest']} | "
                  f"{r['ospa']:.1f} | {r['deadline']} | {r['refused']} | {r['reduced']} |")
        ratios[trust] = row["padded"]["ms"] / max(row["honest"]["ms"], 1e-9)
    for trust, q in ratios.items():
        print(f"trust {'on' if trust else 'off'}: padded / honest = {q:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
