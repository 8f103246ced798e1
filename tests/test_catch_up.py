"""A peer that has fallen behind goes straight to its newest scan.

Found with two overloaded IMM-PF peers: each processed every queued scan, fell behind by a
different amount, and then refused the other's estimates as stale or future. The fast test
checks the driver's choice on a queue; the network test freezes a real peer (SIGSTOP) for
less than the Zenoh lease, so its scans pile up, and checks that it skips to the newest and
fuses with its neighbours again, every scan accounted for (processed or scored as a miss).
"""

from __future__ import annotations

import numpy as np
import pytest
from sensornet.peers.runtime import PeerRuntime
from sensornet.peers.telemetry import Telemetry
from sensornet.protocol.codec import encode
from sensornet.protocol.keys import Keys
from sensornet.protocol.messages import Estimate, Scan
from sensornet.tracking.mixture import GaussianMixture


class _Core:
    @staticmethod
    def window_for(channel: str) -> tuple[int, int]:
        return 4, 8  # last scan 3, horizon 5


class _Driver:
    """Just what :meth:`PeerRuntime._catch_up` uses."""

    def __init__(self) -> None:
        self.telemetry = Telemetry()
        self.core = _Core()


def _scan(keys: Keys, k: int) -> tuple:
    return ("msg", keys.scan("s1"), encode(Scan("s1", k, np.zeros((3, 2)))))


def _estimate(keys: Keys, k: int) -> tuple:
    mix = GaussianMixture(np.ones(1), np.zeros((1, 4)), np.eye(4)[None])
    return ("msg", keys.estimate("s2"), encode(Estimate("s2", k, mix)))


def test_a_peer_more_than_backlog_scans_behind_goes_to_the_newest():
    keys, drv = Keys("net"), _Driver()
    items = [_scan(keys, 4), _estimate(keys, 4), _scan(keys, 5), ("live", "s3", True),
             *(_scan(keys, k) for k in (7, 6, 8, 9, 10)), _estimate(keys, 10)]
    kept = PeerRuntime._catch_up(drv, items)
    # 4, 5 and 6 have their next BACKLOG = 4 scans queued: left out; 7-10, the estimates and
    # the liveliness change stay, in their order
    assert kept == [items[1], items[3], items[4], *items[6:]]
    assert drv.telemetry.scans_skipped_behind == 3
    assert drv.telemetry.summary(10)["scans_skipped_behind"] == 3


def test_a_backlog_of_up_to_backlog_scans_is_worked_off_whole():
    keys, drv = Keys("net"), _Driver()
    items = [_scan(keys, 4), _estimate(keys, 4), *(_scan(keys, k) for k in (5, 6, 7))]
    assert PeerRuntime._catch_up(drv, items) == items
    assert drv.telemetry.scans_skipped_behind == 0


def test_a_forged_scan_far_ahead_drops_nothing():
    keys, drv = Keys("net"), _Driver()
    items = [_scan(keys, 5), *(_scan(keys, 10**9 + i) for i in range(6)), _estimate(keys, 5)]
    assert PeerRuntime._catch_up(drv, items) == items  # the core refuses the forgeries
    assert drv.telemetry.scans_skipped_behind == 0


def test_one_scan_or_unreadable_scans_are_left_alone():
    keys, drv = Keys("net"), _Driver()
    one = [_scan(keys, 4), _estimate(keys, 4)]
    assert PeerRuntime._catch_up(drv, one) == one
    junk = ("msg", keys.scan("s1"), b"\x93not a scan")
    items = [junk, _scan(keys, 9)]  # the core counts the junk; nothing dropped for it
    assert PeerRuntime._catch_up(drv, items) == items
    assert drv.telemetry.scans_skipped_behind == 0


@pytest.mark.network
def test_a_frozen_peer_catches_up_and_fuses_again(tmp_path):
    from tests.test_network_faults import _run

    sets = ["birth.model=truth", "scenario.num_scans=60"]
    # 1 s frozen at 10 scans/s: under the 1.5 s lease, so nobody sees it leave
    scn, codes, summaries = _run("seed000", tmp_path / "run", sets, ["stop:s2@20", "cont:s2@30"],
                                 rerun=False)
    assert all(c == 0 for c in codes.values()), codes
    s2 = summaries["s2"]
    s2 = {k: v for k, v in s2.items() if k not in ("latency_ms_samples", "rss_mb_samples")}
    # it worked off its backlog, or (more than BACKLOG scans queued at once) skipped to the
    # newest: which one depends on how fast its queue refills; either way every scan is
    # accounted for, and it fuses with its neighbours again
    n = scn.num_scans
    # every scan was handled or is a miss: skipped to catch up, or refused as stale once the
    # peer had jumped ahead (which of these, and how many, depends on how the backlog arrived)
    assert s2["stats"]["scans"] + s2["ospa_misses"]["fused"] == n, s2
    # and fused with its neighbours again right to the end, both ways
    for name in ("s1", "s3"):
        assert s2["stats"]["last_fused_from"][name] >= n - 1, s2["stats"]
        assert summaries[name]["stats"]["last_fused_from"]["s2"] >= n - 1, summaries[name]
    # the skipped scans have no output and are scored as misses, not left out of the mean
    skipped = s2["scans_skipped_behind"]
    assert s2["ospa_misses"]["fused"] >= skipped and s2["ospa_misses"]["local"] >= skipped, s2
    assert s2["ospa_scored"]["fused"] + s2["ospa_misses"]["fused"] == n, s2
