"""What a view's CPU does to a peer on the core they share, by the view's scheduling class
(issue 38): none, nice 10 (the view before), SCHED_IDLE (``sensornet view --idle``, as
``sensornet run`` starts it).

Two processes pinned to one CPU: a "host" that wakes every ``--period`` ms (a scan) and
does ``--work`` ms of CPU (its peers' steps; a fixed amount of thread CPU, so preemption
shows as wall time), and a "view" that always has work (a busy loop: a view that runs
behind, the worst case) in the class of the setting. Per setting the host's scan -> done
latency (p50 / p99 / max), the scans it finished late (after the next scan came) and the
view's CPU seconds per wall second; settings interleaved ``--repeats`` times, then the
ratios of the medians to the setting without a view. On a machine busy with other work the
absolute numbers move; the ratios of the interleaved settings are the result.

    python benchmarks/bench_view_sched.py                       # 3 x 5 s per setting
    python benchmarks/bench_view_sched.py --seconds 10 --work 60
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np

if not __package__:  # `python benchmarks/bench_view_sched.py`: the repository root importable
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from sensornet.view import idle_process

SETTINGS = ("none", "nice", "idle")
"""No view, a view at nice 10, a view in SCHED_IDLE."""


def _load() -> str:
    return f"{os.getloadavg()[0]:.1f}"


def host(cpu: int, seconds: float, period_ms: float, work_ms: float, out) -> None:
    """Wake every ``period_ms``, burn ``work_ms`` of this thread's CPU, record the latency
    from the wake-up it was due at to done (ms) into ``out``."""
    os.sched_setaffinity(0, {cpu})
    period, work = period_ms / 1e3, work_ms / 1e3
    lat = []
    due = time.monotonic() + period
    end = due + seconds
    x = 0
    while due < end:
        time.sleep(max(0.0, due - time.monotonic()))
        t0 = time.thread_time()
        while time.thread_time() - t0 < work:
            for _ in range(2000):
                x += 1
        lat.append((time.monotonic() - due) * 1e3)
        due += period
        while due < time.monotonic():  # a scan missed entirely: counted as late, skipped
            lat.append(float("inf"))
            due += period
    out.send(lat)


def view(cpu: int, setting: str, seconds: float, out) -> None:
    """Busy for ``seconds`` in the class ``setting``; sends its CPU seconds per wall second."""
    os.sched_setaffinity(0, {cpu})
    if setting == "nice":
        os.setpriority(os.PRIO_PROCESS, 0, min(19, os.getpriority(os.PRIO_PROCESS, 0) + 10))
    elif setting == "idle":
        how, _ = idle_process(10, tids=[0])
        if how != "idle":
            print("view: SCHED_IDLE not permitted here: nice 10 instead", file=sys.stderr)
    c0, t0 = time.process_time(), time.monotonic()
    x = 0
    while time.monotonic() - t0 < seconds:
        for _ in range(20000):
            x += 1
    out.send((time.process_time() - c0) / (time.monotonic() - t0))


def one(setting: str, cpu: int, seconds: float, period_ms: float, work_ms: float) -> dict:
    """One run of ``setting``: the host's latencies and the view's CPU share."""
    ctx = mp.get_context("fork")
    h_recv, h_send = ctx.Pipe(False)
    v_recv, v_send = ctx.Pipe(False)
    procs = [ctx.Process(target=host, args=(cpu, seconds, period_ms, work_ms, h_send))]
    if setting != "none":  # the view starts first and runs past the host's end
        procs.insert(0, ctx.Process(target=view, args=(cpu, setting, seconds + 0.5, v_send)))
    for p in procs:
        p.start()
    lat = np.array(h_recv.recv())
    share = v_recv.recv() if setting != "none" else 0.0
    for p in procs:
        p.join()
    done = lat[np.isfinite(lat)]
    return {"p50": float(np.median(done)), "p99": float(np.percentile(done, 99)),
            "max": float(done.max()), "late": float(np.mean(lat > period_ms)),
            "view": share}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--seconds", type=float, default=5.0, help="per run (default 5)")
    p.add_argument("--repeats", type=int, default=3, help="runs of each setting, interleaved")
    p.add_argument("--period", type=float, default=100.0, help="ms between scans (100)")
    p.add_argument("--work", type=float, default=40.0, help="host CPU ms a scan (40)")
    p.add_argument("--cpu", type=int, default=None, help="the CPU shared (default: the last)")
    args = p.parse_args(argv)
    if not hasattr(os, "sched_setaffinity"):
        p.error("needs Linux (sched_setaffinity, SCHED_IDLE)")
    cpu = args.cpu if args.cpu is not None else max(os.sched_getaffinity(0))
    print(f"## host: {args.work:g} ms CPU every {args.period:g} ms; a busy view on the same "
          f"CPU ({cpu}); {args.seconds:g} s a run; load average {_load()} at the start\n")
    print("| view | rep | host scan->done p50 / p99 / max (ms) | scans done late | view CPU s "
          "per wall s | load |\n|---|---:|---:|---:|---:|---:|", flush=True)
    runs: dict[str, list[dict]] = {s: [] for s in SETTINGS}
    for rep in range(args.repeats):
        for s in SETTINGS:
            r = one(s, cpu, args.seconds, args.period, args.work)
            runs[s].append(r)
            print(f"| {s} | {rep + 1} | {r['p50']:.1f} / {r['p99']:.1f} / {r['max']:.1f} | "
                  f"{100 * r['late']:.1f} % | {r['view']:.2f} | {_load()} |", flush=True)

    def med(s: str, k: str) -> float:
        return statistics.median(r[k] for r in runs[s])

    print("\n| medians | host p50 (ms) | host p99 (ms) | p99 / no view | view CPU s per wall s |"
          "\n|---|---:|---:|---:|---:|")
    for s in SETTINGS:
        print(f"| {s} | {med(s, 'p50'):.1f} | {med(s, 'p99'):.1f} | "
              f"{med(s, 'p99') / med('none', 'p99'):.2f} | {med(s, 'view'):.2f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
