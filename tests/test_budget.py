"""What one member's estimate may cost a receiver (issue 36 items 1-2, peers.budget): a byte
budget per member before decoding, a reduction to the receiver's own limits after, and a
divergence whose memory stays linear. Costs are counted (components reaching the trust test's
divergence and the fusion), never timed: benchmarks/bench_padding.py prints the times."""

from __future__ import annotations

import numpy as np
import pytest
import sensornet.peers.trust_checks as checks_mod
import sensornet.tracking.divergence as divergence
from scipy.stats import multivariate_normal
from sensornet.peers.admission import Admission, ByteBudget, Route
from sensornet.peers.budget import EstimateBudget, heaviest, row_bytes
from sensornet.peers.core_summary import budget_lines
from sensornet.protocol.codec import encode
from sensornet.protocol.messages import Estimate, Forward, ScanSet
from sensornet.sim.run.lies import LyingCore
from sensornet.sim.run.peers import make_peer
from sensornet.sim.run.twin import run_twin
from sensornet.sim.scenario import load_scenario
from sensornet.tracking.mixture import GaussianMixture
from sensornet.tracking.reduction import Reducer

PAD = 2000
"""The codec's component limit: what the padding lie fills an estimate to."""


def _mix(n: int, rng: np.random.Generator, w: float | None = None, d: int = 4,
         spread: float = 1000.0) -> GaussianMixture:
    weights = rng.uniform(0.6, 1.0, n) if w is None else np.full(n, w)
    return GaussianMixture(weights, rng.uniform(-spread, spread, (n, d)),
                           np.tile(25.0 * np.eye(d), (n, 1, 1)))


def padded(rng: np.random.Generator, n: int = PAD):
    """The padding lie: the real estimate plus negligible-weight components up to ``n``."""
    def lie(mix: GaussianMixture, k: int = 0) -> GaussianMixture:
        extra = _mix(max(0, n - len(mix)), rng, w=1e-4, d=mix.dim)
        return GaussianMixture.concatenate([mix, extra])
    return lie




# -- before decoding: bytes per member ---------------------------------------------------------
def test_byte_budget_lets_a_message_into_debt_then_waits_for_it():
    b = ByteBudget(rate=100.0, capacity=200.0)
    assert b.open(0.0)
    b.charge(150)
    assert b.open(0.0)  # 50 left
    b.charge(10**9)  # larger than the capacity: let in once, charged at most the capacity
    assert not b.open(0.0) and not b.open(1.4)
    assert b.open(1.51)  # the debt (150) paid at 100 B/s


def _admission(estimate_bytes=None):
    return Admission("net", 1.0, {"estimate": 1.0}, factor=4.0, burst=8.0,
                     estimate_bytes=estimate_bytes)


SLOT = EstimateBudget(100, 4).slot_bytes(4.0)
"""A J = 100, d = 4 receiver's byte budget per scan and estimate slot: one 2,000-component
estimate plus 4 times a 100-component one."""


def test_a_member_sending_its_whole_rate_in_huge_estimates_is_bounded_by_size():
    assert SLOT == 2000 * 120 + 256 + 4 * (100 * 120 + 256)
    rng = np.random.default_rng(0)
    big = encode(Estimate("liar", 1, _mix(PAD, rng)))  # 240 kB
    small = encode(Estimate("honest", 1, _mix(10, rng)))
    liar, padder, honest = (Route("estimate", n) for n in ("liar", "padder", "honest"))
    adm = _admission(SLOT)
    got = {"liar": 0, "padder": 0, "honest": 0}
    for k in range(200):  # 1 s scans: the liar sends 4 a scan (its message rate), the others 1
        for i in range(4):
            got["liar"] += adm.admit(liar, k + i / 4, big)
        got["padder"] += adm.admit(padder, float(k), big)
        got["honest"] += adm.admit(honest, float(k), small)
    assert got["honest"] == 200 and got["padder"] == 200  # one at the codec's limit a scan
    # the liar: its bytes over 200 scans and the burst, not its 4 messages a scan
    assert 200 * SLOT / len(big) - 2 <= got["liar"] <= 208 * SLOT / len(big) + 1
    free = _admission(None)  # the message rate alone lets through 4 a scan
    assert sum(free.admit(liar, k + i / 4, big) for k in range(200) for i in range(4)) >= 790
    assert adm.rejected["bytes"] == 800 - got["liar"]
    assert adm.over_budget == {"estimate/liar": 800 - got["liar"]}
    assert adm.over_budget_bytes["estimate/liar"] == (800 - got["liar"]) * len(big)


