"""One LMB peer's local step as it runs in bench_fifty's network, before and after the CPU work
of issue 33 ("50 labelled peers in real time"), in one run.

Runs the twin of bench_fifty's network (``--peers`` LMB peers on a circulant graph of degree 4,
2 consensus rounds, its scenario: ``bench_network.scenario_text``), records every
``LmbFilter.step`` call's inputs (the state the peer holds after adopting its fused density,
the scan, the scan index), then replays them through the new step and the old one
(``benchmarks/lmb_before.py``, commit 211455b), interleaved call by call so the machine's load
falls on both alike, and prints thread CPU ms per step of each, their ratio, and how many
steps did not give the same arrays to the bit (0 expected). Also prints the twin's process CPU
per peer-scan (every part of the peers' logic, new code) for the step's share.

    python benchmarks/bench_lmb_step.py                 # 50 peers, 40 scans, 3 replays
    python benchmarks/bench_lmb_step.py --peers 20 --scans 100 --repeats 5
"""

from __future__ import annotations

import argparse
import copy
import dataclasses
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

if not __package__:  # `python benchmarks/bench_lmb_step.py`: the repository root importable
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from sensornet.peers.host import SharedDecode
from sensornet.peers.lmb_estimator import LmbEstimator
from sensornet.sim.run.peers import make_peer
from sensornet.sim.run.twin import run_twin
from sensornet.sim.scenario import load_scenario, parse_overrides
from sensornet.tracking import lmb
from sensornet.tracking.lmb import LmbState

from benchmarks.bench_network import load_average, scenario_text
from benchmarks.lmb_before import LmbFilterBefore

FIELDS = ("labels", "existence", "weights", "means", "covs", "owner")


def record(n: int, degree: int, scans: int, overrides: list[str]) -> tuple[list, float]:
    """Every ``LmbFilter.step`` call of the twin run: ``[(filter, state, scan, k)]`` (copies
    taken before the call, the filter's Generator included), and the run's process CPU ms per
    peer-scan (the copies' CPU taken out). The peers step one by one (no
    ``LmbEstimator.prepare_many``), so that every step is a call."""
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "twin.toml"
        path.write_text(scenario_text(n, degree, scans, rounds=2, speed=10.0))
        scn = load_scenario(str(path), overrides=parse_overrides(
            ["network.filter=lmb", *overrides]))
    calls: list = []
    step = lmb.LmbFilter.step
    copying = [0.0]

    def recording(self, state, scan, k=None):
        t0 = time.process_time()
        calls.append((copy.deepcopy(self), copy.deepcopy(state), np.array(scan, copy=True), k))
        copying[0] += time.process_time() - t0
        return step(self, state, scan, k)

    peers = {q: make_peer(scn, q, 0, network="twin") for q in scn.sensor_names}
    shared = SharedDecode()
    for core in peers.values():
        core.decode = shared
    lmb.LmbFilter.step = recording
    prepare = LmbEstimator.__dict__["prepare_many"]
    del LmbEstimator.prepare_many  # each peer's own step (a prepared one calls no step)
    try:
        t0 = time.process_time()
        run_twin(scn, 0, peers=peers, batch=True)
        spent = time.process_time() - t0 - copying[0]
    finally:
        lmb.LmbFilter.step = step
        LmbEstimator.prepare_many = prepare
    return calls, spent * 1e3 / n / scans


def _same(a: LmbState, b: LmbState) -> bool:
    pairs = [(getattr(a.tracks, f), getattr(b.tracks, f)) for f in FIELDS]
    pairs += [(getattr(a.pending, f), getattr(b.pending, f)) for f in ("weights", "means", "covs")]
    pairs.append((a.hits, b.hits))
    return a.k == b.k and all(np.array_equal(x, y) for x, y in pairs)


def replay(calls: list, repeats: int) -> tuple[float, float, int]:
    """Thread CPU ms per step of the new and the old step over ``repeats`` passes (both on
    every call, which one first alternating, each from the recorded Generator state), and
    the number of steps whose outputs differ."""
    olds = []
    for f, *_ in calls:
        kw = {fl.name: getattr(f, fl.name) for fl in dataclasses.fields(f) if fl.init}
        olds.append(LmbFilterBefore(**kw))
    t_new = t_old = 0.0
    differ = 0
    for rep in range(repeats):
        for i, ((f, state, z, k), g) in enumerate(zip(calls, olds, strict=True)):
            new, old = copy.copy(f), g
            rng = f._rng
            new._rng, old._rng = copy.deepcopy(rng), copy.deepcopy(rng)
            first_new = (i + rep) % 2 == 0  # the second of the two finds the caches warm
            t0 = time.thread_time()
            a = new.step(state, z, k) if first_new else old.step(state, z, k)
            t1 = time.thread_time()
            b = old.step(state, z, k) if first_new else new.step(state, z, k)
            t2 = time.thread_time()
            if not first_new:
                a, b = b, a
            t_new += (t1 - t0) if first_new else (t2 - t1)
            t_old += (t2 - t1) if first_new else (t1 - t0)
            differ += not _same(a, b)
    count = len(calls) * repeats
    return t_new * 1e3 / count, t_old * 1e3 / count, differ


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--peers", type=int, default=50, help="LMB peers (default 50)")
    p.add_argument("--degree", type=int, default=4, help="graph degree (default 4)")
    p.add_argument("--scans", type=int, default=40, help="scans of the twin run (default 40)")
    p.add_argument("--repeats", type=int, default=3, help="replays of the recorded steps")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="scenario overrides for the twin run (e.g. fusion.trust=false)")
    args = p.parse_args(argv)
    calls, per_peer_scan = record(args.peers, args.degree, args.scans, args.set)
    t_new, t_old, differ = replay(calls, args.repeats)
    print(f"## one LMB peer's step, twin of {args.peers} peers of degree {args.degree}, "
          f"{args.scans} scans ({len(calls)} steps x {args.repeats}); load average "
          f"{load_average()}\n")
    print("| step | CPU ms / step |\n|---|---:|")
    print(f"| before (211455b) | {t_old:.3f} |\n| after | {t_new:.3f} |")
    print(f"\nafter / before: {t_new / t_old:.3f}; steps not equal to the bit: {differ} of "
          f"{len(calls) * args.repeats}")
    print(f"the twin's process CPU per peer-scan (all of the peers' logic, new step): "
          f"{per_peer_scan:.2f} ms")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
