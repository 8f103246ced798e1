"""What a round that does not wait for a late member would cost its fused OSPA (issue 36).

The twin of the secure-mesh case of ``benchmarks/bench_member_costs.py`` (seed 000's targets
seen by 8 linear sensors, full mesh, 60 scans at 10 scans/s, births at the truth; no
processes, so no load): the estimates of 0, 2 or 6 members (s2, s5 / s2-s7, the padding members
of that benchmark) reach their neighbours ``delay`` after they are sent. At 0.3 scan intervals
the round waits for them (the deadline is 0.5): fused fresh. At 0.7 the round runs at the
deadline without them and fuses each one a scan late, predicted through NALE (what a receiver
that stopped waiting for them would fuse, or for a padding member once its grace is over); at
1.7, two scans late. Printed per case: the honest peers' mean fused OSPA (m; s1 and s8, the
worse of the two) and its ratio to the run with every estimate on time, and the same one scan
late with the births left out of the NALE prediction (``tracking.gmphd.predict`` without the
birth intensity; a measurement only, not what the peers do).

    python benchmarks/bench_late_inputs.py [--scans 60] [--run 0]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from sensornet.sim.run.peers import make_peer  # noqa: E402
from sensornet.sim.run.twin import run_twin  # noqa: E402
from sensornet.sim.scenario import load_scenario  # noqa: E402
from sensornet.tracking.gmphd import predict  # noqa: E402

from benchmarks.bench_member_costs import MESH_LIARS, mesh_source  # noqa: E402

HONEST = ("s1", "s8")
DELAYS = (0.3, 0.7, 1.7)
"""Delays of the late members' estimates, in scan intervals."""


def without_births(peers: dict) -> None:
    """Each peer's NALE prediction of a neighbour's estimate with no birth intensity added."""
    for core in peers.values():
        f = core.consensus.estimator.filter
        core.consensus.estimator.predict = (
            lambda mix, steps, f=f: predict(mix, f.motion, f.survival_probability, None, steps))


def worst_ospa(scn, run: int, late: tuple[str, ...], delay: float,
               births: bool = True) -> float:
    """The honest peers' worst mean fused OSPA with ``late``'s estimates ``delay`` (s) late."""
    peers = {n: make_peer(scn, n, run) for n in scn.sensor_names}
    if not births:
        without_births(peers)
    res = run_twin(scn, run, peers=peers,
                   delay=lambda s, r, m: delay if s in late else 0.0)
    return max(res.mean_ospa(n) for n in HONEST)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scans", type=int, default=60)
    ap.add_argument("--run", type=int, default=0, help="Monte Carlo run (its seed)")
    a = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as td:
        scn = load_scenario(str(mesh_source(Path(td))), overrides={
            "birth.model": "truth", "scenario.num_scans": a.scans, "network.speed": 10})
    interval = scn.scan_period / scn.network.speed
    clean = worst_ospa(scn, a.run, (), 0.0)
    print(f"secure mesh of 8 (twin), {a.scans} scans, run {a.run}; on time: fused OSPA "
          f"{clean:.2f} m; deadline {scn.network.deadline} of an interval")
    print("| late members | " + " | ".join(f"{d:g} intervals late" for d in DELAYS)
          + " | 0.7 late, no births in NALE |")
    print("|---|" + "---:|" * (len(DELAYS) + 1))
    for label, late in (("none", ()), *((k, v) for k, v in MESH_LIARS.items())):
        cells = [worst_ospa(scn, a.run, late, d * interval) for d in DELAYS]
        cells.append(worst_ospa(scn, a.run, late, 0.7 * interval, births=False))
        print(f"| {label} ({', '.join(late) or '-'}) | "
              + " | ".join(f"{x:.2f} ({x / clean:.2f})" for x in cells) + " |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
