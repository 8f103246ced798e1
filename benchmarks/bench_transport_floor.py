"""What the transport alone costs: bare Zenoh processes exchanging a network's message pattern.

``N`` processes, each a Zenoh session configured as a peer's (``peers.session.zenoh_config``:
its own loopback listener, links to its graph neighbours, gossip off: ``--sparse``), publish
``--per-scan`` messages of ``--bytes`` bytes per scan on their own key (express, BLOCK
congestion control, as the peers' publishers) and subscribe to their neighbours' keys. The
subscriber callback does what every peer's does before any tracking logic runs
(``payload.to_bytes()`` and a hand-off through a ``queue.Queue`` to a loop thread that takes
it out); there is no decoding, no filter, no fusion, no world. What these processes spend is a
floor under any peer that sends and receives the same messages: if it approaches the machine's
cores, no tracking logic on top keeps real time.

Prints per run: messages received per process per scan, process CPU per process per scan
(whole process, Zenoh's threads included, from the first scan to the last delivery), the total
in cores, the share of messages delivered, and the publish-to-loop latency (median, p99 of the
pooled samples). Run from the repository root:

    python benchmarks/bench_transport_floor.py --graph seed004 --per-scan 4 \
        --bytes 1060
    python benchmarks/bench_transport_floor.py --peers 20 50 --degree 4 --per-scan 2

(seed004: the scenario's 20-sensor graph; a flooding peer sends one forward per iteration, 4 per
scan, about 1,060 bytes each on average. A consensus peer with 2 rounds sends 2 estimates per
scan, about 1,000 bytes each.) A real peer also receives its scan and the truth and publishes
its tracks, which this pattern leaves out: what it measures is a lower bound.
"""

from __future__ import annotations

import argparse
import json
import os
import queue
import statistics
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np

if not __package__:  # `python benchmarks/bench_transport_floor.py`: the repository root importable
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from sensornet.peers.telemetry import percentile

from benchmarks.bench_network import circulant


def child(i: int, folder: Path) -> None:
    """One bare process: link, report ready, publish on the plan's clock, count, report."""
    import zenoh
    from sensornet.peers.session import endpoint, zenoh_config

    plan = json.loads((folder / "plan.json").read_text())
    A = np.array(plan["adjacency"], dtype=bool)
    ports = plan["ports"]
    nbrs = [int(j) for j in np.flatnonzero(A[i])]
    conf = zenoh_config(listen=[endpoint(ports[i])],
                        connect=[endpoint(ports[j]) for j in nbrs if j < i], gossip=False)
    session = zenoh.open(conf)
    q: queue.Queue = queue.Queue()
    lat: list[float] = []
    got = [0]
    heard: set[int] = set()  # neighbours whose hello arrived: our subscription reached them

    def count(b: bytes) -> None:
        v = float(np.frombuffer(b[:8], dtype=np.float64)[0])
        if v < 0.0:  # a hello, -1 - sender, before the start: not a measured message
            heard.add(int(-v - 1.0))
            return
        lat.append(time.monotonic() - v)
        got[0] += 1

    def on_sample(sample) -> None:
        q.put(sample.payload.to_bytes())

    def loop() -> None:
        while True:
            b = q.get()
            if b is None:
                return
            count(b)

    if plan["handler"] == "fifo":  # one subscriber, its Rust channel read by the loop thread
        sub = session.declare_subscriber("floor/*", zenoh.handlers.FifoChannel(4096))
        subs = [sub]

        def loop() -> None:  # noqa: F811 (the channel instead of the callback + queue)
            while True:
                b = sub.recv().payload.to_bytes()
                if len(b) < 8:
                    return
                count(b)
    elif plan["handler"] == "wildcard":  # one subscriber, one callback thread, the queue
        subs = [session.declare_subscriber("floor/*", on_sample)]
    else:
        subs = [session.declare_subscriber(f"floor/{j}", on_sample) for j in nbrs]
    worker = threading.Thread(target=loop, daemon=True)
    worker.start()
    pub = session.declare_publisher(f"floor/{i}", express=True,  # not to our own subscriber
                                    congestion_control=zenoh.CongestionControl.BLOCK,
                                    allowed_destination=zenoh.Locality.REMOTE)
    # ready once every neighbour's hello arrived (links up is not enough: a put before the
    # neighbour's subscription reaches us is lost); hellos go on until the start signal, so
    # that slower neighbours hear ours
    hello = np.float64(-1.0 - i).tobytes()
    go, end = folder / "go", time.monotonic() + 300.0
    ready = False
    while not go.exists():  # the driver writes it; gone driver: give up
        if time.monotonic() > end:
            session.close()
            raise SystemExit(f"process {i}: no start signal in 300 s")
        pub.put(hello)
        if not ready and heard >= set(nbrs):
            (folder / f"ready.{i}").write_text("1")
            ready = True
        time.sleep(0.05)
    t0 = float(go.read_text())
    rate, per, scans = plan["rate"], plan["per_scan"], plan["scans"]
    body = bytes(plan["bytes"] - 8)
    expected = scans * per * len(nbrs)
    while time.monotonic() < t0:
        time.sleep(0.001)
    cpu0 = time.process_time()
    for k in range(scans):
        for m in range(per):  # the scan's messages spread over its first half
            t = t0 + k / rate + m / (2.0 * rate * per)
            dt = t - time.monotonic()
            if dt > 0:
                time.sleep(dt)
            pub.put(np.float64(time.monotonic()).tobytes() + body)
    deadline = time.monotonic() + 60.0  # a bound for failure only: ends when all arrived
    while got[0] < expected and time.monotonic() < deadline:
        time.sleep(0.005)
    cpu = time.process_time() - cpu0
    if plan["handler"] == "fifo":
        session.put(f"floor/{i}", b"", allowed_destination=zenoh.Locality.SESSION_LOCAL)
    q.put(None)
    worker.join(timeout=5.0)
    result = {"cpu_s": cpu, "received": got[0], "expected": expected, "lat": lat}
    (folder / f"result.{i}.json").write_text(json.dumps(result))
    for s in subs:
        s.undeclare()
    pub.undeclare()
    session.close()