def test_scan_forwards_are_not_charged_to_the_estimate_budget():
    fwd = encode(Forward("s", 1, ScanSet({"a": np.zeros((5000, 2))})))
    adm = _admission(1000)
    assert all(adm.admit(Route("estimate", "s"), float(k), fwd) for k in range(20))
    assert not all(adm.admit(Route("estimate", "t"), float(k), encode(Estimate(
        "t", 1, _mix(20, np.random.default_rng(0))))) for k in range(20))
    assert set(adm.over_budget) == {"estimate/t"}  # the estimates only, not the forwards


# -- after decoding: the reduction -------------------------------------------------------------
def _budget(level2=0.5, J=100):
    return EstimateBudget(J, 4, level2, Reducer(max_components=J))


def test_an_honest_estimate_passes_untouched():
    rng = np.random.default_rng(1)
    mix = _mix(12, rng)
    b = _budget()
    assert b.bound("s2", mix, pruning=2) is mix
    msg = Estimate("s2", 3, mix, pruning=2)
    assert b.bound_estimate(msg) is msg
    assert b.counts()["reduced"] == {} and b.counts()["largest"] == {"s2": 12}


def test_padding_of_a_level2_estimate_is_cut_to_the_real_estimate():
    rng = np.random.default_rng(2)
    real = _mix(9, rng)
    lie = padded(rng)(real)
    b = _budget()
    for pruning in (1, 2):  # round 0 is level-2 pruned whatever the sender declares
        out = b.bound("liar", lie, pruning=pruning, rnd=0)
        assert len(out) == 9
        assert np.array_equal(out.means, real.means) and np.array_equal(out.weights,
                                                                        real.weights)
    assert b.reduced["liar"] == 2 and b.dropped["liar"] == 2 * (PAD - 9)


def test_a_later_round_is_cut_to_the_receivers_limit_keeping_the_heaviest():
    rng = np.random.default_rng(3)
    mix = _mix(PAD, rng, spread=1e5)  # far apart: nothing merges
    mix = GaussianMixture(rng.permutation(np.linspace(0.01, 1.0, PAD)), mix.means, mix.covs)
    b = _budget(J=50)
    out = b.bound("s2", mix, pruning=1, rnd=1)
    assert len(out) == 50
    top = np.sort(mix.weights)[-50:]  # brute force: the 50 heaviest weights
    assert np.allclose(np.sort(out.weights), top)
    # components that merge are merged with the receiver's reducer, as its own would be
    near = GaussianMixture(np.full(300, 0.4), np.zeros((300, 4)) + rng.normal(0, 0.01, (300, 4)),
                           np.tile(25.0 * np.eye(4), (300, 1, 1)))
    merged = b.bound("s3", near, pruning=1, rnd=1)
    assert len(merged) == 1 and np.isclose(merged.mass, 0.4 * 100)  # the 2 J kept, merged


def test_heaviest_is_the_sorted_top_n():
    w = np.random.default_rng(4).uniform(size=1000)
    assert np.array_equal(heaviest(w, 10), np.sort(np.argsort(-w)[:10]))
    assert np.array_equal(heaviest(w[:5], 10), np.arange(5))


def test_bad_budgets_are_refused():
    with pytest.raises(ValueError, match="max_components"):
        EstimateBudget(0, 4)
    with pytest.raises(ValueError, match="dim"):
        EstimateBudget(10, 0)
    assert _budget().message_bytes == 100 * row_bytes(4) + 256 and row_bytes(4) == 120
    with pytest.raises(ValueError, match="estimate_bytes"):
        _admission(0)


# -- the divergence: same numbers, memory linear -----------------------------------------------
def test_blocked_log_overlaps_match_a_brute_force_reference(monkeypatch):
    rng = np.random.default_rng(5)
    mixes = []
    for n in (7, 0, 11, 4):
        A = rng.normal(size=(n, 4, 4))
        mixes.append(GaussianMixture(rng.uniform(0.1, 1.0, n), rng.normal(0, 3, (n, 4)),
                                     A @ A.transpose(0, 2, 1) + 2 * np.eye(4)))
    ref = np.full((4, 4), -np.inf)
    for i, p in enumerate(mixes):
        for j, q in enumerate(mixes):
            s = sum(a * b * multivariate_normal(mb, Pa + Pb).pdf(ma)
                    for a, ma, Pa in zip(p.weights, p.means, p.covs, strict=True)
                    for b, mb, Pb in zip(q.weights, q.means, q.covs, strict=True))
            if s > 0:
                ref[i, j] = np.log(s)
    one = divergence.log_overlaps(mixes)
    monkeypatch.setattr(divergence, "BLOCK_PAIRS", 30)  # 22 components: rows of 1
    blocked = divergence.log_overlaps(mixes)
    for L in (one, blocked):
        assert np.array_equal(np.isfinite(L), np.isfinite(ref))
        assert np.allclose(L[np.isfinite(L)], ref[np.isfinite(ref)], rtol=1e-10)


