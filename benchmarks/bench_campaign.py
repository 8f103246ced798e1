"""Campaign benchmark: the 2-cell x 50-run seed-000 twin campaign on 1 and 2 local workers.

Runs ``sim/campaigns/seed000-twin.toml`` (consensus rounds 1 and 2, 50 Monte Carlo runs each,
100 scans) three ways in one invocation, each into a fresh results folder:

1. ``--jobs 1`` (in this process), 2. ``--jobs 2`` (a local process pool), 3. ``--jobs 2
--dask local`` (a Dask ``LocalCluster``; ``--no-dask`` leaves it out),

and prints the wall time of each (``run_campaign`` as ``sensornet campaign`` calls it: pool or
cluster start-up, every task, every Parquet write and the final compaction are inside the
timed region; loading the campaign file is not), the speed-up of 2 workers over 1 against the
target (>= 1.8x), and whether the three result tables are equal bit for bit (every computed
value compared as exact text, timing columns aside). ``--repeats N`` runs N (1-worker,
2-worker) pairs in alternating order and reports the median ratio.

The speed-up is only meaningful on an otherwise idle machine: the load average before and
after, and the cores each variant actually got (CPU seconds of the tasks / wall), are printed
beside it.

    python benchmarks/bench_campaign.py            # the campaign itself (~2-3 min on 2 cores)
    python benchmarks/bench_campaign.py --quick    # 2 cells x 4 runs x 10 scans (~15 s)
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

if not __package__:  # run as a script: this checkout's code, not the installed one
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

TARGET = 1.8


def campaign_file(tmp: Path, runs: int, scans: int | None) -> Path | str:
    """The shipped seed000-twin campaign, or a copy with fewer scans."""
    if scans is None:
        return "seed000-twin"
    path = tmp / "bench-twin.toml"
    path.write_text(f"""[campaign]
name = "bench-twin"
scenario = "seed000"
runner = "twin"
runs = {runs}

[set]
"scenario.num_scans" = {scans}

[grid]
"network.rounds" = [1, 2]
""")
    return path


def timed(c, folder: Path, **kw) -> dict:
    from sensornet.sim.campaign import canonical_rows, results_table, run_campaign

    t0 = time.perf_counter()
    s = run_campaign(c, folder, progress=False, **kw)
    wall = time.perf_counter() - t0
    table = results_table(folder, complete_only=True)
    task_wall = sum(table.column("seconds").to_pylist())
    return {"wall": wall, "ran": s.ran, "cpu": s.cpu_seconds, "task_wall": task_wall,
            "rows": canonical_rows(table),
            "workers": len(set(table.column("worker").to_pylist()))}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs", type=int, default=50, help="Monte Carlo runs per cell (50)")
    ap.add_argument("--scans", type=int, default=None,
                    help="scans per run (default: the scenario's 100)")
    ap.add_argument("--repeats", type=int, default=1,
                    help="(1-worker, 2-worker) pairs, alternating order; median ratio (1)")
    ap.add_argument("--no-dask", action="store_true", help="leave the Dask LocalCluster out")
    ap.add_argument("--quick", action="store_true", help="2 cells x 4 runs x 10 scans")
    args = ap.parse_args(argv)
    if args.quick:
        args.runs, args.scans = 4, args.scans or 10

    from sensornet.sim.campaign import load_campaign
    from sensornet.sim.campaign.runners import code_version

    # One code version for every worker, whatever is edited in the tree while this runs.
    os.environ.setdefault("SENSORNET_CODE_VERSION", f"bench-{code_version()}")
    load0 = os.getloadavg()
    with tempfile.TemporaryDirectory(prefix="bench-campaign-") as tmpdir:
        tmp = Path(tmpdir)
        c = load_campaign(campaign_file(tmp, args.runs, args.scans), runs=args.runs)
        n_tasks = len(c.tasks())
        print(f"campaign {c.name}: {len(c.cells)} cells x {c.runs} runs = {n_tasks} tasks "
              f"(twin), load average before: {load0[0]:.2f}", flush=True)
        results: dict[str, list[dict]] = {"1 worker": [], "2 workers": []}
        ratios = []
        for rep in range(args.repeats):
            order = ("1 worker", "2 workers") if rep % 2 == 0 else ("2 workers", "1 worker")
            got = {}
            for name in order:
                got[name] = timed(c, tmp / f"{name[0]}-{rep}", jobs=int(name[0]))
                results[name].append(got[name])
                print(f"  {name}: {got[name]['wall']:.2f} s", flush=True)
            ratios.append(got["1 worker"]["wall"] / got["2 workers"]["wall"])
        dask = None
        if not args.no_dask:
            try:
                dask = timed(c, tmp / "dask", jobs=2, dask="local")
                print(f"  Dask LocalCluster, 2 workers: {dask['wall']:.2f} s", flush=True)
            except ImportError as exc:
                print(f"  Dask left out: {exc}")
    load1 = os.getloadavg()

    def row(name: str, r: dict, ratio: str) -> str:
        return (f"| {name} | {r['wall']:.2f} | {ratio} | {r['cpu'] / max(1, r['ran']):.3f} | "
                f"{r['cpu'] / r['wall']:.2f} | {r['workers']} |")

    print()
    print("| runner | wall (s) | speed-up | CPU s per run | cores it got | worker processes |")
    print("|---|---:|---:|---:|---:|---:|")
    for name, rs in results.items():
        for i, r in enumerate(rs):
            ratio = "1.00" if name == "1 worker" else f"{ratios[i]:.2f}x"
            print(row(f"{name}{f' (pair {i + 1})' if args.repeats > 1 else ''}", r, ratio))
    base = statistics.median(r["wall"] for r in results["1 worker"])
    if dask is not None:
        print(row("Dask LocalCluster, 2 workers", dask, f"{base / dask['wall']:.2f}x"))
    ratio = statistics.median(ratios)
    two = results["2 workers"][-1]
    overhead = two["wall"] - two["task_wall"] / 2
    print()
    print(f"2 workers: wall - (task seconds / 2) = {overhead:.2f} s of start-up, hand-off, "
          "writes and tail")
    print(f"load average before {load0[0]:.2f}, after {load1[0]:.2f} (on {os.cpu_count()} "
          "cores: the speed-up measures an idle machine only when both are low)")
    print()
    ok = ratio >= TARGET
    print("| measure | value | target | |")
    print("|---|---:|---:|---|")
    print(f"| speed-up, 2 local workers over 1 (median of {len(ratios)}) | {ratio:.2f}x | "
          f">= {TARGET}x | {'PASS' if ok else 'FAIL'} |")
    tables = [results["1 worker"][0]["rows"], *(r["rows"] for r in results["1 worker"][1:]),
              *(r["rows"] for r in results["2 workers"])]
    names = "1 worker = 2 workers"
    if dask is not None:
        tables.append(dask["rows"])
        names += " = Dask LocalCluster"
    same = all(t == tables[0] for t in tables) and len(tables[0]) == n_tasks
    print(f"| results bit for bit, {names} | {'equal' if same else 'DIFFERENT'} "
          f"({len(tables[0])} rows) | equal | {'PASS' if same else 'FAIL'} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
