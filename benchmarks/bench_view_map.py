"""What the geographic map costs the live view (issue 34 item 5, :mod:`sensornet.view_map`).

Feeds the view's drawing the truth of ``paris`` (the shipped excerpt's aircraft at the
scenario's ticks, about 20 in the air) and each of ``--peers`` peers' labelled fused tracks
(the truth plus 100 m noise, one id per aircraft), encoded as on the wire, for ``--scans``
scans, flushing every 5 scans (a second at the scenario's 10x), into a real ``.rrd`` (Rerun
FileSink); prints the CPU per scan of :class:`sensornet.view.ViewState` (the 2-D map only) and
of :class:`sensornet.view_map.GeoViewState` (both maps) and their ratio.

    python benchmarks/bench_view_map.py                  # 4 peers, 300 scans
    python benchmarks/bench_view_map.py --peers 8 --scans 300
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import rerun as rr

if not __package__:  # run as a script: this checkout's code, not the installed one
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from sensornet.protocol.codec import encode
from sensornet.protocol.messages import Tracks, Truth
from sensornet.sim.scenario import load_scenario
from sensornet.sim.traffic.recorded import recorded_world, truth_ids

from sensornet.view import Batcher, ViewState
from sensornet.view_map import GeoViewState, geo_map


def messages(peers: list[str], scans: int,
             rng: np.random.Generator) -> list[list[tuple[str, bytes]]]:
    """Per scan: the truth and each peer's tracks, ``(key, payload)``."""
    scn = load_scenario("paris", overrides={"scenario.num_scans": scans})
    world = recorded_world(scn)
    grid = world.grid
    out = []
    for k in range(1, scans + 1):
        icao, X = grid.planar(k - 1)  # [px, vx, py, vy] of the aircraft present
        ids = truth_ids(icao)
        here = np.flatnonzero(grid.present[k - 1])  # a track id per aircraft
        batch = [("sensornet/b/truth", encode(Truth(k, ids, X)))]
        for n in peers:
            noisy = X + rng.normal(0.0, 100.0, X.shape) * [1, 0, 1, 0]
            tid = np.column_stack([np.zeros(len(here), np.int64), here, np.zeros(len(here))])
            batch.append((f"sensornet/b/tracks/{n}",
                          encode(Tracks(n, k, noisy, ids=tid.astype(np.int64)))))
        out.append(batch)
    return out


def run(geo: bool, peers: int, scans: int, out: Path, flush_scans: int = 5) -> float:
    rng = np.random.default_rng(0)
    scn = load_scenario("paris")
    names = [f"p{i}" for i in range(peers)]
    data = messages(names, scans, rng)
    rec = rr.RecordingStream("sensornet-bench", recording_id="bench-view-map")
    rec.set_sinks(rr.FileSink(str(out)))
    b = Batcher(rr, rec)
    t0 = time.process_time()
    state = (GeoViewState(b, names, 2.0, geo=geo_map(scn)) if geo
             else ViewState(b, names, 2.0))
    for k, batch in enumerate(data, start=1):
        for key, payload in batch:
            state.receive(key, payload)
        if k % flush_scans == 0:
            b.flush()
    b.flush()
    rec.flush()
    cpu = time.process_time() - t0
    rec.disconnect()
    return cpu * 1e3 / scans


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--peers", type=int, default=4)
    p.add_argument("--scans", type=int, default=300)
    args = p.parse_args(argv)
    os.environ.setdefault("RERUN_ANALYTICS", "0")
    with tempfile.TemporaryDirectory(prefix="sensornet-view-map-") as tmp:
        run(True, 2, 10, Path(tmp) / "warm.rrd")  # imports and first calls, not measured
        plain = run(False, args.peers, args.scans, Path(tmp) / "plain.rrd")
        both = run(True, args.peers, args.scans, Path(tmp) / "geo.rrd")
    print(f"| paris, {args.peers} peers, {args.scans} scans | CPU ms per scan |\n|---|---:|\n"
          f"| 2-D map only (ViewState) | {plain:.2f} |\n"
          f"| 2-D and geographic maps (GeoViewState) | {both:.2f} |\n\n"
          f"ratio {both / plain:.2f}; load average {os.getloadavg()[0]:.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
