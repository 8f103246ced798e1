"""A transient fault does not end a peer for good: frozen past the lease (its links to the world
and the others lapse), it rides out the world's absence within the grace, relinks, and finishes
the run, every scan after its return processed (issue 25: it used to stop with "world left
before ending the run", the grace defaulting to 0)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from sensornet.peers.core_types import WORLD_GRACE_MIN, WORLD_GRACE_SCANS, CoreConfig
from sensornet.sim.run.peers import make_peer
from sensornet.sim.scenario import load_scenario

from tests.test_network_faults import FOUR, _run


def test_the_default_grace_is_a_few_scan_intervals_and_at_least_a_few_seconds():
    assert CoreConfig("p", "p", "n", interval=0.1).grace() == WORLD_GRACE_MIN
    assert CoreConfig("p", "p", "n", interval=1.0).grace() == WORLD_GRACE_SCANS * 1.0
    assert CoreConfig("p", "p", "n", interval=1.0, world_grace=0.0).grace() == 0.0  # at once
    core = make_peer(load_scenario("seed000"), "s1")
    core.liveliness("world", True, 0.0)
    assert core.liveliness("world", False, 1.0) == []  # not the end: within the grace
    assert core.next_due() == 1.0 + core.cfg.grace()


@pytest.mark.network
def test_a_peer_frozen_5s_with_a_1s_lease_rejoins_and_finishes(tmp_path):
    source = tmp_path / "four.toml"
    source.write_text(FOUR)
    sets = ["birth.model=truth", "scenario.num_scans=125"]
    # 10 scans/s: s3 frozen from scan 15 to scan 65, 5 s, five times the lease (30 scans of
    # margin after the latest return asserted below, as before)
    faults = ["stop:s3@15", "cont:s3@65"]
    scn, codes, summaries = _run(str(source), tmp_path / "run", sets, faults, rerun=False,
                                 lease_ms=1000, peer_args={"s3": ["--save-tracks"]})
    done = json.loads((tmp_path / "run" / "process-faults.json").read_text())
    assert [d["action"] for d in done] == ["stop", "cont"]
    assert all(c == 0 for c in codes.values()), codes
    s3 = summaries["s3"]
    assert s3["stop_reason"] == "end of run", s3["stop_reason"]
    assert s3["internal_errors"] == {} and s3["last_k"] == scn.num_scans, s3
    assert len(s3["world_outages"]) >= 1, s3["world_outages"]  # it was gone, and came back
    saved = np.load(tmp_path / "run" / "tracks-s3.npz")
    ks = sorted(int(name[1:]) for name in saved.files)
    # the freeze is the longest gap in its tracks (when SIGSTOP lands depends on the
    # machine's load: the faults follow s1's scans); after it, every scan to the end
    i = max(range(1, len(ks)), key=lambda j: ks[j] - ks[j - 1])
    back = ks[i]  # the first scan fused after its return
    assert back - ks[i - 1] > 20, ks  # 5 s frozen at 10 scans/s
    assert back <= 65 + 30, ks  # back within 3 s of SIGCONT (relinked, world seen again)
    assert ks[i:] == list(range(back, scn.num_scans + 1)), ks  # then every one
    n = scn.num_scans
    assert s3["ospa_scored"]["fused"] + s3["ospa_misses"]["fused"] == n, s3
    for name in ("s1", "s2", "s4"):  # the others fused it again after its return
        assert summaries[name]["stop_reason"] == "end of run"
        got = summaries[name]
        assert got["stats"]["last_fused_from"]["s3"] >= n - 1, (
            name, got["stats"]["last_fused_from"], got["peer_events"], got["admitted_by_sender"])
