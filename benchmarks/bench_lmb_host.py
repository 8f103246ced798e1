"""A host of labelled peers finishing its rounds together against one by one, in one run
(issue 33, "50 labelled peers in real time at 10 scans/s on 2 cores in peer hosts").

Runs the twin of bench_fifty's network (``--peers`` peers of ``--kind``, circulant graph of
degree 4, 2 rounds, every peer in one host batch as ``bench_fifty --twin``) with the host's
per-round work after the fusion done one peer at a time (:class:`peers.batching.FusionBatch`
with every ``*_together`` switch off) and together (all on), ``--repeats`` interleaved pairs:

- process CPU ms per peer-scan of each way and their ratio (medians);
- thread CPU ms per peer-scan of the fused densities' labelling (each peer's
  ``label_fused``, or the host's ``label_fused_many``) and of the tracks' input masses (each
  peer's ``input_mass`` and ``input_support``, or the host's ``masses_many``), their ratios;
- whether every message every peer published (estimates with labels, tracks with ids) is
  the same bytes both ways (a SHA-256 over them; it must be).

    python benchmarks/bench_lmb_host.py                          # 50 LMB peers, 3 pairs
    python benchmarks/bench_lmb_host.py --set fusion.trust=false # without the defence
    python benchmarks/bench_lmb_host.py --kind gmphd --scans 60
"""

from __future__ import annotations

import argparse
import hashlib
import statistics
import sys
import tempfile
import time
from pathlib import Path

if not __package__:  # `python benchmarks/bench_lmb_host.py`: the repository root importable
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import sensornet.peers.batching as batching
import sensornet.peers.consensus as consensus
from sensornet.peers.consensus import Consensus
from sensornet.peers.core import Publish
from sensornet.peers.host import SharedDecode
from sensornet.sim.run import twin
from sensornet.sim.run.peers import make_peer
from sensornet.sim.scenario import load_scenario, parse_overrides

from benchmarks.bench_network import load_average, scenario_text

SWITCHES = ("label_together", "tracks_together")
"""The FusionBatch switches of the host's work done together (all off: one by one)."""


class Timer:
    """Thread CPU seconds spent in wrapped functions (outermost calls only)."""

    def __init__(self) -> None:
        self.s = 0.0
        self.depth = 0

    def wrap(self, fn):
        def timed(*a, **kw):
            self.depth += 1
            t0 = time.thread_time()
            try:
                return fn(*a, **kw)
            finally:
                self.depth -= 1
                if self.depth == 0:
                    self.s += time.thread_time() - t0
        return timed


def one_run(scn, together: bool) -> tuple[float, float, float, str]:
    """The twin once: process CPU ms per peer-scan, labelling and input-mass thread CPU ms
    per peer-scan, the SHA-256 of every published message in order."""
    peers = {q: make_peer(scn, q, 0, network="twin") for q in scn.sensor_names}
    shared = SharedDecode()
    for core in peers.values():
        core.decode = shared
    digest = hashlib.sha256()
    carry = twin._Clock.carry_out

    def record(self, t, sender, outputs):
        for o in outputs:
            if isinstance(o, Publish):
                digest.update(sender.encode())
                digest.update(o.payload)
        return carry(self, t, sender, outputs)

    label, mass = Timer(), Timer()
    saved = (twin.FusionBatch, Consensus._label, batching._label_together,
             consensus.input_mass, consensus.input_support, batching._masses_together)
    twin._Clock.carry_out = record
    twin.FusionBatch = lambda: batching.FusionBatch(**{s: together for s in SWITCHES})
    Consensus._label = label.wrap(saved[1])
    batching._label_together = label.wrap(saved[2])
    consensus.input_mass = mass.wrap(saved[3])
    consensus.input_support = mass.wrap(saved[4])
    batching._masses_together = mass.wrap(saved[5])
    try:
        t0 = time.process_time()
        twin.run_twin(scn, 0, peers=peers, batch=True)
        cpu = time.process_time() - t0
    finally:
        twin._Clock.carry_out = carry
        (twin.FusionBatch, Consensus._label, batching._label_together, consensus.input_mass,
         consensus.input_support, batching._masses_together) = saved
    per = len(peers) * scn.num_scans
    return cpu * 1e3 / per, label.s * 1e3 / per, mass.s * 1e3 / per, digest.hexdigest()


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--kind", default="lmb", help="network.filter (default lmb)")
    p.add_argument("--peers", type=int, default=50)
    p.add_argument("--scans", type=int, default=100)
    p.add_argument("--repeats", type=int, default=3, help="interleaved pairs (default 3)")
    p.add_argument("--set", dest="sets", action="append", default=[], metavar="KEY=VALUE",
                   help="a scenario override (repeatable), e.g. fusion.trust=false")
    args = p.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "twin.toml"
        path.write_text(scenario_text(args.peers, 4, args.scans, rounds=2, speed=10.0))
        scn = load_scenario(str(path), overrides=parse_overrides(
            [f"network.filter={args.kind}", *args.sets]))
    print(f"## {args.peers} {args.kind} peers in one host, {args.scans} scans"
          f"{''.join(' --set ' + s for s in args.sets)}; switches {', '.join(SWITCHES)}; "
          f"load average {load_average()}\n")
    print("| way | pair | CPU ms/peer-scan | labelling ms/peer-scan | input masses ms/peer-scan "
          "| load |")
    print("|---|---:|---:|---:|---:|---:|")
    got: dict[bool, list[tuple[float, float, float, str]]] = {False: [], True: []}
    for rep in range(args.repeats):
        for together in ((False, True) if rep % 2 == 0 else (True, False)):
            r = one_run(scn, together)
            got[together].append(r)
            print(f"| {'together' if together else 'one by one'} | {rep + 1} | {r[0]:.2f} | "
                  f"{r[1]:.3f} | {r[2]:.3f} | {load_average()} |", flush=True)
    med = {w: [statistics.median(r[i] for r in rs) for i in range(3)] for w, rs in got.items()}
    same = len({r[3] for rs in got.values() for r in rs}) == 1
    print("\ntogether / one by one (medians): " + ", ".join(
        f"{name} {med[True][i] / med[False][i]:.3f} ({med[False][i]:.3f} -> {med[True][i]:.3f})"
        for i, name in enumerate(("CPU", "labelling", "input masses")))
        + f"; published bytes {'identical' if same else 'DIFFER'}")
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
