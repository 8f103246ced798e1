"""Soak: a long run at full speed with faults on; checks each peer's memory does not grow.

Runs the seed-000 network (world + 3 peers as processes) for ``--scans`` scans (default
10,000) as fast as ``--speed`` allows, with link loss, duplication and reordering, Rerun
recording on (the recording path is part of what must not leak), and prints each peer's
resident memory after scan 1,000 and after the last scan. Target: within 10 %.

    python benchmarks/soak.py                 # 10,000 scans (a few minutes)
    python benchmarks/soak.py --scans 2000    # shorter
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

if not __package__:  # run as a script: this checkout's code, not the installed one
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from sensornet.sim.run.launcher import read_summaries, start_run, wait_run
from sensornet.sim.scenario import load_scenario, parse_overrides


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--scans", type=int, default=10_000)
    p.add_argument("--speed", type=float, default=100.0, help="scans per second (T = 1 s)")
    p.add_argument("--no-rerun", action="store_true", help="without the Rerun recording")
    p.add_argument("--keep", help="keep the run folder here")
    args = p.parse_args(argv)
    sets = ["birth.model=truth", f"scenario.num_scans={args.scans}",
            f"network.speed={args.speed}", "network.deadline=0.9",
            "faults.default.loss=0.1", "faults.default.duplicate=0.1",
            "faults.default.reorder=0.5",
            'faults.default.delay={kind="uniform", low=0.0, high=0.002}']
    scn = load_scenario("seed000", overrides=parse_overrides(sets))
    with tempfile.TemporaryDirectory(prefix="sensornet-soak-") as tmp:
        out = Path(args.keep) if args.keep else Path(tmp)
        out.mkdir(parents=True, exist_ok=True)
        t0 = time.monotonic()
        handle = start_run(scn, "seed000", out, overrides=sets, rerun=not args.no_rerun)
        try:
            codes = wait_run(handle, timeout=args.scans / args.speed * 3 + 120)
        finally:
            handle.stop_all()
        wall = time.monotonic() - t0
        summaries = read_summaries(out, scn.sensor_names)
    print(f"soak: {args.scans} scans at up to {args.speed:g} scans/s, faults on, Rerun "
          f"{'off' if args.no_rerun else 'on'}; {wall:.0f} s wall; exit codes {codes}")
    print("| peer | scans | RSS after scan 1 (MB) | after 1000 | after last | last / 1000 | "
          "target |")
    print("|---|---:|---:|---:|---:|---:|---|")
    ok = len(summaries) == len(scn.sensors)
    for name, s in summaries.items():
        samples = dict((int(k), v) for k, v in s["rss_mb_samples"])
        first, at1000 = samples.get(1), samples.get(1000)
        last = s["rss_mb_samples"][-1][1]
        ratio = last / at1000 if at1000 else float("nan")
        good = at1000 is not None and ratio <= 1.10
        ok &= good
        print(f"| {name} | {s['scans']} | {first or 0:.1f} | {at1000 or 0:.1f} | {last:.1f} | "
              f"{ratio:.3f} | {'PASS' if good else 'FAIL'} (<= 1.10) |")
    for name, s in summaries.items():
        print(f"{name}: rejected {s['rejected_total']}, internal errors {s['internal_errors']}, "
              f"deadline fusions {s['stats']['deadline_fusions']}, faults {s['injected_faults']}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
