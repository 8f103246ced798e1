"""CPU of the peer logic per peer per scan: the twin of an ``n``-peer circulant network.

The twin (``sim/run/twin.py``) runs every peer's logic (decode, admission, filter, fusion,
encode, scoring) on a virtual clock without transport, so its CPU is what the logic costs.
Each measurement runs in a fresh process, alternating the current code ('after') with the
hot-path modules at the commit before issue 23's per-call work ('before',
``benchmarks/twin_before.py``); per size the medians over ``--repeats`` pairs, the median of
the pairs' ratios and every pair, with the fused OSPA of both (equal OSPA: the speed-up did
not change the tracks). Then
one profiled run of the current code (cProfile), its time split by function group. Three
modes: ``receiver`` (the twin as it is: every receiver decodes its copy), ``host`` (what the
co-hosted peers of ``sensornet run --per-process`` do: one decode shared by all peers, and the
consensus rounds ready at one instant fused together, ``peers.batching``; the 'before' side
has no batching) and ``host-each`` (the shared decode, each round fused at once).

    python benchmarks/bench_twin_cpu.py                       # 50 peers of degree 4, L = 2
    python benchmarks/bench_twin_cpu.py --sizes 20,50,100 --scans 30 --repeats 3
    python benchmarks/bench_twin_cpu.py --modes host --against each   # batched vs each at once

Target (issue 23): <= 1.5 ms CPU per peer per scan at 50 peers of degree 4.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TARGET_MS = 1.5
COMMIT_BEFORE = "d7f97c4"
"""benchmarks/twin_before.py's commit."""

GROUPS: dict[str, list[tuple[str, str]]] = {
    "fusion": [("tracking/fusion.py", "*"), ("tracking/fusion_rules.py", "*"),
               ("tracking/fusion_batch.py", "hybrid_fuse_many")],
    "decode": [("protocol/codec.py", "decode")],
    "encode": [("protocol/codec.py", "encode")],
    "filter predict/update": [("tracking/gmphd.py", "predict"), ("tracking/gmphd.py", "update"),
                              ("tracking/gmphd_batch.py", "step_many")],
    "reduction/merge": [("tracking/reduction.py", "__call__"),
                        ("tracking/reduction.py", "sweep_labels"),
                        ("tracking/reduction.py", "merge"),
                        ("tracking/fusion_batch.py", "reduce_many")],
    "extraction": [("tracking/gmphd.py", "extract")],
    "scoring": [("peers/scoring.py", "*"), ("peers/scan_results.py", "*")],
    "trust": [("peers/trust.py", "*"), ("peers/trust_checks.py", "*")],
    "admission": [("peers/admission.py", "*")],
}
"""Function groups: ``(file suffix, function name or *)`` entry points. A group's time is its
entries' cumulative time less what they spent in another group's entries they call directly;
'bookkeeping' is the rest of the twin's time (the core, consensus, twin's queue)."""


def _group_of(func: tuple[str, int, str]) -> str | None:
    path, _, name = func
    path = path.replace(os.sep, "/")
    for group, entries in GROUPS.items():
        for suffix, fname in entries:
            if path.endswith(suffix) and (fname == "*" or fname == name):
                return group
    return None


def breakdown(stats) -> dict[str, float]:
    """Seconds per group from ``pstats.Stats`` (see :data:`GROUPS`)."""
    raw = stats.stats  # func -> (cc, nc, tt, ct, callers)
    groups = {f: _group_of(f) for f in raw}
    out = dict.fromkeys(GROUPS, 0.0)
    for f, (*_, callers) in raw.items():
        g = groups[f]
        if g is None:
            continue
        # time reached from outside the group only (a group entry calling another adds nothing)
        outside = sum(c[3] for caller, c in callers.items() if groups.get(caller) != g)
        out[g] += outside
        for caller, c in callers.items():  # nested in another group: not that group's time
            cg = groups.get(caller)
            if cg is not None and cg != g:
                out[cg] -= c[3]
    return out


def child(n: int, degree: int, scans: int, rounds: int, before: bool, profile: bool,
          host: bool = False, batch: bool = False) -> dict:
    """One twin run in this process: CPU ms per peer per scan and mean fused OSPA. ``host``:
    every peer decodes through one shared decode, as the peers of one host do
    (``peers.host.SharedDecode``: an estimate decoded once, not once per receiver);
    ``batch``: the rounds ready at one instant fused together (``run_twin(batch=True)``)."""
    if before:
        sys.path.insert(0, str(ROOT))
        from benchmarks import twin_before
        twin_before.install()
    from sensornet.peers.host import SharedDecode
    from sensornet.sim.run.peers import make_peer
    from sensornet.sim.run.twin import run_twin
    from sensornet.sim.scenario import load_scenario
    from sensornet.sim.world.graphs import network_scenario

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / f"net{n}d{degree}.toml"
        path.write_text(network_scenario(n, degree, scans, rounds=rounds, speed=10.0))
        scn = load_scenario(str(path))
    prof = None
    if profile:
        import cProfile
        prof = cProfile.Profile()
        prof.enable()
    peers = {p: make_peer(scn, p, 0, network="twin") for p in scn.sensor_names}
    if host:
        shared = SharedDecode()
        for core in peers.values():
            core.decode = shared
    t0 = time.process_time()
    result = run_twin(scn, 0, peers=peers, **({"batch": True} if batch else {}))
    cpu = time.process_time() - t0
    out = {"ms": cpu * 1e3 / n / scans,
           "ospa": statistics.fmean(result.mean_ospa(p) for p in scn.sensor_names)}
    if prof is not None:
        import pstats
        prof.disable()
        groups = breakdown(pstats.Stats(prof))
        total = sum(s[2] for s in pstats.Stats(prof).stats.values())
        out["groups"] = {g: v * 1e3 / n / scans for g, v in groups.items()}
        out["groups"]["bookkeeping"] = (total - sum(groups.values())) * 1e3 / n / scans
        out["profiled_ms"] = total * 1e3 / n / scans
    return out


