"""Hostile inputs a receiver must bound by itself (issue: one peer core), shared by the twin
tests (tests/test_attacks_twin.py) and the real-process tests (tests/test_attacks.py), which
assert the same counts: the twin and the processes run the same core on the same bytes.

Each attack is a list of ``(key, payload)`` put on the network once the run reaches scan
``k0``, the peers it reaches, and what each of them must count. Forged messages that are
well-formed and name another sender truthfully are the authentication issue's, not these.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import msgpack
import numpy as np
from sensornet.protocol.codec import VERSION, encode
from sensornet.protocol.keys import Keys
from sensornet.protocol.messages import Control, Estimate, Scan, Truth
from sensornet.tracking.mixture import GaussianMixture

SETS = ["birth.model=truth", "scenario.num_scans=40", "network.deadline=0.9"]
"""Scenario overrides of every attacked run (seed 000, 3 peers, 10 scans/s)."""
K0 = 10
"""The attack starts once the run has reached this scan."""


@dataclass(frozen=True)
class Attack:
    name: str
    make: Callable[[Keys, int, np.ndarray], list[tuple[str, bytes]]]
    """``(keys, k0, truth states of k0 + 1) -> [(key, payload), ...]``."""
    victims: tuple[str, ...]
    counts: dict[str, int] = field(default_factory=dict)
    """Rejections by reason every victim must report (exactly)."""
    transport_drops: int = 0
    """Messages the transport drops for size before any peer sees them."""


def _mixture(n: int, d: int, rng: np.random.Generator) -> GaussianMixture:
    return GaussianMixture(rng.uniform(0.1, 1.0, n), rng.normal(0, 500, (n, d)),
                           np.tile(np.eye(d) * 100.0, (n, 1, 1)))


def _future_scans(keys, k0, x):
    z = np.zeros((3, 2))
    return [(keys.scan("s1"), encode(Scan("s1", 10**9 + i, z, seq=1))) for i in range(3)]


def _forged_end(keys, k0, x):
    return [(keys.ctl(), encode(Control("end", "forged", {})))]


def _future_estimates(keys, k0, x):
    rng = np.random.default_rng(5)
    big = _mixture(2000, 4, rng)
    msgs = [(keys.estimate("s2"), encode(Estimate("s2", 10**6 + i, big))) for i in range(300)]
    msgs.append((keys.estimate("s2"), encode(Estimate("s2", 10**9, _mixture(3, 4, rng)))))
    return msgs


def _oversized(keys, k0, x):
    d = 4
    huge = msgpack.packb([VERSION, "E", "s2", k0 + 1, 0, 1, 1.0, 1, 0, d,
                          b"\0" * (8 * 15 * 10**6)], use_bin_type=True)  # 10^6 components
    over_codec = msgpack.packb([VERSION, "E", "s2", k0 + 1, 0, 1, 1.0, 1, 0, d,
                                b"\0" * ((1 << 20) + 120)], use_bin_type=True)
    return [(keys.estimate("s2"), over_codec),  # first: still inside the window when it lands
            (keys.estimate("s2"), b"\x93" + b"\0" * 50_000_000),  # 50 MB of junk
            (keys.estimate("s2"), huge)]


def _wrong_dimension(keys, k0, x):
    rng = np.random.default_rng(6)
    return [(keys.estimate("s2"), encode(Estimate("s2", k0 + 1, _mixture(4, 2, rng))))
            for _ in range(3)]


def _forged_truth(keys, k0, x):
    fake = np.asarray(x) + 100.0
    ids = np.arange(len(fake))
    return [(keys.truth(), encode(Truth(k0 + 1, ids, fake))) for _ in range(3)]


ATTACKS = [
    Attack("future-scan", _future_scans, ("s1",), {"future": 3}),
    Attack("forged-end", _forged_end, ("s1", "s2", "s3")),
    Attack("future-estimates", _future_estimates, ("s1", "s3"), {"future": 301}),
    Attack("oversized", _oversized, ("s1", "s3"), {"too-large": 1}, transport_drops=2),
    Attack("wrong-dimension", _wrong_dimension, ("s1", "s3"), {"incompatible": 3}),
    # peers regenerate the truth from their scenario and do not subscribe to it: nothing of
    # it reaches them (received_by_kind has no truth) and nothing is counted
    Attack("forged-truth", _forged_truth, ("s1", "s2", "s3"), {"truth-mismatch": 0}),
]
BY_NAME = {a.name: a for a in ATTACKS}


def only_attack_counts(rejected: dict[str, int], attack: Attack) -> dict[str, int]:
    """The victim's rejections under the attack's reasons (others come from the clean run)."""
    return {r: rejected.get(r, 0) for r in attack.counts}
