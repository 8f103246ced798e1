"""Can a stopped view hold the world back? (issue 38: a slow viewer drops its own work, never
the peers')

The world puts its scans, scan bundles, truth and control with congestion control BLOCK
(``sim/run/world_process.py``: nothing dropped under load), and the view subscribes to them.
This puts ``--size`` byte messages on one key from a publisher with the world's session
settings (``peers.session.open_session``), BLOCK and then DROP (the peers' reports), to a
subscriber in a child process that dials it as the view does (``LiveView.open``: its
callback only queues) and is stopped (SIGSTOP: Ctrl-Z on a terminal, a debugger) once
matched; back to back, or one every ``--every`` ms (a world's pace). Per mode: the puts
made, the longest one, when it came (MB put before it), how long the puts took in all and
when the publisher stopped matching the subscriber (its link gone). A
put that waits is the world's scan schedule waiting, and every peer's with it. A stopped
subscriber answers no keep-alive either: its link goes at Zenoh's lease, so only what fills
the link's buffers (a few MB) before then can make a put wait.

    python benchmarks/bench_stopped_view.py                  # 100 kB back to back, 30 MB at most
    python benchmarks/bench_stopped_view.py --size 4600 --every 10   # seed004's world, paced
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import zenoh

if not __package__:  # `python benchmarks/bench_stopped_view.py`: the repository root importable
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from sensornet.peers.session import endpoint, free_port, open_session  # noqa: E402

VIEW = """
import queue, sys, time, zenoh
from sensornet.peers.session import DIAL_SOON, zenoh_config
q = queue.Queue(maxsize=20_000)
s = zenoh.open(zenoh_config((), [sys.argv[1]], retry=DIAL_SOON))
sub = s.declare_subscriber("bench/stopped/x", lambda x: q.put_nowait(x.payload.to_bytes()))
print("subscribed", flush=True)
time.sleep(3600)
"""
"""The stopped subscriber: a view's session (``zenoh_config`` as ``LiveView.open``) whose
callback queues what it hears."""


def one(mode: str, size: int, total_mb: float, seconds: float, every_ms: float = 0.0) -> dict:
    """Puts to a stopped subscriber with congestion control ``mode`` (one every ``every_ms``;
    0: back to back): how long they waited."""
    ep = endpoint(free_port())
    session = open_session(listen=[ep])
    cc = zenoh.CongestionControl.BLOCK if mode == "block" else zenoh.CongestionControl.DROP
    pub = session.declare_publisher("bench/stopped/x", congestion_control=cc)
    view = subprocess.Popen([sys.executable, "-c", VIEW, ep], stdout=subprocess.PIPE, text=True,
                            env={**os.environ, "PYTHONPATH": str(Path(__file__).parents[1])})
    try:
        if view.stdout.readline().strip() != "subscribed":
            raise SystemExit("the subscriber did not start")
        end = time.monotonic() + 60.0
        while not pub.matching_status.matching and time.monotonic() < end:
            time.sleep(0.02)
        os.kill(view.pid, signal.SIGSTOP)
        payload = b"\0" * size
        worst, worst_at, n, gone = 0.0, 0, 0, None
        t0 = time.monotonic()
        while n * size < total_mb * 1e6 and time.monotonic() - t0 < seconds:
            t = time.monotonic()
            pub.put(payload)
            dt = time.monotonic() - t
            n += 1
            if dt > worst:
                worst, worst_at = dt, n
            if gone is None and not pub.matching_status.matching:  # its link went
                gone = time.monotonic() - t0
            if every_ms:
                time.sleep(every_ms / 1e3)
        return {"mode": mode, "puts": n, "worst_s": worst, "worst_after_mb": worst_at * size / 1e6,
                "all_s": time.monotonic() - t0, "gone_s": gone}
    finally:
        os.kill(view.pid, signal.SIGCONT)
        view.kill()
        view.wait()
        pub.undeclare()
        session.close()


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--size", type=int, default=100_000, help="bytes a message")
    p.add_argument("--mb", type=float, default=30.0, help="MB put at most per mode")
    p.add_argument("--seconds", type=float, default=40.0, help="seconds of puts at most")
    p.add_argument("--every", type=float, default=0.0, metavar="MS",
                   help="a put every MS ms (default 0: back to back)")
    args = p.parse_args(argv)
    print("| congestion control | puts | longest put (s) | came after (MB put) | all puts (s) | "
          "unmatched after (s) |")
    print("|---|---:|---:|---:|---:|---:|")
    for mode in ("block", "drop"):
        r = one(mode, args.size, args.mb, args.seconds, args.every)
        gone = "-" if r["gone_s"] is None else f"{r['gone_s']:.1f}"
        print(f"| {mode} | {r['puts']} | {r['worst_s']:.2f} | {r['worst_after_mb']:.1f} | "
              f"{r['all_s']:.1f} | {gone} |", flush=True)
    pace = f"one every {args.every:g} ms" if args.every else "back to back"
    print(f"\n{args.size} bytes a message, {pace}, the subscriber stopped; load average "
          f"{os.getloadavg()[0]:.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
