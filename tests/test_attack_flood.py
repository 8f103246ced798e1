"""A member's flood is bounded before decoding, against real processes (world + 3 peers on
loopback): a raw Zenoh session floods s1 under s2's name with estimates stamped with the scan
s1 is on and fresh round numbers (each used to open a new slot, skip the bucket and be decoded
on the main loop). Now s1 decodes from that key at most its bucket's allowance, counts every
refusal by reason, and still fuses every scan."""

from __future__ import annotations

import time

import numpy as np
import pytest
import zenoh
from sensornet.peers.admission import Admission, Route
from sensornet.protocol.codec import decode, encode
from sensornet.protocol.messages import Estimate
from sensornet.sim.scenario import load_scenario, parse_overrides
from sensornet.tracking.mixture import GaussianMixture

from tests.attacks import K0, Attack
from tests.test_attacks import REAL, _attacked_run

pytestmark = pytest.mark.network

FLOOD = 6000


def scn_interval() -> float:
    scn = load_scenario("seed000", overrides=parse_overrides(REAL))
    return scn.scan_period / scn.network.speed


def test_fresh_round_flood_is_decoded_at_most_the_bucket_allowance(tmp_path):
    rng = np.random.default_rng(3)
    n = 20
    mix = GaussianMixture(rng.uniform(0.1, 1, n), rng.normal(0, 500, (n, 4)),
                          np.tile(np.eye(4) * 100.0, (n, 1, 1)))
    sent = {}

    def flood(handle, session, keys):
        at = {"k": 0}
        reached, interval = time.monotonic(), scn_interval()

        def on_tracks(sample) -> None:  # the scan s1 is on, followed while flooding
            at["k"] = max(at["k"], decode(sample.payload.to_bytes()).k)

        sub = session.declare_subscriber(keys.tracks("s1"), on_tracks)
        pub = session.declare_publisher(keys.estimate("s2"),
                                        congestion_control=zenoh.CongestionControl.BLOCK)
        try:
            t0 = time.monotonic()
            for i in range(FLOOD):
                # the scan s1 is on: from its tracks, or from the clock if they lag behind
                k = max(at["k"], K0 + int((time.monotonic() - reached) / interval))
                pub.put(encode(Estimate("s2", k + 1, mix, round=1000 + i)))
            sent["seconds"] = time.monotonic() - t0
            sent["last_k"] = at["k"]
        finally:
            pub.undeclare()
            sub.undeclare()

    t0 = time.monotonic()
    empty = Attack("fresh-rounds", lambda keys, k0, x: [], ("s1",))
    scn, codes, summaries = _attacked_run(tmp_path, empty, after=flood, rerun=False)
    wall = time.monotonic() - t0  # longer than any peer ran: a generous allowance
    assert all(c == 0 for c in codes.values()), codes
    s1 = summaries["s1"]
    assert s1["internal_errors"] == {} and s1["stop_reason"] == "end of run", s1
    # every flood message was refused before decoding, under its reason
    before = sum(s1["rejected"].get(r, 0) for r in ("round", "future", "stale", "rate",
                                                      "inbox", "inbox-total"))
    assert s1["rejected"].get("round", 0) >= FLOOD // 2, s1["rejected"]
    assert before >= FLOOD, (s1["rejected"], sent)
    # decoded from s2's key: s2's own estimates and at most the bucket's allowance
    interval = scn.scan_period / scn.network.speed
    per_scan = scn.network.rounds
    allowance = (max(4.0, 8.0 * per_scan) + 4.0 * per_scan * wall / interval)
    decoded = s1["admitted_by_sender"]["estimate/s2"]
    assert decoded <= allowance, (decoded, allowance)
    assert decoded < FLOOD // 10, decoded  # before: every one of them
    assert s1["inbox_peak"] <= 4096
    # and s1 fused every scan with both neighbours, to the end
    assert s1["scans"] == scn.num_scans and s1["ospa_misses"] == {"local": 0, "fused": 0}, s1
    assert s1["stats"]["last_fused_from"]["s3"] == scn.num_scans, s1["stats"]
    assert s1["stats"]["last_fused_from"]["s2"] == scn.num_scans, s1["stats"]


def test_admission_bucket_allowance_matches_the_formula_used_above():
    """The allowance the process test computes is the bucket's (capacity + rate x time)."""
    adm = Admission("x", 0.2, {"estimate": 1.0})
    r = Route("estimate", "s2")
    let = sum(adm.admit(r, i / 1000.0) for i in range(2000))  # 2 s at 1000/s
    assert let <= max(4.0, 8.0) + 4.0 * 2.0 / 0.2 + 1
    assert let >= 8 + 4.0 * 1.9 / 0.2
