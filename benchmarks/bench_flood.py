"""What a member's flood costs the honest peers (issue 25): real time, accuracy, memory.

Runs the seed-000 network (world + 3 peers, births at the truth, Rerun off) once clean and once
per flood, each flood put from a raw Zenoh session on ``estimate/s2`` (s1 and s3 take s2's
estimates) once s1 has published the tracks of scan 10, every message stamped with the scan the
peers are on and a fresh round number (the issue's attack: each used to open a new slot, skip
the bucket and be decoded). ``--pattern mixed``: every other message instead takes round 0 on
each scan of the peers' window in turn (valid slots, up to 4 decodes each: what only the bucket
bounds; each one let through is also *fused*, and a 2,000-component estimate costs a peer's
fusion far more than its decoding):

- ``plain``: 240 kB estimates (2,000 components) in plain mode, anyone may put them;
- ``secure``: small estimates (one component, ~220 B with the signature) sealed with s2's own
  signing key over s2's own certificate: a member flooding within its own keys.

Prints, per flooded peer: p99 scan -> fused tracks (target < 100 ms), deadline fusions per scan
(target <= 5 %), fused OSPA minus clean (target < 5 m), messages from s2's key let through to
decoding against the bucket's allowance over the run (target <=), max RSS / clean (target
<= 1.2), and what was refused before decoding, by reason.

    python benchmarks/bench_flood.py [--scans 60] [--speed 4] [--plain 10000] [--secure 57500]
                                     [--pattern rounds|mixed]

Defaults are the issue's numbers; ``--plain 2000 --secure 10000`` is a quicker look.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import threading
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import msgpack  # noqa: E402
import numpy as np  # noqa: E402
import zenoh  # noqa: E402
from sensornet.protocol.codec import decode, encode  # noqa: E402
from sensornet.protocol.envelope import inner  # noqa: E402
from sensornet.protocol.keys import Keys  # noqa: E402
from sensornet.protocol.messages import Estimate  # noqa: E402
from sensornet.tracking.mixture import GaussianMixture  # noqa: E402

K0 = 10
NETWORK = "benchflood"
VICTIMS = ("s1", "s3")


def _template(components: int) -> list:
    """The fields of an estimate of ``components`` 4-D components (re-stamped per message)."""
    n = components
    mix = GaussianMixture(np.ones(n), np.zeros((n, 4)), np.tile(np.eye(4) * 100.0, (n, 1, 1)))
    return msgpack.unpackb(encode(Estimate("s2", 0, mix)), raw=False)


def _flood(session, keys: Keys, count: int, components: int, interval: float, signer,
           reached: float, seen: dict, mixed: bool) -> dict:
    """Put ``count`` estimates on ``estimate/s2``, stamped with the scan s1 is on (its tracks,
    or the clock since it reached ``K0``) and fresh round numbers; as fast as Zenoh takes them."""
    fields = _template(components)
    key = keys.estimate("s2")
    pub = session.declare_publisher(key, congestion_control=zenoh.CongestionControl.BLOCK)
    t0 = time.monotonic()
    try:
        for i in range(count):
            k = max(seen["k"], K0 + int((time.monotonic() - reached) / interval))
            if not mixed or i % 2 == 0:  # the scan the peers are on, a fresh round number
                fields[3], fields[4] = k + 1, 1000 + i
            else:  # a round the peers run, on every scan of their window: the bucket's work
                fields[3], fields[4] = k - 2 + (i // 2) % 8, 0
            payload = msgpack.packb(fields, use_bin_type=True)
            pub.put(signer.seal(key, payload) if signer is not None else payload)
    finally:
        pub.undeclare()
    return {"sent": count, "seconds": time.monotonic() - t0,
            "bytes": len(msgpack.packb(fields, use_bin_type=True))}


def one_run(out: Path, scans: int, speed: float, mode: str, count: int,
            mixed: bool = False) -> tuple[dict, dict]:
    from sensornet.peers.security import Security, make_keys
    from sensornet.peers.session import open_session
    from sensornet.sim.run.launcher import read_summaries, start_run, wait_run
    from sensornet.sim.scenario import load_scenario, parse_overrides

    sets = ["birth.model=truth", f"scenario.num_scans={scans}", f"network.speed={speed}"]
    scn = load_scenario("seed000", overrides=parse_overrides(sets))
    keys_dir = None
    if mode == "secure":
        keys_dir = out / "keys"
        make_keys(NETWORK, ["world", *scn.sensor_names], keys_dir)
    handle = start_run(scn, "seed000", out, network=NETWORK, overrides=sets, rerun=False,
                       secure=keys_dir)
    flood: dict = {}
    try:
        if mode != "clean":
            sec = (Security.load(keys_dir, "s2", NETWORK, tuple(scn.sensor_names))
                   if keys_dir else None)
            session = open_session(connect=list(handle.endpoints.values()), security=sec)
            keys, seen, at_k0 = Keys(handle.network), {"k": 0}, threading.Event()

            def on_clock(sample) -> None:  # s1's tracks; in secure mode s2's own scans
                k = decode(inner(sample.payload.to_bytes())).k
                seen["k"] = max(seen["k"], k)
                if k >= K0:
                    at_k0.set()

            # the access control lets s2 read only its own scans, not s1's tracks
            clock = keys.scan("s2") if sec is not None else keys.tracks("s1")
            sub = session.declare_subscriber(clock, on_clock)
            try:
                if at_k0.wait(120):
                    interval = scn.scan_period / scn.network.speed
                    flood = _flood(session, keys, count, 2000 if mode == "plain" else 1,
                                   interval, sec.signer() if sec else None,
                                   time.monotonic(), seen, mixed)
            finally:
                sub.undeclare()
                session.close()
        codes = wait_run(handle, timeout=scans / speed + 300)
    finally:
        handle.stop_all()
    summaries = read_summaries(out, scn.sensor_names)
    return {"codes": codes, "flood": flood, "interval": scn.scan_period / scn.network.speed,
            "rounds": scn.network.rounds, "scans": scans}, summaries


def allowance(run: dict, s: dict) -> float:
    """What s2's estimate bucket lets through over the run (peers.admission: 4x the honest
    rate, a burst of 8 scans' worth), from full at the start."""
    per = run["rounds"]
    seconds = run["scans"] * run["interval"] + 5.0  # the run, and its start and end
    return max(4.0, 8.0 * per) + 4.0 * per / run["interval"] * seconds


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scans", type=int, default=60)
    ap.add_argument("--speed", type=float, default=4.0)
    ap.add_argument("--plain", type=int, default=10_000, help="240 kB messages (0: skip)")
    ap.add_argument("--secure", type=int, default=57_500, help="small signed messages (0: skip)")
    ap.add_argument("--pattern", choices=("rounds", "mixed"), default="rounds")
    a = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        clean_run, clean = one_run(Path(tmp) / "clean", a.scans, a.speed, "clean", 0)
        print(f"clean: exit codes {clean_run['codes']}")
        for name in VICTIMS:
            s = clean[name]
            print(f"  {name}: p99 {s['latency_ms_p99']:.1f} ms, fused OSPA "
                  f"{s['mean_ospa_fused']:.1f} m, RSS {s['max_rss_mb']:.0f} MB")
        print("| flood | peer | p99 ms | deadline fusions | fused OSPA - clean (m) | "
              "decoded from s2 / allowance | RSS / clean | refused before decoding | targets |")
        print("|---|---|---|---|---|---|---|---|---|")
        ok = True
        for mode, count in (("plain", a.plain), ("secure", a.secure)):
            if count <= 0:
                continue
            run, sums = one_run(Path(tmp) / mode, a.scans, a.speed, mode, count,
                                a.pattern == "mixed")
            fl = run["flood"]
            label = (f"{mode} {fl.get('sent', 0)} x {fl.get('bytes', 0)} B in "
                     f"{fl.get('seconds', 0):.1f} s")
            for name in VICTIMS:
                s, c = sums[name], clean[name]
                dl = s["stats"]["deadline_fusions"] / max(1, s["stats"]["scans"])
                dosp = s["mean_ospa_fused"] - c["mean_ospa_fused"]
                dec, allow = s["admitted_by_sender"].get("estimate/s2", 0), allowance(run, s)
                rss = s["max_rss_mb"] / c["max_rss_mb"]
                passed = (s["latency_ms_p99"] < 100 and dl <= 0.05 and dosp < 5
                          and dec <= allow and rss <= 1.2)
                ok &= passed
                before = {r: n for r, n in s["rejected"].items() if r in (
                    "round", "rate", "duplicate", "stale", "future", "inbox", "inbox-total",
                    "incompatible", "replayed", "unauthenticated")}
                print(f"| {label} | {name} | {s['latency_ms_p99']:.1f} | {dl:.1%} | "
                      f"{dosp:+.1f} | {dec} / {allow:.0f} | {rss:.2f} | {before} | "
                      f"{'PASS' if passed else 'FAIL'} |")
        print("all targets met" if ok else "some target missed (see FAIL rows)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
