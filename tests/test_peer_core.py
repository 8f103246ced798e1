"""The sans-I/O peer core's parts, one at a time: admission, scan window, scoring, contracts."""

from __future__ import annotations

import numpy as np
import pytest
from sensornet.peers.admission import SLOT_ATTEMPTS, Admission, Route, TokenBucket, parse_key, peek
from sensornet.peers.consensus import Consensus
from sensornet.peers.contracts import Fuser, FusionInput, LocalEstimator, LocalOutput
from sensornet.peers.core import CoreConfig, PeerCore, Publish
from sensornet.peers.fusers import NoFuser
from sensornet.peers.scoring import Scorer
from sensornet.protocol.codec import encode
from sensornet.protocol.keys import Keys
from sensornet.protocol.messages import Control, Estimate, Forward, Returns, Scan, ScanSet, Truth
from sensornet.sim.run.peers import consensus_options, make_peer
from sensornet.sim.scenario import load_scenario, parse_overrides
from sensornet.tracking.mixture import GaussianMixture

KEYS = Keys("twin")
MIX = GaussianMixture(np.ones(1), np.zeros((1, 4)), np.eye(4)[None])


def test_parse_key():
    assert parse_key("sensornet/twin/scan/s1", "twin") == Route("scan", "s1")
    assert parse_key("sensornet/twin/truth", "twin") == Route("truth", "")
    for bad in ("sensornet/other/scan/s1", "sensornet/twin/scan", "sensornet/twin/tracks/s1",
                "x/twin/scan/s1", "sensornet/twin/truth/extra", "sensornet/twin/estimate/"):
        assert parse_key(bad, "twin") is None, bad


def test_peek_reads_the_header_of_every_message_and_nothing_else():
    assert peek(encode(Estimate("s2", 12, MIX, round=1, kind="prediction"))) == ("E", 12, 1, 1)
    assert peek(encode(Scan("s1", 7, np.zeros((4, 2))))) == ("S", 7, 0, 0)
    assert peek(encode(Truth(9, np.arange(1), np.zeros((1, 4))))) == ("T", 9, 0, 0)
    assert peek(encode(Returns("s1", 5, np.zeros((3, 2)), round=0))) == ("R", 5, 0, 101)
    fwd = Forward("s2", 6, ScanSet({"s1": np.zeros((2, 2)), "s2": np.zeros((1, 2))}), round=2)
    assert peek(encode(fwd)) == ("F", 6, 2, 100)
    assert peek(encode(Control("end"))) is None
    for junk in (b"", b"\x93", b"\xff" * 50, b"\x9b" + b"\x01" * 300,
                 encode(Scan("s1", 7, np.zeros((4, 2))))[:5]):
        assert peek(junk) is None


def test_token_bucket_refills_at_its_rate():
    b = TokenBucket(rate=10.0, capacity=2.0)
    assert b.take(0.0) and b.take(0.0) and not b.take(0.0)
    assert b.take(0.1) and not b.take(0.1)


def test_admission_window_slots_and_rate():
    adm = Admission("twin", 0.1, {"estimate": 1.0, "ctl": 0.5},
                    window=lambda ch: (5, 20))
    est = lambda k: encode(Estimate("s2", k, MIX))  # noqa: E731
    r = Route("estimate", "s2")
    assert not adm.admit(r, 0.0, est(21)) and not adm.admit(r, 0.0, est(4))
    assert adm.rejected == {"future": 1, "stale": 1}
    assert all(adm.admit(r, 0.0, est(10)) for _ in range(SLOT_ATTEMPTS))
    assert not adm.admit(r, 0.0, est(10)) and adm.rejected["duplicate"] == 1
    assert adm.admit(r, 0.0, est(11))  # another slot
    # what has no parseable header is charged to the sender's bucket
    n = sum(adm.admit(r, 0.0, b"junk") for _ in range(100))
    assert 0 < n < 100 and adm.rejected["rate"] == 100 - n
    assert not adm.admit(None, 0.0, b"")
    assert adm.rejected["wrong-key"] == 1


@pytest.fixture(scope="module")
def scn():
    return load_scenario("seed000", overrides=parse_overrides(
        ["birth.model=truth", "scenario.num_scans=40"]))


def _scan(core, k, now):
    return core.receive(KEYS.scan("s1"), encode(Scan("s1", k, np.zeros((0, 2)))), now)


