"""Cost of ``--ros2`` (issue 35): a peer's CPU per scan with and without its ROS 2 output.

Row (end to end): ``--repeats`` pairs of the default scenario run as processes,
``sensornet run --set scenario.num_scans=S --no-rerun --speed X``, without and with ``--ros2``
(the pair's order alternates); per run the peers' CPU while running (``cpu_s_running`` of
``peer-*.json``, process CPU time) over their scans, in ms per peer-scan, and the ``publish``
share of ``cpu_ms_breakdown``. Printed: the medians, the ratio of the medians and every pair's.
With ``--before DIR`` each repeat also runs ``--ros2`` with ``DIR`` first on ``PYTHONPATH``
(the code before ``peers/ros2_cdr.py``, made as below), the three runs' order rotating.

In process: the ROS 2 work of one peer-scan (both messages built and put, on a Zenoh session
with no links), rosbags' objects + ``serialize_cdr`` (as before) against the CDR packed by
``peers/ros2_cdr.py`` (as now), CPU time, same process; then a cProfile of the packed path.

    python benchmarks/bench_ros2.py                      # 3 pairs of 60 scans at 5x
    python benchmarks/bench_ros2.py --repeats 5 --scans 100 --only inproc
    # the rosbags path as it was (commit e45411f), for --before /tmp/ros2_before/path:
    mkdir -p /tmp/ros2_before/tree /tmp/ros2_before/path
    git archive e45411f | tar -x -C /tmp/ros2_before/tree
    cp -r /tmp/ros2_before/tree/sensornet /tmp/ros2_before/path/
    for d in peers protocol sim tracking; do
        ln -s /tmp/ros2_before/tree/$d /tmp/ros2_before/path/sensornet/$d; done

Target (issue 35): ROS 2 output adds <= 10 % CPU per peer-scan (ratio on/off <= 1.10).
"""

from __future__ import annotations

import argparse
import cProfile
import json
import os
import pstats
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

if not __package__:  # run as a script: this checkout's code, not the installed one
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from sensornet.peers import ros2
from sensornet.peers.session import open_session
from sensornet.protocol.messages import Tracks

TARGET = 1.10


def run_once(kind: str, scans: int, speed: float, out: Path, before: str | None) -> dict:
    """One ``sensornet run`` (``kind``: off, on, before) into ``out``; the peers' CPU ms per
    peer-scan, and its ``publish`` and ``transport`` (Zenoh's threads) shares."""
    cmd = [sys.executable, "-m", "sensornet", "run", "--set", f"scenario.num_scans={scans}",
           "--no-rerun", "--speed", str(speed), "--out", str(out)]
    cmd += [] if kind == "off" else ["--ros2"]
    env = dict(os.environ)
    if kind == "before":
        env["PYTHONPATH"] = os.pathsep.join(filter(None, [before, env.get("PYTHONPATH")]))
    done = subprocess.run(cmd, capture_output=True, text=True, cwd=out.parent, timeout=900,
                          env=env)
    if done.returncode != 0:
        raise SystemExit(f"run failed ({' '.join(cmd)}): {done.stderr.strip()[-400:]}")
    peers = [json.loads(p.read_text()) for p in sorted(out.glob("peer-*.json"))]
    n = sum(p["scans"] for p in peers)
    return {"ms": 1e3 * sum(p["cpu_s_running"] for p in peers) / n} | {
        f"{part}_ms": sum(p["cpu_ms_breakdown"].get(part, 0.0) for p in peers) / n
        for part in ("publish", "transport")}


