"""What signed messages (secure mode, ``protocol.envelope``) cost per message and per scan.

Times, per message, sealing (Ed25519 sign + trailer) and opening (verify + replay check) beside
the codec's own encode and decode of the same message, for a scan and for estimates of 1, 10
and 100 four-dimensional Gaussian components; then the cost per scan of one seed-000 peer with
two neighbours and one consensus round: it opens a scan, a truth and two estimates, and seals
one estimate and one tracks message. Medians of ``--n`` calls (CPU time of this thread).

    python benchmarks/bench_signing.py [--n 2000]

Opening runs on Zenoh's callback threads, not on the peer's main loop, and ``cryptography``
releases the GIL while it verifies: most of it overlaps the peer's own work. Sealing runs on the
main loop, before each publication.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np
from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey

if not __package__:  # run as a script: this checkout's code, not the installed one
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from sensornet.protocol.codec import decode, encode
from sensornet.protocol.envelope import Signer, Verifier
from sensornet.protocol.keys import Keys
from sensornet.protocol.messages import Estimate, Scan, Tracks, Truth
from sensornet.tracking.mixture import GaussianMixture


def _median_us(fn, n: int) -> float:
    times = []
    for _ in range(n):
        t0 = time.thread_time_ns()
        fn()
        times.append(time.thread_time_ns() - t0)
    return statistics.median(times) / 1e3


def _estimate(components: int, rng) -> Estimate:
    P = np.eye(4)[None].repeat(components, 0) * rng.uniform(1, 10, (components, 1, 1))
    mix = GaussianMixture(rng.uniform(0, 1, components), rng.normal(0, 500, (components, 4)),
                          P)
    return Estimate("s2", 7, mix, round=0, seq=7, send_time=time.time())


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=2000, help="calls per median")
    args = ap.parse_args(argv)
    rng = np.random.default_rng(0)
    keys = Keys("bench")
    world_key, peer_key = Ed25519PrivateKey.generate(), Ed25519PrivateKey.generate()
    world, peer = Signer(world_key), Signer(peer_key)
    roster = {"world": world_key.public_key(), "s2": peer_key.public_key()}
    messages = {
        "scan (8 measurements)": (keys.scan("s1"), world,
                                  Scan("s1", 7, rng.normal(0, 500, (8, 2)), seq=7)),
        "truth (4 targets)": (keys.truth(), world,
                              Truth(7, np.arange(4), rng.normal(0, 500, (4, 4)))),
        **{f"estimate ({c} component{'s' if c > 1 else ''})": (keys.estimate("s2"), peer,
                                                               _estimate(c, rng))
           for c in (1, 10, 100)},
        "tracks (4 targets)": (keys.tracks("s2"), peer,
                               Tracks("s2", 7, rng.normal(0, 500, (4, 4)))),
    }
    print(f"Per message, median of {args.n} calls (µs of CPU):\n")
    print("| message | bytes | encode | decode | seal (sign) | open (verify) | "
          "open / decode |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    cost = {}
    for label, (key, signer, msg) in messages.items():
        data = encode(msg)
        sealed = signer.seal(key, data)
        enc = _median_us(lambda m=msg: encode(m), args.n)
        dec = _median_us(lambda d=data: decode(d), args.n)
        seal = _median_us(lambda k=key, s=signer, d=data: s.seal(k, d), args.n)

        def open_fresh(k=key, s=sealed):
            Verifier(roster).open(k, s)  # a fresh verifier: never "replayed"

        ver = _median_us(open_fresh, args.n)
        cost[label] = (seal, ver)
        print(f"| {label} | {len(data)} (+{len(sealed) - len(data)}) | {enc:.1f} | {dec:.1f} | "
              f"{seal:.1f} | {ver:.1f} | {ver / dec:.1f}x |")
    opened = (cost["scan (8 measurements)"][1] + cost["truth (4 targets)"][1]
              + 2 * cost["estimate (10 components)"][1])
    sealed_us = cost["estimate (10 components)"][0] + cost["tracks (4 targets)"][0]
    print("\nPer scan of a seed-000 peer (2 neighbours, 1 round): opens a scan, a truth and 2 "
          "estimates, seals an estimate and a tracks message:\n")
    print("| work | µs per scan | on |")
    print("|---|---:|---|")
    print(f"| open (verify) x 4 | {opened:.0f} | Zenoh's callback threads |")
    print(f"| seal (sign) x 2 | {sealed_us:.0f} | the peer's main loop |")
    print(f"| total | {opened + sealed_us:.0f} | |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