def test_one_scan_cannot_move_the_clock_but_a_quiet_restart_can(scn):
    core = make_peer(scn, "s1", neighbours=(), degrees=())
    _scan(core, 1, 0.0)
    _scan(core, 2, 0.1)
    _scan(core, 20, 0.15)  # a forged jump: refused, the peer keeps going
    assert core.rejected["future"] == 1 and core.consensus.last_k == 2
    _scan(core, 3, 0.2)
    assert core.consensus.last_k == 3
    # nothing accepted for more than `quiet` intervals: a new numbering is followed
    t = 0.2 + 3.5 * core.cfg.interval
    _scan(core, 30, t)
    assert core.consensus.last_k == 30 and core.reanchored == 1
    # but never one past the run's last scan (no world sends it): a forged scan 10^9 after a
    # quiet spell would leave the peer refusing every real scan as stale
    assert core.cfg.last_scan == 40
    _scan(core, 10**9, t + 3.5 * core.cfg.interval)
    assert core.rejected["future"] == 2 and core.consensus.last_k == 30
    _scan(core, 31, t + 3.6 * core.cfg.interval)
    assert core.consensus.last_k == 31 and core.reanchored == 1


def test_a_gap_in_the_scans_is_scored_as_misses(scn):
    core = make_peer(scn, "s1", neighbours=(), degrees=())
    for k in (1, 2, 5):  # scans 3 and 4 never arrive
        _scan(core, k, 0.1 * k)
        core.tick(0.1 * k)
    core.finish(1.0)
    s = core.snapshot()
    assert s["ospa_misses"] == {"local": 2, "fused": 2}
    assert s["ospa_scored"] == {"local": 3, "fused": 3}
    c = scn.metrics.ospa_cutoff
    assert s["mean_ospa_fused"] >= 2 * c / 5  # the two misses count c each


def test_scans_missed_during_a_pause_are_misses_a_new_numbering_is_not(scn):
    """A peer frozen (or far behind) for 2 s at 10 scans/s comes back at scan 23: the 20
    scans in between had no output (misses). The world restarting its numbering at 38 after
    a pause is a new start, not 14 misses."""
    core = make_peer(scn, "s1", neighbours=(), degrees=())
    dt = core.cfg.interval
    for k in (1, 2):
        _scan(core, k, k * dt)
        core.tick(k * dt)
    _scan(core, 23, 2 * dt + 2.0)
    core.tick(2 * dt + 2.0)
    assert core.consensus.last_k == 23 and core.reanchored == 1
    assert core.snapshot()["ospa_misses"] == {"local": 20, "fused": 20}
    _scan(core, 38, 2 * dt + 2.0 + 4 * dt)
    assert core.consensus.last_k == 38 and core.reanchored == 2
    assert core.snapshot()["ospa_misses"] == {"local": 20, "fused": 20}


def test_scorer_truth_from_the_scenario_rejects_a_forged_truth():
    true = np.array([[0.0, 0.0, 0.0, 0.0]])
    sc = Scorer(100.0, 2.0, (0, 2), truth=lambda k: true)
    assert sc.truth_message(1, true) is None
    assert sc.truth_message(1, true + 50) == "truth-mismatch"
    sc.expect(1)
    sc.output("fused", 1, true + [[3.0, 0, 4.0, 0]])
    assert sc.mean("fused") == pytest.approx(5.0)
    sc.expect(2)
    sc.finish()
    assert sc.mean("fused") == pytest.approx((5.0 + 100.0) / 2)  # the missing one: c


def test_scorer_without_truth_function_keeps_the_first_truth():
    sc = Scorer(100.0, 2.0, (0, 2))
    x = np.zeros((1, 4))
    assert sc.truth_message(3, x) is None
    assert sc.truth_message(3, x) is None  # the same again: fine
    assert sc.truth_message(3, x + 1) == "truth-conflict"


def test_forged_end_does_not_stop_a_peer_but_the_world_leaving_does(scn):
    core = make_peer(scn, "s1")
    core.liveliness("world", True, 0.0)
    assert core.receive(KEYS.ctl(), encode(Control("end")), 0.1) == []
    assert core.ctl_end_early == 1
    out = core.liveliness("world", False, 0.2)
    assert [type(o).__name__ for o in out][-1] == "Stop" and out[-1].reason == "end of run"


def test_wrong_dimension_is_incompatible_before_fusion(scn):
    core = make_peer(scn, "s1")
    bad = GaussianMixture(np.ones(2), np.zeros((2, 2)), np.tile(np.eye(2), (2, 1, 1)))
    core.receive(KEYS.estimate("s2"), encode(Estimate("s2", 1, bad)), 0.0)
    assert core.rejected["incompatible"] == 1 and core.consensus.stats.estimates_in == 0


class _CountingEstimator:
    """The ten-line example of docs/architecture.md: a new estimator plugs in as is."""

    dim, kinds, position_index = 4, ("posterior",), (0, 2)

    def step(self, steps: int, z: np.ndarray) -> LocalOutput:
        means = np.zeros((len(z), 4))
        means[:, [0, 2]] = z
        mix = GaussianMixture(np.ones(len(z)), means, np.tile(np.eye(4), (len(z), 1, 1)))
        return LocalOutput(mix, {"posterior": mix})

    def predict(self, mix, steps):
        return mix

    def extract(self, mix):
        return mix.means

    def adopt(self, fused):
        pass