# -- the whole receiver, trust on: counted cost of a padded member -----------------------------
SCANS = 15


@pytest.fixture(scope="module")
def runs():
    scn = load_scenario("seed000", overrides={"fusion.rule": "hybrid", "fusion.trust": True,
                                              "scenario.num_scans": SCANS})
    out = {}
    for case in ("honest", "padded"):
        calls: list[int] = []

        def counted(mixes, _orig=divergence.log_overlaps, _calls=calls):
            _calls.append(sum(len(m) for m in mixes))
            return _orig(mixes)

        mp = pytest.MonkeyPatch()
        mp.setattr(checks_mod, "log_overlaps", counted)
        try:
            peers = {n: make_peer(scn, n, 0) for n in scn.sensor_names}
            fused: list[int] = []
            for n in ("s1", "s3"):
                fuser = peers[n].consensus.fuser
                fuse = fuser.fuse

                def fuse_counted(inp, _fuse=fuse, _fused=fused):
                    _fused.append(sum(len(v["posterior"]) for v in inp.neighbours.values()))
                    return _fuse(inp)
                fuser.fuse = fuse_counted
            if case == "padded":
                peers["s2"] = LyingCore(peers["s2"], padded(np.random.default_rng(6)))
            res = run_twin(scn, 0, peers=peers)
        finally:
            mp.undo()
        out[case] = (res, calls, fused)
    return out


def test_a_padded_member_costs_its_neighbours_no_more_than_an_honest_one(runs):
    (hon, hcalls, hfused), (pad, pcalls, pfused) = runs["honest"], runs["padded"]
    assert pad.peers["s2"].lies_told >= SCANS - 1
    assert hcalls and pcalls and hfused and pfused
    # components reaching the divergence and the fusion, per call and in all: the honest
    # run's (the padding is cut on arrival: s2's real estimate is what is left)
    assert pcalls == hcalls and pfused == hfused
    for n in ("s1", "s3"):
        b = pad.summary(n)["budget"]
        assert b["refused"] == {}  # one estimate a scan at the codec's limit: let in, cut
        assert b["reduced"]["s2"] >= SCANS - 1  # every padded one
        assert b["components_dropped"]["s2"] >= b["reduced"]["s2"] * (PAD - 100)
        assert b["largest"]["s2"] == PAD
        assert hon.summary(n)["budget"]["reduced"] == {}  # honest: nothing cut
        assert hon.summary(n)["budget"]["refused"] == {}
        # every scan processed in time, tracked as with an honest neighbour
        assert pad.summary(n)["scans"] == hon.summary(n)["scans"]
        assert pad.summary(n)["stats"]["deadline_fusions"] == 0
        assert pad.summary(n)["internal_errors"] == {}
        assert pad.mean_ospa(n) == pytest.approx(hon.mean_ospa(n), rel=1e-9)
    lines = budget_lines({n: pad.summary(n) for n in ("s1", "s3")})
    assert len(lines) == 1 and lines[0].startswith("over budget: s2's estimates, by s1: ")
    assert "reduced" in lines[0] and "refused" not in lines[0]



def test_labels_follow_the_rows_kept_and_go_where_components_merge():
    rng = np.random.default_rng(7)
    real = _mix(5, rng)
    lie = padded(rng, 300)(real)
    labels = np.arange(300 * 3, dtype=np.int64).reshape(300, 3)
    b = _budget(J=50)
    cut = b.bound_estimate(Estimate("s2", 1, lie, round=0, pruning=2, labels=labels))
    assert len(cut.mixture) == 5 and np.array_equal(cut.labels, labels[:5])
    merged = b.bound_estimate(Estimate("s2", 1, lie, round=1, pruning=1, labels=labels))
    assert len(merged.mixture) <= 50 and merged.labels is None


def test_a_liars_labels_follow_its_rows():
    """The lie keeps its own rows' labels, pads appended rows with label 0 and sends none when
    it drops rows (protocol 2 refuses labels of another length)."""
    from sensornet.sim.run.lies import told_labels

    own = np.array([[1, 5, 0], [2, 7, 3]], np.int64)
    assert told_labels(None, 4) is None
    assert np.array_equal(told_labels(own, 2), own)
    padded_labels = told_labels(own, 5)
    assert padded_labels.shape == (5, 3) and np.array_equal(padded_labels[:2], own)
    assert not padded_labels[2:].any()
    assert told_labels(own, 1) is None