def end_to_end(args) -> None:
    kinds = ["off", "on"] + (["before"] * (args.before is not None))
    rows: list[dict[str, dict]] = []
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(args.repeats):
            order = kinds[r % len(kinds):] + kinds[:r % len(kinds)]
            got = {k: run_once(k, args.scans, args.speed, Path(tmp) / f"{k}{r}", args.before)
                   for k in order}
            rows.append(got)
            print(f"  repeat {r} ({', '.join(order)}): " + ", ".join(
                f"{k} {got[k]['ms']:.3f} ms (publish {got[k]['publish_ms']:.3f}, transport "
                f"{got[k]['transport_ms']:.3f})"
                for k in kinds) + " per peer-scan; ratios " + ", ".join(
                f"{k}/off {got[k]['ms'] / got['off']['ms']:.3f}" for k in kinds[1:]), flush=True)
    med = {k: statistics.median(g[k]["ms"] for g in rows) for k in kinds}
    pub = {k: statistics.median(g[k]["publish_ms"] for g in rows) for k in kinds}
    zen = {k: statistics.median(g[k]["transport_ms"] for g in rows) for k in kinds}
    print(f"end to end ({args.repeats} repeats, {args.scans} scans at {args.speed}x, 3 peers), "
          "median CPU per peer-scan (publish, transport shares): " + ", ".join(
              f"{k} {med[k]:.3f} ms ({pub[k]:.3f}, {zen[k]:.3f})" for k in kinds))
    for k in kinds[1:]:
        ratio = med[k] / med["off"]
        pairs = statistics.median(g[k]["ms"] / g["off"]["ms"] for g in rows)
        print(f"  ros2 {'now' if k == 'on' else 'before'}: ratio of medians {ratio:.3f}, median "
              f"of the repeats' ratios {pairs:.3f} (target <= {TARGET:.2f}: "
              f"{'PASS' if ratio <= TARGET else 'FAIL'})")
        added = pub[k] - pub["off"]
        print(f"    its publish share added {added:.3f} ms a peer-scan, {added / med['off']:.1%} "
              "of off (steadier than the totals on a loaded machine)")


def scan_tracks(rng, n: int) -> Tracks:
    """Labelled tracks as the default scenario's peers publish them (4-D, covariances)."""
    A = rng.normal(size=(n, 4, 4))
    return Tracks("s1", int(rng.integers(0, 1000)), rng.normal(size=(n, 4)) * 500,
                  ids=rng.integers(0, 1000, size=(n, 3)), covs=A @ A.transpose(0, 2, 1),
                  existence=rng.uniform(size=n), status=rng.integers(0, 2, n).astype(np.int8))


def rosbags_path(face: ros2.PeerRos2, t: Tracks, wall: float) -> None:
    """What ``PeerRos2.tracks`` did before ``peers/ros2_cdr.py``."""
    ns = int(wall * 1e9)
    face.tracks_pub.publish(ros2.tracks_message(t, ns, face.scan_period), ns)
    face.markers_pub.publish(ros2.markers_message(t, ns, face.color_index), ns)


def in_process(args) -> None:
    rng = np.random.default_rng(0)
    msgs = [scan_tracks(rng, int(rng.integers(3, 9))) for _ in range(50)]
    session = open_session((), (), gossip=False)
    face = ros2.PeerRos2(session, "s1")
    try:
        cost = {}
        for name, step in (("rosbags", lambda t: rosbags_path(face, t, time.time())),
                           ("packed", lambda t: face.tracks(t, time.time()))):
            for t in msgs[:5]:
                step(t)
            c0 = time.process_time()
            for _ in range(args.loops):
                for t in msgs:
                    step(t)
            cost[name] = (time.process_time() - c0) * 1e3 / (args.loops * len(msgs))
        print(f"in process (3-8 labelled tracks a scan, both topics built and put): rosbags "
              f"{cost['rosbags']:.3f} ms, packed {cost['packed']:.3f} ms per peer-scan "
              f"({cost['rosbags'] / cost['packed']:.1f}x less)")
        prof = cProfile.Profile()
        prof.enable()
        for t in msgs * 20:
            face.tracks(t, time.time())
        prof.disable()
        print("cProfile of the packed path (1000 peer-scans), top 8 by own time:")
        pstats.Stats(prof).sort_stats("tottime").print_stats(8)
    finally:
        face.close()
        session.close()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3, help="off/on pairs of runs")
    ap.add_argument("--scans", type=int, default=60)
    ap.add_argument("--speed", type=float, default=5.0)
    ap.add_argument("--loops", type=int, default=20, help="in-process loops over 50 scans")
    ap.add_argument("--only", choices=("inproc", "e2e"), help="one of the two measurements")
    ap.add_argument("--before", metavar="DIR", help="also run --ros2 with DIR first on "
                    "PYTHONPATH (the code before peers/ros2_cdr.py: see the docstring)")
    args = ap.parse_args()
    if args.only != "e2e":
        in_process(args)
    if args.only != "inproc":
        end_to_end(args)


if __name__ == "__main__":
    main()
