"""Can one view process show 100 peers at 10 scans/s? (issue 38)

Feeds the live view's drawing (:class:`sensornet.view.ViewState`, decoding included) the
messages of ``--peers`` peers for ``--scans`` scans, synthetic but of the sizes a GM-PHD
network sends: per peer and scan its tracks (5 targets), its round-0 estimate (20 components),
its telemetry (about 25 values and the fused mixture's 10 heaviest components), its sensor's
scan (20 returns), and the truth once a scan; a round-1 estimate per peer as well (skipped
from its head, as the view does). Writes a real ``.rrd`` (Rerun FileSink) and prints the CPU
per scan against the 100 ms a scan lasts at 10 scans/s, for the batched logging (one
``send_columns`` per entity per flush) and for one ``rr.log`` per row (what the peers did
before), and their ratio.

    python benchmarks/bench_view.py                 # 100 peers, 50 scans
    python benchmarks/bench_view.py --peers 50 --scans 100
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
from sensornet.protocol.codec import encode
from sensornet.protocol.messages import Estimate, Scan, Telemetry, Tracks, Truth
from sensornet.tracking.mixture import GaussianMixture

from sensornet.view import Batcher, ViewState


def _mix(rng: np.random.Generator, n: int) -> GaussianMixture:
    means = rng.uniform(-1000, 1000, size=(n, 4))
    covs = np.tile(np.diag([100.0, 10.0, 100.0, 10.0]), (n, 1, 1))
    return GaussianMixture.trusted(rng.uniform(0.1, 1.0, n), means, covs)


def messages(peers: int, scans: int, rng: np.random.Generator) -> list[list[tuple[str, bytes]]]:
    """Per scan: ``(key, payload)`` of everything the view hears."""
    names = [f"p{i:03d}" for i in range(peers)]
    out = []
    for k in range(1, scans + 1):
        now = time.time()
        batch = [("sensornet/b/truth", encode(Truth(k, np.arange(5), rng.normal(size=(5, 4)),
                                                    send_time=now)))]
        for n in names:
            values = {f"out_of_sequence/{w}": 0.0 for w in ("late", "redundant", "too_old")}
            values.update({"latency_ms": 20.0, "age": 0.0, "components/fused": 10.0,
                           "components/before_level2": 30.0, "components/after_level2": 20.0,
                           "cardinality/local": 5.0, "compute_ms/filter": 1.0,
                           "compute_ms/fusion": 0.5, "ospa/local": 10.0, "ospa/fused": 5.0,
                           **{f"cost/{c}": 100.0 for c in ("tuples", "bytes", "tuples_pub")},
                           **{f"trust/q{j}/{w}": 1.0 for j in range(2)
                              for w in ("statistic", "weight")}})
            batch += [
                (f"sensornet/b/scan/{n}", encode(Scan(n, k, rng.normal(size=(20, 2))))),
                (f"sensornet/b/estimate/{n}", encode(Estimate(n, k, _mix(rng, 20)))),
                (f"sensornet/b/estimate/{n}", encode(Estimate(n, k, _mix(rng, 20), round=1))),
                (f"sensornet/b/tracks/{n}", encode(Tracks(n, k, rng.normal(size=(5, 4)),
                                                          send_time=now))),
                (f"sensornet/b/telemetry/{n}", encode(Telemetry(n, k, values,
                                                                mixture=_mix(rng, 10)))),
            ]
        out.append(batch)
    return out


class _PerRow(Batcher):
    """The same rows, one ``rr.log`` each (the peers' way before issue 38)."""

    def _send(self, path, kind, ks, ts, data) -> None:
        rec = self.rec
        for k, t, d in zip(ks, ts, data, strict=True):
            rec.set_time("scan", sequence=k)
            rec.set_time("sim", duration=t)
            if kind == "scalar":
                rec.log(path, rr.Scalars(d))
            elif kind == "points":
                rec.log(path, rr.Points2D(d[0], colors=d[1], radii=d[2], labels=d[3],
                                          show_labels=d[3] is not None or None))
            elif kind == "strips":
                rec.log(path, rr.LineStrips2D(d[0], colors=d[1], radii=d[2]))
            elif kind == "text":
                rec.log(path, rr.TextLog(d[0], level=d[1]))
            else:
                rec.log(path, rr.Transform3D(translation=d))
            self.calls += 1
        self.rows_sent += len(ks)


def run(peers: int, scans: int, per_row: bool, out: Path,
        flush_scans: int = 10) -> tuple[float, int]:
    rng = np.random.default_rng(0)
    data = messages(peers, scans, rng)
    rec = rr.RecordingStream("sensornet-bench", recording_id="bench-view")
    rec.set_sinks(rr.FileSink(str(out)))
    b = (_PerRow if per_row else Batcher)(rr, rec)
    state = ViewState(b, [f"p{i:03d}" for i in range(peers)], 0.1)
    t0 = time.process_time()
    for k, batch in enumerate(data, start=1):
        for key, payload in batch:
            state.receive(key, payload)
        if k % flush_scans == 0:  # 10: one flush a second at 10 scans/s
            b.flush()
    b.flush()
    rec.flush()
    cpu = time.process_time() - t0
    rec.disconnect()
    return cpu * 1e3 / scans, b.rows_sent


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--peers", type=int, default=100)
    p.add_argument("--scans", type=int, default=80)
    args = p.parse_args(argv)
    os.environ.setdefault("RERUN_ANALYTICS", "0")
    with tempfile.TemporaryDirectory(prefix="sensornet-view-") as tmp:
        run(10, 10, False, Path(tmp) / "warm.rrd")  # imports and first calls, not measured
        naive, rows = run(args.peers, args.scans, True, Path(tmp) / "per-row.rrd")
        lines = [f"| {args.peers} peers, {args.scans} scans | CPU ms per scan | share of a "
                 f"core at 10 scans/s |", "|---|---:|---:|",
                 f"| one rr.log per row (the peers' way before) | {naive:.1f} | "
                 f"{naive / 100:.0%} |"]
        for every in (10, 20, 40, 80):  # the view doubles its period while a flush is long
            batched, _ = run(args.peers, args.scans, False, Path(tmp) / f"b{every}.rrd", every)
            lines.append(f"| batched, one send_columns per entity every {every / 10:g} s | "
                         f"{batched:.1f} | {batched / 100:.0%} |")
    print("\n".join(lines) + f"\n\n{rows} rows; load average {os.getloadavg()[0]:.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