def test_a_new_estimator_plugs_into_the_contracts(scn):
    est = _CountingEstimator()
    assert isinstance(est, LocalEstimator) and isinstance(NoFuser(), Fuser)
    consensus = Consensus(consensus_options(scn, "s1", neighbours=(), degrees=()), est,
                          NoFuser())
    core = PeerCore(CoreConfig("s1", "s1", "twin"), consensus,
                    Scorer(100.0, 2.0, est.position_index))
    out = core.receive(KEYS.scan("s1"), encode(Scan("s1", 1, np.array([[1.0, 2.0]]))), 0.0)
    tracks = [o for o in out if isinstance(o, Publish) and o.channel == "tracks"]
    assert len(tracks) == 1 and np.allclose(tracks[0].message.states[:, [0, 2]], [[1.0, 2.0]])


def test_fusion_input_carries_weights_in_sorted_order():
    inp = FusionInput(1, 0, MIX, {"b": {"posterior": MIX}, "a": {"posterior": MIX}},
                      (0.5, 0.25, 0.25), np.zeros((0, 2)))
    assert sorted(inp.neighbours) == ["a", "b"] and sum(inp.weights) == 1.0


def test_a_restarted_peer_never_overwrites_its_earlier_files(tmp_path):
    from sensornet.peers.runtime import output_stem
    from sensornet.sim.run.launcher import read_summaries

    assert output_stem(tmp_path, "s2") == "peer-s2"
    (tmp_path / "rerun").mkdir()
    (tmp_path / "rerun" / "peer-s2.rrd").write_bytes(b"")  # killed: a recording, no summary
    assert output_stem(tmp_path, "s2") == "peer-s2.restart1"
    (tmp_path / "peer-s2.restart1.json").write_text('{"scans": 5}')
    assert output_stem(tmp_path, "s2") == "peer-s2.restart2"
    (tmp_path / "peer-s2.restart2.json").write_text('{"scans": 9}')
    (tmp_path / "peer-s22.json").write_text('{"scans": 1}')  # another peer's
    got = read_summaries(tmp_path, ["s2"])["s2"]
    assert got["scans"] == 9
    assert got["summary_files"] == ["peer-s2.restart1.json", "peer-s2.restart2.json"]


def test_tracks_closed_by_a_scan_far_ahead_are_scored_not_missed(scn):
    """A peer frozen while scan 1's consensus waited for its neighbours comes back at scan 15:
    that scan closes scan 1 with what it has (tracks published, scored after publishing) and
    scans 2-14 are misses. Scan 1's tracks must be scored before the scorer settles scans
    that far behind (a loaded run once counted one miss too many)."""
    core = make_peer(scn, "s1", 0)  # neighbours s2, s3, which never send
    dt = core.cfg.interval
    _scan(core, 1, dt)
    _scan(core, 15, dt + 2.0)
    core.tick(dt + 2.0)
    core.finish(dt + 2.0 + dt)
    s = core.snapshot()
    assert s["ospa_misses"]["fused"] == 13, s["ospa_misses"]
    assert s["ospa_scored"]["fused"] == 2, s["ospa_scored"]


def test_skipped_scans_count_in_the_cardinality_error_as_no_target():
    from sensornet.peers.scoring import Scorer

    truth = {k: np.zeros((k, 4)) for k in range(1, 6)}  # k targets at scan k
    s = Scorer(100.0, 2.0, (0, 2), truth=truth.get)
    s.expect(1)
    s.output("fused", 1, np.zeros((1, 4)))  # right number at scan 1
    s.skipped(range(2, 4))  # scans 2 and 3 never arrived: 2 + 3 targets missed
    assert s.mean("fused") == pytest.approx((0.0 + 2 * 100.0) / 3)
    assert s.mean_cardinality_error("fused") == pytest.approx((0 + 2 + 3) / 3)


def test_optional_hooks_are_declared_with_defaults():
    """The core, the consensus and the observer call a part's optional hooks through the
    contracts' declarations: a part without them gets the defaults, one with them its own."""
    from sensornet.peers.contracts import EstimatorHooks, FuserHooks
    from sensornet.sim.run.peers import make_parts
    from sensornet.sim.scenario import load_scenario

    plain = EstimatorHooks.of(object())
    assert plain.payload == "mixture" and plain.plane is None and plain.model_names == ()
    assert plain.particles() is None and plain.pda_view() is None
    assert plain.partition_view() is None
    assert FuserHooks.of(object()) == FuserHooks()
    est, fuser = make_parts(load_scenario("seed004"), "s1")
    hooks, fh = EstimatorHooks.of(est), FuserHooks.of(fuser)
    assert hooks.payload == "scans" and hooks.plane == est.plane
    assert fh.late == fuser.late and fh.outgoing == fuser.outgoing
    est, fuser = make_parts(load_scenario("seed001"), "r1")
    hooks = EstimatorHooks.of(est)
    assert hooks.model_names == ("CV", "CA") and hooks.particles == est.particles
    assert FuserHooks.of(fuser).model_probabilities == fuser.model_probabilities
