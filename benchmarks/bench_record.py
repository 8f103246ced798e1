"""Recording benchmark: what ``sensornet run --record`` costs a 3-peer seed-000 run.

Runs the seed-000 network (3 peers as processes over Zenoh on loopback, 10 scans/s, 100 scans,
truth births, Rerun off, as the latency part of ``bench_network.py``) in pairs: one run with
every peer recording its core's inputs (``--record``: ``record/peer-<name>.mcap``), one
without, the order alternating from pair to pair so that a drift in the machine's load falls
on both, after one uncounted warm-up run. Per run, the median of the pooled scan -> fused-track
latencies (one sample per scan and peer, from the peers' summaries); per variant, the median of
those medians. Prints:

* the latency with and without recording and their ratio, against the target (<= 5 % more);
* the size of one run's recording (every peer's ``.mcap``), against the target (<= 20 MB);
* whether the recording replays bit for bit (``sensornet replay``: every peer's fused tracks
  byte for byte), for the last recorded run.

    python benchmarks/bench_record.py              # 5 pairs of 100-scan runs (~3 min)
    python benchmarks/bench_record.py --quick      # 1 pair of 20-scan runs (~20 s)
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
from pathlib import Path

if not __package__:  # run as a script: this checkout's code, not the installed one
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

TARGETS = {"latency_ratio": 1.05, "size_mb": 20.0}


def one_run(out: Path, scans: int, record: bool) -> dict:
    """One run: its pooled latency median, recording bytes and exit codes."""
    from sensornet.sim.run.launcher import read_summaries, start_run, wait_run
    from sensornet.sim.scenario import load_scenario, parse_overrides

    sets = ["birth.model=truth", f"scenario.num_scans={scans}", "network.speed=10"]
    scn = load_scenario("seed000", overrides=parse_overrides(sets))
    handle = start_run(scn, "seed000", out, overrides=sets, rerun=False,
                       peer_args={n: ["--record"] for n in scn.sensor_names} if record
                       else None)
    try:
        codes = wait_run(handle, timeout=scans / 10 + 90)
    finally:
        handle.stop_all()
    s = read_summaries(out, scn.sensor_names)
    lat = [x for v in s.values() for x in v.get("latency_ms_samples") or []]
    files = sorted((out / "record").glob("*.mcap")) if record else []
    return {"median": statistics.median(lat) if lat else float("nan"), "samples": len(lat),
            "codes": codes, "peers": len(s), "files": files,
            "bytes": sum(f.stat().st_size for f in files)}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--pairs", type=int, default=5, help="(recorded, plain) pairs (5)")
    ap.add_argument("--scans", type=int, default=100, help="scans per run (100)")
    ap.add_argument("--warmup", type=int, default=1,
                    help="plain 20-scan runs first, not counted (1)")
    ap.add_argument("--quick", action="store_true", help="1 pair of 20-scan runs")
    args = ap.parse_args(argv)
    if args.quick:
        args.pairs, args.scans = 1, 20
    load0 = os.getloadavg()
    runs: dict[bool, list[dict]] = {True: [], False: []}
    with tempfile.TemporaryDirectory(prefix="bench-record-") as tmpdir:
        tmp = Path(tmpdir)
        print(f"seed000, 3 peers, {args.scans} scans at 10 scans/s, {args.pairs} pairs; "
              f"load average before: {load0[0]:.2f}", flush=True)
        for i in range(args.warmup):  # file caches, .pyc files, Zenoh's first start
            one_run(tmp / f"warmup-{i}", min(args.scans, 20), False)
        for i in range(args.pairs):
            order = (True, False) if i % 2 == 0 else (False, True)
            for rec in order:
                r = one_run(tmp / f"{'rec' if rec else 'plain'}-{i}", args.scans, rec)
                runs[rec].append(r)
                bad = {k: v for k, v in r["codes"].items() if v != 0}
                print(f"  pair {i + 1} {'recorded' if rec else 'plain   '}: median "
                      f"{r['median']:.2f} ms over {r['samples']} samples"
                      + (f", {r['bytes'] / 1e6:.2f} MB recorded" if rec else "")
                      + (f"  (exit codes {bad})" if bad else ""), flush=True)
        last = runs[True][-1]
        identical, replayed = 0, 0
        if last["files"]:
            from sensornet.sim.run.replay import replay

            for f in last["files"]:
                replayed += 1
                identical += replay(f).identical
    load1 = os.getloadavg()
    med = {rec: statistics.median(r["median"] for r in rs) for rec, rs in runs.items()}
    ratio = med[True] / med[False]
    size_mb = max(r["bytes"] for r in runs[True]) / 1e6
    per_scan = 1e3 * size_mb / args.scans
    complete = all(r["peers"] == 3 and all(c == 0 for c in r["codes"].values())
                   for rs in runs.values() for r in rs)
    print()
    print(f"load average before {load0[0]:.2f}, after {load1[0]:.2f} (on {os.cpu_count()} cores)"
          + ("" if complete else "; some runs did not finish cleanly (see above)"))
    print()
    print("| measure | value | target | |")
    print("|---|---:|---:|---|")
    print(f"| scan -> fused tracks, median of {args.pairs} run medians, plain (ms) | "
          f"{med[False]:.2f} | | |")
    print(f"| the same, recorded (ms) | {med[True]:.2f} | | |")
    ok = ratio <= TARGETS["latency_ratio"]
    print(f"| recorded / plain | {ratio:.3f} ({100 * (ratio - 1):+.1f} %) | <= "
          f"{TARGETS['latency_ratio']:.2f} | {'PASS' if ok else 'FAIL'} |")
    ok = size_mb <= TARGETS["size_mb"]
    note = "" if args.scans == 100 else f" ({per_scan:.0f} kB/scan x 100 = {per_scan / 10:.2f})"
    print(f"| recording of one {args.scans}-scan run, 3 peers (MB) | {size_mb:.2f}{note} | <= "
          f"{TARGETS['size_mb']:.0f} | {'PASS' if ok else 'FAIL'} |")
    ok = replayed > 0 and identical == replayed
    print(f"| peers whose replay is identical to the last bit | {identical}/{replayed} | "
          f"all | {'PASS' if ok else 'FAIL'} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
