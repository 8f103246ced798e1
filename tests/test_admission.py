"""Admission before decoding (peers.admission): a member's flood costs a receiver at most its
token bucket's allowance, however the messages are stamped, and the inbox stays bounded."""

from __future__ import annotations

import numpy as np
from sensornet.peers.admission import (
    INBOX_BYTES,
    INBOX_MIN,
    INBOX_SCANS,
    INBOX_TOTAL,
    SLOT_ATTEMPTS,
    Admission,
    Route,
)
from sensornet.protocol.codec import encode
from sensornet.protocol.messages import Estimate
from sensornet.tracking.mixture import GaussianMixture

MIX = GaussianMixture(np.ones(1), np.zeros((1, 4)), np.eye(4)[None])
S2 = Route("estimate", "s2")
INTERVAL = 0.1


def _adm(rounds=2, kinds=("posterior",), window=(5, 20)) -> Admission:
    return Admission("twin", INTERVAL, {"estimate": float(rounds), "scan": 1.0},
                     window=lambda ch: window, rounds=rounds, kinds=kinds)


def _allowance(adm: Admission, route: Route, seconds: float) -> float:
    """What the sender's bucket lets through in ``seconds`` from full."""
    per = adm.per_scan[route.channel]
    return max(4.0, adm.burst * per) + adm.factor * per / adm.interval * seconds


def test_rounds_and_kinds_outside_what_the_peer_runs_are_refused_before_decoding():
    adm = _adm()
    bad_round = encode(Estimate("s2", 10, MIX, round=2))
    bad_kind = encode(Estimate("s2", 10, MIX, kind="prediction"))
    assert not adm.admit(S2, 0.0, bad_round) and not adm.admit(S2, 0.0, bad_kind)
    assert adm.rejected == {"round": 1, "incompatible": 1}
    assert adm.admit(S2, 0.0, encode(Estimate("s2", 10, MIX, round=1)))
    assert adm.admitted == {"estimate/s2": 1}


def test_a_fresh_round_flood_is_decoded_at_most_the_bucket_allowance():
    """10,000 estimates at 4,000/s, each on a fresh round number of the current scans: before,
    every one opened a new slot and skipped the bucket."""
    adm = _adm()
    n, rate = 10_000, 4000.0
    msgs = [encode(Estimate("s2", 5 + i % 16, MIX, round=i)) for i in range(n)]
    let = sum(adm.admit(S2, i / rate, m) for i, m in enumerate(msgs))
    seconds = n / rate
    assert let <= _allowance(adm, S2, seconds)
    assert let <= 16 * 2 * SLOT_ATTEMPTS  # 16 scans in the window, 2 rounds
    assert let == 2 and adm.rejected["round"] == n - 2  # only rounds 0 and 1 exist
    assert sum(adm.rejected.values()) == n - let


def test_valid_slots_at_full_speed_are_held_to_the_bucket():
    """Every message on a slot the peer really has (scan in the window, a round it runs): the
    slot bound alone would let 16 x 2 x 4 = 128 through; the bucket holds it to its allowance."""
    adm = _adm()
    slots = [(k, r) for k in range(5, 21) for r in range(2)]
    n, rate = 2000, 4000.0
    let = 0
    for i in range(n):
        k, r = slots[i % len(slots)]
        let += adm.admit(S2, i / rate, encode(Estimate("s2", k, MIX, round=r)))
    assert let <= _allowance(adm, S2, n / rate)
    assert adm.rejected["rate"] > 0 and adm.rejected["duplicate"] > 0
    assert adm.admitted["estimate/s2"] == let


def test_an_honest_sender_is_never_refused():
    adm = _adm(window=(0, 10**9))
    for k in range(500):  # one scan every interval, both rounds
        for r in range(2):
            assert adm.admit(S2, k * INTERVAL, encode(Estimate("s2", k, MIX, round=r)))
    assert adm.rejected == {}


def test_the_inbox_is_bounded_per_sender_and_freed_as_the_loop_takes_messages():
    adm = _adm(window=(0, 10**9))
    adm.factor, adm.burst = 1e9, 1e9  # only the inbox bounds here
    key = "sensornet/twin/estimate/s2"
    payloads = [encode(Estimate("s2", k, MIX)) for k in range(200)]
    let = [p for p in payloads if adm.arrive(S2, 0.0, p)]
    bound = max(INBOX_MIN, INBOX_SCANS * 2)
    assert len(let) == bound and adm.rejected["inbox"] == len(payloads) - bound
    assert adm.queued()["messages"] == bound
    for p in let[:5]:
        adm.taken(key, len(p))
    assert adm.queued()["messages"] == bound - 5
    assert sum(adm.arrive(S2, 0.0, p) for p in payloads) == 5  # room for five more
    for p in let[5:]:
        adm.taken(key, len(p))
    assert adm.queued()["bytes"] == 5 * len(payloads[0])
    assert adm.inbox_peak == bound
    adm.taken("sensornet/twin/estimate/s9", 10)  # never arrived: nothing to give back
    assert adm.queued()["messages"] == 5


def test_the_inbox_is_bounded_in_total_and_in_bytes():
    adm = Admission("twin", INTERVAL, {"scan": 1.0}, factor=1e9, burst=1e9,
                    max_senders=10**6)
    n = 0
    for s in range(INBOX_TOTAL // INBOX_MIN + 2):
        route = Route("scan", f"x{s}")
        n += sum(adm.arrive(route, 0.0, b"x") for _ in range(INBOX_MIN))
    assert n == INBOX_TOTAL and adm.rejected["inbox-total"] == 2 * INBOX_MIN
    big = Admission("twin", INTERVAL, {"scan": 1.0}, factor=1e9, burst=1e9)
    chunk = b"\0" * (INBOX_BYTES // 10 + 1)
    assert sum(big.arrive(Route("scan", f"y{i}"), 0.0, chunk) for i in range(20)) == 9
    assert big.rejected["inbox-total"] == 11
