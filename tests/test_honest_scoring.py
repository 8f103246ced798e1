"""Every scan a peer never fused is scored as a miss at the cut-off (README), also when it fell
behind: the summary's mean OSPA equals the OSPA recomputed from its saved tracks with each
missing scan at the cut-off.

Found with flooded peers: one that skipped a backlog compared the jump in scan numbers with
the wall time since its last scan, took it as a new numbering of the scans, and counted no
miss (summaries said 0 misses and 34-44 m; the recomputation gave 89-118 m)."""

from __future__ import annotations

import numpy as np
import pytest
from sensornet.peers.core import PeerCore
from sensornet.protocol.codec import encode
from sensornet.protocol.keys import Keys
from sensornet.protocol.messages import Scan
from sensornet.sim.run.peers import make_peer, truth_function
from sensornet.sim.scenario import load_scenario, parse_overrides
from sensornet.tracking.metrics import ospa

SETS = ["birth.model=truth", "scenario.num_scans=60"]


def recomputed(scn, tracks: dict[int, np.ndarray], which_pos=(0, 2)) -> float:
    """Mean OSPA over every scan of the run: each saved track set against the truth, each
    scan without one at the cut-off."""
    truth = truth_function(scn, 0)
    c, p = scn.metrics.ospa_cutoff, scn.metrics.ospa_order
    pos = list(which_pos)
    vals = []
    for k in range(1, scn.num_scans + 1):
        X = truth(k)
        if k not in tracks:
            vals.append(c)
            continue
        est = tracks[k][:, pos] if len(tracks[k]) else np.zeros((0, 2))
        vals.append(ospa(est, X[:, pos] if len(X) else np.zeros((0, 2)), c, p))
    return float(np.mean(vals))


def _scan(core: PeerCore, k: int, now: float, sent: float) -> list:
    z = np.zeros((0, 2))
    return core.receive(Keys("twin").scan("s1"), encode(Scan("s1", k, z, send_time=sent)), now)


def test_a_jump_the_world_clock_explains_is_scored_as_misses_not_a_new_numbering():
    """A peer 3 s behind (it was handling old scans) skips to the newest: the jump (30 scans)
    is far more than the wall time since its last scan explains, but the world's send times
    say it is the same numbering: every scan in between is a miss."""
    scn = load_scenario("seed000", overrides=parse_overrides(SETS))
    core = make_peer(scn, "s1")
    dt = core.cfg.interval
    for k in range(1, 10):  # on time (scans are numbered from 1)
        _scan(core, k, 100.0 + k * dt, 100.0 + k * dt)
    # behind: scan 10 (sent long ago) handled at 104.0; then the scans are refused until
    # quiet, and scan 40 (sent at 104.0) is taken at 104.0 + quiet
    _scan(core, 10, 104.0, 100.0 + 10 * dt)
    late = 104.0 + (core.cfg.quiet + 1) * dt
    _scan(core, 40, late, 100.0 + 40 * dt)
    core.finish(late + 1.0)
    assert core.reanchored == 1
    skipped = 40 - 10 - 1
    s = core.scorer
    assert s.misses["fused"] >= skipped and s.misses["local"] >= skipped, s.misses
    assert s.counts["fused"] + s.misses["fused"] == 11 + skipped


def test_a_restart_of_the_numbering_is_still_a_new_numbering():
    scn = load_scenario("seed000", overrides=parse_overrides(SETS))
    core = make_peer(scn, "s1")
    dt = core.cfg.interval
    for k in range(1, 10):
        _scan(core, k, 100.0 + k * dt, 100.0 + k * dt)
    # a world restarted 1.1 s later at scan 50 (its clock says: not 41 scans after scan 9)
    later = 102.0
    _scan(core, 50, later, later)
    core.finish(later + 1.0)
    assert core.reanchored == 1
    assert core.scorer.misses["fused"] <= 2, core.scorer.misses  # none for 10..49


@pytest.mark.network
def test_a_peer_frozen_past_its_backlog_reports_the_true_ospa(tmp_path):
    """s2 frozen (SIGSTOP) for 3 s at 10 scans/s, under the lease: on return its queued scans
    come in a burst, it skips to the newest; its summary counts every scan it has no tracks for
    as a miss, and its mean fused OSPA is the recomputation from its saved tracks."""
    from tests.test_network_faults import _run

    scn, codes, summaries = _run("seed000", tmp_path / "run", SETS,
                                 ["stop:s2@20", "cont:s2@50"], rerun=False, lease_ms=6000,
                                 peer_args={"s2": ["--save-tracks", "--world-grace", "4"]})
    assert all(c == 0 for c in codes.values()), codes
    s2 = summaries["s2"]
    assert s2["stop_reason"] == "end of run" and s2["internal_errors"] == {}, s2
    saved = np.load(tmp_path / "run" / "tracks-s2.npz")
    tracks = {int(name[1:]): saved[name] for name in saved.files}
    n = scn.num_scans
    missing = n - len([k for k in tracks if 1 <= k <= n])
    assert missing >= 10, sorted(tracks)  # the freeze cost it scans
    assert s2["ospa_misses"]["fused"] == missing, (s2["ospa_misses"], missing)
    assert s2["ospa_scored"]["fused"] + s2["ospa_misses"]["fused"] == n, s2
    assert s2["mean_ospa_fused"] == pytest.approx(recomputed(scn, tracks), abs=1e-6)


def test_scans_the_world_published_after_this_peers_last_are_misses():
    """A peer that got no scans after scan 10 (a link that never came back) while the world
    went on to 20: the world's "end" names its last scan, and the ten this peer never handled
    are misses; an "end" naming a scan absurdly far ahead changes nothing."""
    from sensornet.protocol.messages import Control

    scn = load_scenario("seed000", overrides=parse_overrides(SETS))
    ctl = Keys("twin").ctl()
    for last, extra in ((20, 10), (10**9, 0), ("20", 0)):
        core = make_peer(scn, "s1")
        dt = core.cfg.interval
        for k in range(1, 11):
            _scan(core, k, 100.0 + k * dt, 100.0 + k * dt)
        core.receive(ctl, encode(Control("end", "r", {"last_k": last})), 102.0)
        core.finish(102.5)
        s = core.scorer
        assert s.counts["fused"] + s.misses["fused"] == 10 + extra, (last, s.misses)
        assert s.misses["fused"] >= extra and s.misses["local"] >= extra
