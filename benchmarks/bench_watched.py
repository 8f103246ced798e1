"""What a watched peer spends on its live view (issue 38), without transport: the observer's
gathering (``Observer.record``/``published``) and its reports' packing and encoding
(``Observer.flush``), CPU per peer-scan on the twin of a scenario, and the bytes it sends.

The twin (``sim/run/twin.py``) runs every peer's logic on a virtual clock; here each peer also
has an :class:`peers.observer.Observer` attached (as a watched peer's runtime drives it: every
output through it, a flush after each step), timed with the thread's CPU clock around the
calls. ``--hosts H``: the peers' reports gathered per host of ``n / H`` peers and sent as one
message a flush (:class:`peers.observer.HostReports`), as ``sensornet run`` packs them.

    python benchmarks/bench_watched.py                    # seed004, 60 scans, 2 hosts
    python benchmarks/bench_watched.py --hosts 0          # each peer puts its own reports
    python benchmarks/bench_watched.py --scenario seed001 --scans 40 --repeats 3
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

if not __package__:  # run as a script: this checkout's code, not the installed one
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from sensornet.peers.core import Publish, Record
from sensornet.peers.observer import KINDS, HostReports, Observer
from sensornet.protocol.keys import Keys
from sensornet.sim.run import twin
from sensornet.sim.run.peers import make_peer
from sensornet.sim.scenario import load_scenario, parse_overrides


def watched_twin(scn, run: int, hosts: int, put) -> dict:
    """One twin run of ``scn`` with every peer watched, as a watched runtime drives its
    observer (every output through it, a flush after each step; ``hosts``: reports gathered
    per host of ``n / hosts`` peers, sent once per virtual instant, 0: each peer its own);
    ``put(t, key, payload)`` gets each put at virtual time ``t`` on its report key (network
    ``twin``). Returns the CPU seconds of gathering and of flushing."""
    names = scn.sensor_names
    keys = Keys("twin")
    peers = {n: make_peer(scn, n, run) for n in names}
    cpu = {"gather": 0.0, "flush": 0.0}
    now = [0.0]
    observers, host_of, last = {}, {}, [None]
    groups = [names[i::hosts] for i in range(hosts)] if hosts else [[n] for n in names]

    def put_on(key: str):
        return lambda payload: put(now[0], key, payload)

    for h, group in enumerate(groups):
        reports = HostReports(put_on(keys.telemetries(f"h{h + 1}"))) if hosts else None
        for n in group:
            obs = Observer(peers[n], scn.scan_period)
            observers[n] = (obs.attach(put_on(keys.telemetry(n))) if reports is None
                            else reports.add(obs))
            host_of[n] = reports
    handle = twin._Clock.handle

    def watched(self, t, target, core, out):
        handle(self, t, target, core, out)  # out now holds the tick's outputs too
        obs = observers[target]
        # the calls a watched runtime adds to its loop over the outputs (the loop is there
        # anyway, to publish): listed first, so that only the calls are timed
        # (the runtime hands over only tracks and the record kinds the observer reads)
        calls = [(obs.published, o, 1.0) if isinstance(o, Publish)
                 else (obs.record, o, 1.0 if o.kind == "local" else None)
                 for o in out if (isinstance(o, Publish) and o.channel == "tracks")
                 or (isinstance(o, Record) and o.kind in KINDS)]
        t0 = time.thread_time()
        if last[0] != t:  # a new instant: the hosts' passes of the last one are over
            for reports in {id(r): r for r in host_of.values() if r is not None}.values():
                reports.send()
            last[0] = now[0] = t
        for call, o, x in calls:
            call(o, x)
        t1 = time.thread_time()
        if obs.wants_flush:
            obs.flush(idle=True, host=obs.reports is not None)
        cpu["gather"] += t1 - t0
        cpu["flush"] += time.thread_time() - t1

    twin._Clock.handle = watched
    try:
        twin.run_twin(scn, run, peers=peers)
    finally:
        twin._Clock.handle = handle
    t0 = time.thread_time()
    for obs in observers.values():
        obs.flush(idle=True, force=True)
    for reports in {id(r): r for r in host_of.values() if r is not None}.values():
        reports.send()
    cpu["flush"] += time.thread_time() - t0
    return cpu


def measure(source: str, scans: int, hosts: int, run: int = 0) -> dict:
    """One twin run with every peer watched: CPU (ms per peer-scan) of gathering and of
    flushing, reports and puts per peer-scan, bytes per peer-scan."""
    scn = load_scenario(source, overrides=parse_overrides([f"scenario.num_scans={scans}"]))
    sent: list[bytes] = []
    cpu = watched_twin(scn, run, hosts, lambda t, key, payload: sent.append(payload))
    peer_scans = len(scn.sensor_names) * scans
    return {"gather": 1e3 * cpu["gather"] / peer_scans, "flush": 1e3 * cpu["flush"] / peer_scans,
            "puts": len(sent) / peer_scans, "bytes": sum(map(len, sent)) / peer_scans}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--scenario", default="seed004")
    p.add_argument("--scans", type=int, default=60)
    p.add_argument("--hosts", type=int, default=2,
                   help="peers' reports sent per host (0: each peer its own)")
    p.add_argument("--repeats", type=int, default=3)
    args = p.parse_args(argv)
    rows = [measure(args.scenario, args.scans, args.hosts) for _ in range(args.repeats)]
    med = {k: statistics.median(r[k] for r in rows) for k in rows[0]}
    print(f"{args.scenario}, {args.scans} scans, hosts {args.hosts or 'none'}: per peer-scan "
          f"(median of {args.repeats}) gather {med['gather']:.3f} ms, flush {med['flush']:.3f} "
          f"ms, {med['puts']:.2f} puts, {med['bytes']:.0f} bytes; each run "
          + ", ".join(f"{r['gather'] + r['flush']:.3f}" for r in rows) + " ms")
    return 0


if __name__ == "__main__":
    sys.exit(main())
