"""Same tracks in peer hosts: a network run as a process per peer, as peer hosts and on the
twin, on the same scenario, runs and link-fault draws: mean fused OSPA with 95 % intervals.

The packing changes how the peers' messages travel (Zenoh between processes, a hand-off
inside a host, scan bundles), never what a peer computes, so the three must agree: the
per-process and hosted means each inside the other's interval, the twin inside both.

    python benchmarks/bench_same_tracks.py [--peers 12] [--degree 4] [--scans 60] [--runs 5]
        [--first-run 0] [--per-process N] [--set KEY=VALUE ...]

Defaults: 12 GM-PHD peers of degree 4 (one process each keeps real time at that size), 10
scans/s, two consensus rounds, every link delayed 10 ms and losing 5 % of its estimates (the
fault layer, drawn per run the same way in all three), hosts of ``ceil(peers / 2)``. Prints one
row per run and the verdict.
"""

from __future__ import annotations

import argparse
import math
import statistics
import sys
import tempfile
from pathlib import Path

from scipy import stats

if not __package__:  # run as a script: this checkout's code, not the installed one
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from sensornet.sim.run.launcher import read_summaries, start_run, wait_run
from sensornet.sim.run.twin import run_twin
from sensornet.sim.scenario import load_scenario, parse_overrides
from sensornet.sim.world.graphs import network_scenario

FAULTS = ["faults.default.delay=0.01", "faults.default.loss=0.05"]


def interval(xs: list[float]) -> tuple[float, float, float]:
    """Mean and its two-sided 95 % Student-t interval over the runs."""
    m = statistics.fmean(xs)
    if len(xs) < 2:
        return m, float("nan"), float("nan")
    half = stats.t.ppf(0.975, len(xs) - 1) * statistics.stdev(xs) / math.sqrt(len(xs))
    return m, m - half, m + half


def real(source: Path, sets: list[str], run: int, per: int, tmp: Path) -> float:
    """Mean over the peers of their fused OSPA, one run as processes (``per`` peers each)."""
    scn = load_scenario(str(source), overrides=parse_overrides(sets))
    out = tmp / f"run-{run}-{per}"
    handle = start_run(scn, str(source), out, overrides=sets, run=run, rerun=False,
                       sparse=True, per_process=per)
    try:
        codes = wait_run(handle, timeout=scn.num_scans * scn.scan_period
                         / scn.network.speed + 90 + 3 * len(scn.sensors))
    finally:
        handle.stop_all()
    if any(c != 0 for c in codes.values()):
        raise SystemExit(f"run {run} ({per} per process) failed: exit codes {codes}")
    s = read_summaries(out, scn.sensor_names)
    if set(s) != set(scn.sensor_names):
        raise SystemExit(f"run {run} ({per} per process): summaries of {sorted(s)} only")
    return statistics.fmean(v["mean_ospa_fused"] for v in s.values())


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--peers", type=int, default=12)
    p.add_argument("--degree", type=int, default=4)
    p.add_argument("--scans", type=int, default=60)
    p.add_argument("--runs", type=int, default=5)
    p.add_argument("--first-run", type=int, default=0)
    p.add_argument("--per-process", type=int, default=None,
                   help="peers per host (default: half the peers, two hosts)")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="scenario overrides (default: 10 ms delay and 5 %% loss on every link)")
    a = p.parse_args(argv)
    per = a.per_process or math.ceil(a.peers / 2)
    sets = a.set or FAULTS
    with tempfile.TemporaryDirectory(prefix="same-tracks-") as d:
        tmp = Path(d)
        source = tmp / "net.toml"
        source.write_text(network_scenario(a.peers, a.degree, a.scans, rounds=2, speed=10.0))
        scn = load_scenario(str(source), overrides=parse_overrides(sets))
        print(f"{a.peers} peers of degree {a.degree}, {a.scans} scans at 10/s, {' '.join(sets)}; "
              f"hosts of {per}; runs {a.first_run}-{a.first_run + a.runs - 1}\n")
        print("| run | twin | a process per peer | hosts |\n|---:|---:|---:|---:|")
        rows = {"twin": [], "processes": [], "hosts": []}
        for run in range(a.first_run, a.first_run + a.runs):
            twin = run_twin(scn, run)
            rows["twin"].append(statistics.fmean(
                pr.mean_ospa("fused") for pr in twin.peers.values()))
            rows["processes"].append(real(source, sets, run, 1, tmp))
            rows["hosts"].append(real(source, sets, run, per, tmp))
            print(f"| {run} | {rows['twin'][-1]:.3f} | {rows['processes'][-1]:.3f} | "
                  f"{rows['hosts'][-1]:.3f} |", flush=True)
    iv = {k: interval(v) for k, v in rows.items()}
    print("\n| mean fused OSPA (m) | mean | 95 % interval |\n|---|---:|---|")
    for k, (m, lo, hi) in iv.items():
        print(f"| {k} | {m:.3f} | {lo:.3f} - {hi:.3f} |")

    def inside(x: str, y: str) -> bool:
        return iv[y][1] <= iv[x][0] <= iv[y][2]

    checks = {"processes inside hosts'": inside("processes", "hosts"),
              "hosts inside processes'": inside("hosts", "processes"),
              "twin inside processes'": inside("twin", "processes"),
              "twin inside hosts'": inside("twin", "hosts")}
    for what, ok in checks.items():
        print(f"{what} interval: {'yes' if ok else 'NO'}")
    return 0 if all(checks.values()) else 1


if __name__ == "__main__":
    sys.exit(main())