def run(A: np.ndarray, rate: float, per_scan: int, nbytes: int, scans: int, folder: Path,
        handler: str = "callback", timeout: float = 180.0) -> dict:
    """Start one process per node of ``A``, run them, collect their results."""
    from sensornet.peers.session import free_port

    n = len(A)
    folder.mkdir(parents=True, exist_ok=True)
    for p in folder.glob("*"):
        p.unlink()
    ports: list[int] = []
    while len(ports) < n:
        p = free_port()
        if p not in ports:
            ports.append(p)
    (folder / "plan.json").write_text(json.dumps(
        {"adjacency": A.astype(int).tolist(), "ports": ports, "rate": rate,
         "per_scan": per_scan, "bytes": nbytes, "scans": scans,
         "handler": handler}))
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1])}
    procs = [subprocess.Popen([sys.executable, __file__, "--child", str(i), "--dir", str(folder)],
                              env=env) for i in range(n)]
    try:
        end = time.monotonic() + timeout
        while sum((folder / f"ready.{i}").exists() for i in range(n)) < n:
            if time.monotonic() > end or any(p.poll() not in (None, 0) for p in procs):
                raise RuntimeError("the processes did not come up")
            time.sleep(0.05)
        t0 = time.monotonic() + 1.0
        (folder / "go.tmp").write_text(repr(t0))
        (folder / "go.tmp").rename(folder / "go")
        for p in procs:
            p.wait(timeout=max(1.0, end + scans / rate - time.monotonic()))
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()
                p.wait()
    results = [json.loads((folder / f"result.{i}.json").read_text()) for i in range(n)]
    lat = sorted(x for r in results for x in r["lat"])
    duration = scans / rate
    cpu = [r["cpu_s"] / scans * 1e3 for r in results]
    return {"n": n, "degree": float(A.sum(axis=1).mean()),
            "received_per_scan": statistics.mean(r["received"] for r in results) / scans,
            "cpu_ms_mean": statistics.mean(cpu), "cpu_ms_max": max(cpu),
            "cores": sum(r["cpu_s"] for r in results) / duration,
            "delivered": sum(r["received"] for r in results)
            / max(1, sum(r["expected"] for r in results)),
            "lat_median_ms": 1e3 * lat[len(lat) // 2] if lat else float("nan"),
            "lat_p99_ms": 1e3 * percentile(lat, 0.99) if lat else float("nan")}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--graph", choices=["seed004", "circulant"], default="circulant")
    ap.add_argument("--peers", type=int, nargs="+", default=[20])
    ap.add_argument("--degree", type=int, default=4)
    ap.add_argument("--rate", type=float, default=10.0, help="scans per second")
    ap.add_argument("--per-scan", type=int, default=3, help="messages per process per scan")
    ap.add_argument("--bytes", type=int, default=1000, help="bytes per message")
    ap.add_argument("--scans", type=int, default=100)
    ap.add_argument("--runs", type=int, default=1)
    ap.add_argument("--handler", choices=["callback", "wildcard", "fifo", "all"],
                    default="callback",
                    help="callback: one subscriber per neighbour, each a Python callback "
                         "handing off through a queue.Queue (as the peers); wildcard: one "
                         "subscriber to every key (the links bring only the neighbours'), one "
                         "callback, the queue; fifo: one wildcard subscriber whose channel "
                         "the loop thread reads (no callback thread, no queue)")
    ap.add_argument("--dir", default="runs/bench_transport_floor")
    ap.add_argument("--child", type=int, default=None, help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    folder = Path(a.dir)
    if a.child is not None:
        child(a.child, folder)
        return 0
    graphs = []
    if a.graph == "seed004":
        from sensornet.sim.scenario import load_scenario
        from sensornet.sim.world.build import adjacency

        graphs.append(("seed004", adjacency(load_scenario("seed004"))[1]))
    else:
        graphs += [(f"circulant deg {a.degree}", circulant(n, a.degree)) for n in a.peers]
    print(f"bare Zenoh processes, {a.rate:g} scans/s, {a.per_scan} messages of {a.bytes} B "
          f"per process per scan, {a.scans} scans; load average "
          f"{os.getloadavg()[0]:.2f} on {os.cpu_count()} cores")
    print("| graph | handler | processes | mean degree | received / process / scan | CPU ms / "
          "process / scan (mean, max) | total cores | delivered | latency median / p99 ms |")
    print("|---|---|---:|---:|---:|---:|---:|---:|---:|")
    handlers = ["callback", "wildcard", "fifo"] if a.handler == "all" else [a.handler]
    for name, A in graphs:
        for _ in range(a.runs):
            for h in handlers:  # interleaved run for run
                r = run(A, a.rate, a.per_scan, a.bytes, a.scans, folder, h)
                print(f"| {name} | {h} | {r['n']} | {r['degree']:.1f} | "
                      f"{r['received_per_scan']:.1f} | "
                      f"{r['cpu_ms_mean']:.2f}, {r['cpu_ms_max']:.2f} | {r['cores']:.2f} | "
                      f"{100 * r['delivered']:.1f} % | {r['lat_median_ms']:.2f} / "
                      f"{r['lat_p99_ms']:.2f} |", flush=True)
    print(f"load average after: {os.getloadavg()[0]:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
