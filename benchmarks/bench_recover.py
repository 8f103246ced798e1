"""What recovery (``--recover``: Zenoh's advanced publisher/subscriber, set by ``run --router``)
costs a routed run: the same routed seed-000 run with and without it, in alternating pairs.

Prints, per pair, the peers' scan -> fused-track latency medians (ms) and the ratio of their
means (with / without); with recovery, each publisher also keeps a cache of 64 messages and
puts a heartbeat every 0.5 s.

    python benchmarks/bench_recover.py [--pairs 3] [--scans 40] [--secure]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
from pathlib import Path

if not __package__:  # run as a script: this checkout's code, not the installed one
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from sensornet.sim.run.launcher import read_summaries, start_run, wait_run
from sensornet.sim.scenario import load_scenario, parse_overrides

SETS = ["birth.model=truth"]


def once(out: Path, scans: int, recover: bool, secure: bool) -> list[float]:
    sets = [*SETS, f"scenario.num_scans={scans}"]
    scn = load_scenario("seed000", overrides=parse_overrides(sets))
    keys = None
    if secure:
        from sensornet.peers.security import make_keys

        keys = out / "keys"
        make_keys(f"bench-{out.name}", ["world", *scn.sensor_names, "router"], keys)
    handle = start_run(scn, "seed000", out, network=f"bench-{out.name}" if secure else None,
                       overrides=sets, rerun=False, router=True, recover=recover, secure=keys)
    codes = wait_run(handle, timeout=scans * scn.scan_period / scn.network.speed + 60)
    if any(codes.values()):
        raise SystemExit(f"run in {out} failed: {codes}")
    summaries = read_summaries(out, scn.sensor_names)
    assert all(("recovery" in s) == recover for s in summaries.values())
    return [round(s["latency_ms_median"], 2) for s in summaries.values()]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--pairs", type=int, default=3)
    ap.add_argument("--scans", type=int, default=40)
    ap.add_argument("--secure", action="store_true")
    a = ap.parse_args()
    ratios = []
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(a.pairs):
            on = once(Path(tmp) / f"on{i}", a.scans, True, a.secure)
            off = once(Path(tmp) / f"off{i}", a.scans, False, a.secure)
            ratios.append(statistics.mean(on) / statistics.mean(off))
            print(f"pair {i}: latency medians (ms) with recovery {on}, without {off}: "
                  f"{ratios[-1]:.2f}x", flush=True)
    print(f"with / without recovery: median {statistics.median(ratios):.2f}x "
          f"(pairs {', '.join(f'{r:.2f}' for r in ratios)})")


if __name__ == "__main__":
    main()
