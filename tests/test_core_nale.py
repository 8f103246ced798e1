"""NALE buffer (tracking.nale): newest estimate per sender, prediction by age, policies."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from sensornet.tracking.mixture import GaussianMixture
from sensornet.tracking.nale import NaleBuffer

SENDERS = ("a", "b", "c", 7)

offers_strategy = st.lists(
    st.tuples(st.sampled_from(SENDERS), st.integers(min_value=0, max_value=15)),
    min_size=0,
    max_size=40,
)


def estimate(tag: float) -> GaussianMixture:
    return GaussianMixture(np.array([tag]), np.zeros((1, 4)), np.eye(4)[None])


class RecordingPredictor:
    """A predictor that records its calls and returns a new, recognisable mixture."""

    def __init__(self):
        self.calls: list[tuple[GaussianMixture, int]] = []
        self.outputs: list[GaussianMixture] = []

    def __call__(self, est: GaussianMixture, age: int) -> GaussianMixture:
        self.calls.append((est, age))
        out = est.scaled(0.5**age)
        self.outputs.append(out)
        return out


def offer_all(buf, offers):
    """Offer ``(sender, stamp)`` pairs in order; returns the estimates offered and kept flags."""
    ests, kept = [], []
    for sender, stamp in offers:
        e = estimate(float(stamp) + 1.0)
        ests.append(e)
        kept.append(buf.offer(sender, stamp, e))
    return ests, kept


@settings(max_examples=150, deadline=None)
@given(offers=offers_strategy, data=st.data())
def test_keeps_exactly_the_newest_per_sender(offers, data):
    order = data.draw(st.permutations(range(len(offers))))
    offers = [offers[i] for i in order]
    buf = NaleBuffer()
    ests, kept = offer_all(buf, offers)
    # Reference: newest stamp per sender, the first estimate that arrived with that stamp.
    newest: dict = {}
    accepted = 0
    for (sender, stamp), e in zip(offers, ests, strict=True):
        if sender not in newest or stamp > newest[sender][0]:
            newest[sender] = (stamp, e)
            accepted += 1
    assert set(buf.stored) == set(newest)
    for sender, (stamp, e) in newest.items():
        assert buf.stored[sender][0] == stamp
        assert buf.stored[sender][1] is e
    assert buf.counts.accepted == accepted == sum(kept)
    assert buf.counts.accepted + buf.counts.redundant == len(offers)
    # ages
    k = 20
    assert buf.ages(k) == {s: k - a for s, (a, _) in newest.items()}


@settings(max_examples=150, deadline=None)
@given(
    offers=offers_strategy,
    k=st.integers(min_value=0, max_value=18),
    max_age=st.one_of(st.none(), st.integers(min_value=0, max_value=6)),
    policy=st.sampled_from(["nale", "drop-late", "as-is"]),
)
def test_collect_follows_policy(offers, k, max_age, policy):
    buf = NaleBuffer(max_age=max_age, policy=policy)
    offer_all(buf, offers)
    stored = dict(buf.stored)
    pred = RecordingPredictor()
    out = buf.collect(k, pred)
    expected_senders, too_old, late, dropped = set(), 0, 0, 0
    expected_calls = {}
    for sender, (a, est) in stored.items():
        age = k - a
        if age < 0:
            continue  # from the future: kept for later, not counted
        if max_age is not None and age > max_age:
            too_old += 1
            continue
        if age > 0 and policy == "drop-late":
            dropped += 1
            continue
        if age > 0:
            late += 1
            if policy == "nale":
                expected_calls[sender] = (est, age)
        expected_senders.add(sender)
    assert set(out) == expected_senders
    assert buf.counts.too_old == too_old
    assert buf.counts.late == late
    assert buf.counts.dropped_late == dropped
    # The predictor got exactly the stored estimates with their ages, nothing else.
    assert len(pred.calls) == len(expected_calls)
    for sender in expected_senders:
        a, est = stored[sender]
        if sender in expected_calls:
            call_index = next(i for i, (e, _) in enumerate(pred.calls) if e is est)
            assert pred.calls[call_index][1] == k - a
            assert out[sender] is pred.outputs[call_index]
            assert out[sender].weights[0] == pytest.approx(est.weights[0] * 0.5 ** (k - a))
        else:
            assert out[sender] is est
    # Collecting does not change what is stored.
    assert buf.stored == stored


def test_collect_predicts_with_gmphd_predict_by_age():
    from sensornet.tracking.gmphd import predict
    from sensornet.tracking.models import ConstantVelocity

    motion = ConstantVelocity(T=1.0, sigma_w=1.0)
    birth = GaussianMixture(np.array([0.1]), np.zeros((1, 4)), 100 * np.eye(4)[None])
    est = GaussianMixture(np.array([1.0]), np.array([[0.0, 2.0, 5.0, -1.0]]),
                          np.eye(4)[None] * 4)
    buf = NaleBuffer()
    buf.offer("p", 7, est)
    out = buf.collect(10, lambda m, age: predict(m, motion, 0.9, birth, steps=age))
    fused_input = out["p"]
    np.testing.assert_allclose(fused_input.means[0], [6.0, 2.0, 2.0, -1.0])
    assert fused_input.weights[0] == pytest.approx(0.9**3)
    assert len(fused_input) == 2  # births once
    assert buf.counts.late == 1


def test_sequence_counts_and_forget():
    buf = NaleBuffer(max_age=2)
    assert buf.offer("x", 5, estimate(1))
    assert not buf.offer("x", 5, estimate(2))  # same stamp: redundant
    assert not buf.offer("x", 3, estimate(3))  # older: redundant
    assert buf.offer("x", 6, estimate(4))
    assert buf.offer("y", 1, estimate(5))
    assert (buf.counts.accepted, buf.counts.redundant) == (3, 2)
    out = buf.collect(6, lambda m, age: pytest.fail("no prediction at age 0"))
    assert set(out) == {"x"} and buf.counts.too_old == 1  # y is 5 scans old
    out = buf.collect(8, lambda m, age: m.scaled(10.0 * age))
    assert out["x"].weights[0] == pytest.approx(4.0 * 20.0)  # estimate(4), age 2
    assert buf.counts.too_old == 2  # counted again at each fusion it is skipped
    buf.forget("y")
    buf.forget("nobody")
    assert set(buf.stored) == {"x"}
    # A newer estimate after forgetting is accepted again from scratch.
    buf.forget("x")
    assert buf.offer("x", 2, estimate(6))


def test_future_estimate_waits():
    buf = NaleBuffer(policy="drop-late")
    buf.offer("x", 9, estimate(1))
    assert buf.collect(8, lambda m, age: m) == {}
    assert buf.counts.dropped_late == 0 and buf.counts.too_old == 0
    assert set(buf.collect(9, lambda m, age: m)) == {"x"}


def test_unknown_policy():
    with pytest.raises(ValueError):
        NaleBuffer(policy="newest")
