"""protocol.codec.decode_fields: a host's co-hosted receivers decode an estimate from the
fields its publisher packed (peers.host_parts.SharedDecode.seed) instead of unpacking the
bytes. Checked here against decode of the same bytes: the same message (every field, every
array's bytes, dtype and shape) or the same refusal, for honest estimates (protocol 1, 2, 3)
and for what a lying peer may pack (negative or non-finite weights, a covariance that is not
positive definite, more components than the receiver takes, bad labels, odd names)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from sensornet.peers.host_parts import SharedDecode
from sensornet.protocol.codec import Limits, Rejected, decode, decode_fields, encode_fields
from sensornet.protocol.messages import Estimate
from sensornet.tracking.mixture import GaussianMixture


def _mix(rng, n, d=4, w=None, P=None):
    A = rng.normal(size=(n, d, d))
    covs = A @ A.swapaxes(1, 2) + np.eye(d) if P is None else P
    return GaussianMixture.trusted(rng.uniform(0.1, 1.0, n) if w is None else w,
                                   rng.normal(size=(n, d)) * 100, covs)


def _cases():
    rng = np.random.default_rng(7)
    lab = lambda n: np.column_stack([np.arange(n), np.full(n, 3), np.arange(n) + 5])  # noqa: E731
    yield Estimate("p01", 3, _mix(rng, 2))
    yield Estimate("p01", 3, _mix(rng, 0))
    yield Estimate("p02", 9, _mix(rng, 5), round=1, seq=4, send_time=12.5, pruning=2,
                   labels=lab(5))
    yield Estimate("p02", 9, _mix(rng, 3), labels=lab(3),
                   label_masks=rng.integers(0, 1 << 40, (3, 2)))
    yield Estimate("p03", 1, _mix(rng, 2, w=np.array([0.5, -0.1])))  # negative weight
    yield Estimate("p03", 1, _mix(rng, 2, w=np.array([np.nan, 0.4])))  # not finite
    bad = np.tile(np.eye(4), (2, 1, 1))
    bad[1, 0, 0] = -1.0
    yield Estimate("p03", 1, _mix(rng, 2, P=bad))  # not positive definite
    asym = np.tile(np.eye(4), (2, 1, 1))
    asym[0, 0, 1] = 0.3  # only the upper triangle travels: decoded symmetric
    yield Estimate("p03", 1, _mix(rng, 2, P=asym))
    yield Estimate("p03", 1, _mix(rng, 30))  # more than a small receiver takes
    yield Estimate("p03", 1, _mix(rng, 2), labels=-lab(2))  # negative labels
    yield Estimate("", 1, _mix(rng, 1))  # no sender name
    yield Estimate("x" * 100, 1, _mix(rng, 1))  # a name over max_name
    yield Estimate("p04", -1, _mix(rng, 1))  # a negative scan index
    yield Estimate("p04", 1, _mix(rng, 1), send_time=float("inf"))
    yield Estimate("p04", 1, _mix(rng, 1), kind="prediction")


def _same(a, b):
    assert type(a) is type(b)
    for f in dataclasses.fields(a):
        x, y = getattr(a, f.name), getattr(b, f.name)
        if isinstance(x, GaussianMixture):
            for u, v in ((x.weights, y.weights), (x.means, y.means), (x.covs, y.covs)):
                assert u.tobytes() == v.tobytes() and u.dtype == v.dtype and u.shape == v.shape
        elif isinstance(x, np.ndarray):
            assert x.tobytes() == y.tobytes() and x.dtype == y.dtype and x.shape == y.shape
        else:
            assert type(x) is type(y) and x == y, f.name


@pytest.mark.parametrize("limits", [Limits(), Limits(max_components=10, max_name=8)])
def test_fields_decode_as_the_bytes(limits):
    refusals = accepted = 0
    for msg in _cases():
        payload, *packed = encode_fields(msg)
        try:
            want = decode(payload, limits)
        except Rejected as exc:
            with pytest.raises(Rejected) as got:
                decode_fields(payload, *packed, limits)
            assert (got.value.reason, str(got.value)) == (exc.reason, str(exc))
            refusals += 1
            continue
        _same(decode_fields(payload, *packed, limits), want)
        accepted += 1
    assert refusals >= 8 and accepted >= 5, (refusals, accepted)


def test_shared_decode_uses_the_seed_once_and_keeps_refusals_per_receiver():
    rng = np.random.default_rng(1)
    shared, limits = SharedDecode(), Limits()
    msg = Estimate("p01", 2, _mix(rng, 3), labels=np.zeros((3, 3), np.int64))
    payload, *packed = encode_fields(msg)
    shared.seed(payload, *packed)
    first, second = shared(payload, limits), shared(payload, limits)
    assert first is second and shared.seeded == 1 and shared.hits == 1
    _same(first, decode(payload, limits))
    with pytest.raises(ValueError):  # read-only as a decoded one
        first.mixture.weights[0] = 2.0
    lie = Estimate("p01", 2, _mix(rng, 2, w=np.array([np.inf, 1.0])))
    payload, *packed = encode_fields(lie)
    shared.seed(payload, *packed)
    for _ in range(2):  # refused each time, as the bytes are
        with pytest.raises(Rejected, match="not finite|NaN"):
            shared(payload, limits)
    assert decode_fields(b"x" * (limits.max_bytes + 1), *packed, limits) is None
    assert decode_fields(payload, packed[0], "S", packed[2], limits) is None