def measure(n: int, args, before: bool, profile: bool = False, host: bool = False,
            batch: bool = False) -> dict:
    cmd = [sys.executable, __file__, "--child", str(n), "--degree", str(args.degree),
           "--scans", str(args.scans), "--rounds", str(args.rounds)]
    cmd += ["--before"] * before + ["--profile"] * profile + ["--host"] * host
    cmd += ["--batch"] * (batch and not before)  # the code before has no batch
    done = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT, timeout=3600)
    if done.returncode:
        raise SystemExit(f"child failed: {done.stderr.strip().splitlines()[-1:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sizes", default="50", help="peer counts, comma-separated")
    ap.add_argument("--degree", type=int, default=4)
    ap.add_argument("--rounds", type=int, default=2, help="consensus rounds L")
    ap.add_argument("--scans", type=int, default=30)
    ap.add_argument("--repeats", type=int, default=3, help="before/after pairs per size")
    ap.add_argument("--against", choices=("before", "each"), default="each",
                    help="the 'before' side of each pair: the current code with each peer's "
                         "step and fusion on its own (default: what the host batch saves), or "
                         "the hot path at the commit before issue 23's per-call work (its old "
                         "modules no longer fit today's tree: the run says so and stops)")
    ap.add_argument("--child", type=int, help=argparse.SUPPRESS)
    ap.add_argument("--before", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--profile", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--host", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--batch", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--modes", default="receiver,host",
                    help="receiver: a decode per receiver (the twin as it is); host: one "
                         "shared decode and batched fusions, as the co-hosted peers of one "
                         "host; host-each: the shared decode, each fusion at once")
    args = ap.parse_args()
    if args.child:
        print(json.dumps(child(args.child, args.degree, args.scans, args.rounds, args.before,
                               args.profile, args.host, args.batch)))
        return
    print(f"twin CPU per peer per scan: degree {args.degree}, L = {args.rounds}, {args.scans} "
          f"scans, median of {args.repeats} before/after pairs (before: "
          f"{'commit ' + COMMIT_BEFORE if args.against == 'before' else 'each fusion at once'}"
          f"); load {os.getloadavg()[0]:.1f}")
    print(f"{'peers':>5} {'mode':>9} {'before ms':>10} {'after ms':>9} {'before/after':>12} "
          f"{'OSPA before':>11} {'OSPA after':>10} {'target':>7}")
    modes = args.modes.split(",")
    for n, mode in [(int(s), m) for s in args.sizes.split(",") for m in modes]:
        host, batch = mode in ("host", "host-each"), mode == "host"
        old = args.against == "before"
        pairs = [(measure(n, args, old, host=host),
                  measure(n, args, False, host=host, batch=batch))
                 for _ in range(args.repeats)]
        b = statistics.median(p[0]["ms"] for p in pairs)
        a = statistics.median(p[1]["ms"] for p in pairs)
        ratios = statistics.median(p[0]["ms"] / p[1]["ms"] for p in pairs)
        ob, oa = pairs[0][0]["ospa"], pairs[0][1]["ospa"]
        ok = "PASS" if a <= TARGET_MS else "FAIL"
        print(f"{n:>5} {mode:>9} {b:>10.3f} {a:>9.3f} {ratios:>12.2f} {ob:>11.4f} {oa:>10.4f} "
              f"{ok if n == 50 else '':>7}   pairs: "
              + ", ".join(f"{p[0]['ms']:.2f}/{p[1]['ms']:.2f}" for p in pairs), flush=True)
    n, mode = int(args.sizes.split(",")[-1]), modes[-1]
    prof = measure(n, args, False, profile=True, host=mode in ("host", "host-each"),
                   batch=mode == "host")
    print(f"\nwhere it goes at {n} peers, {mode} (cProfile, {prof['profiled_ms']:.3f} ms per "
          f"peer per scan with the profiler's overhead; load {os.getloadavg()[0]:.1f}):")
    total = prof["profiled_ms"]
    for g, v in sorted(prof["groups"].items(), key=lambda kv: -kv[1]):
        print(f"  {g:<22} {v:7.3f} ms  {100 * v / total:5.1f} %")


if __name__ == "__main__":
    main()
