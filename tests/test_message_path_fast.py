"""The per-message path's fast paths (issues 33/38) give what the general code gives: the
estimate decoder's exact-type field checks fall back to the general readers (the same
refusals and reasons), the mixture's sum-first finiteness checks and Python weight checks
refuse what the element-wise ones did, the budget's Python level-2 check drops what NumPy's
did (NaN included), and a step's one-lock ``taken_all`` frees the inbox as ``taken`` did."""

from __future__ import annotations

import msgpack
import numpy as np
import pytest
from sensornet.peers.admission import Admission, parse_key
from sensornet.peers.budget import EstimateBudget
from sensornet.protocol.codec import DEFAULT_LIMITS, Rejected, decode, encode, unpack_mixture
from sensornet.protocol.messages import Estimate
from sensornet.tracking.mixture import GaussianMixture


def _estimate(n: int = 2, d: int = 4, labels: bool = True) -> Estimate:
    rng = np.random.default_rng(n)
    mix = GaussianMixture(rng.uniform(0.5, 1.0, n), rng.normal(size=(n, d)),
                          np.tile(2.0 * np.eye(d), (n, 1, 1)))
    return Estimate("p1", 7, mix, round=1, seq=3, send_time=12.5, pruning=2,
                    labels=np.arange(3 * n, dtype=np.int64).reshape(n, 3) if labels else None)


def _with(payload: bytes, index: int, value) -> bytes:
    """``payload`` with its ``index``-th wire field replaced by ``value``."""
    body = msgpack.unpackb(payload, raw=False)
    body[index] = value
    return msgpack.packb(body, use_bin_type=True)


def _reason(payload: bytes) -> str:
    with pytest.raises(Rejected) as exc:
        decode(payload)
    return exc.value.reason


@pytest.mark.parametrize("labels", [False, True])
def test_a_valid_estimate_decodes_to_what_was_encoded(labels):
    msg = _estimate(labels=labels)
    out = decode(encode(msg))
    assert (out.sender, out.k, out.round, out.seq, out.send_time, out.pruning, out.kind) == (
        "p1", 7, 1, 3, 12.5, 2, "posterior")
    np.testing.assert_array_equal(out.mixture.covs, msg.mixture.covs)
    assert (out.labels is None) == (not labels)


def test_fields_of_another_type_get_the_general_readers_answers():
    p = encode(_estimate())  # protocol 2: [v, "E", s, k, r, q, ts, p, o, d, i, x]
    assert type(decode(_with(p, 6, 12)).send_time) is float  # an int time is taken
    assert decode(_with(p, 6, 12)).send_time == 12.0
    assert _reason(_with(p, 6, float("inf"))) == "nonfinite"
    assert _reason(_with(p, 3, True)) == "field"  # a bool is not an index
    assert _reason(_with(p, 3, -1)) == "field"
    assert _reason(_with(p, 5, 1 << 53)) == "field"
    assert _reason(_with(p, 2, "")) == "field"
    assert _reason(_with(p, 2, "x" * 65)) == "field"
    assert _reason(_with(p, 9, 0)) == "field"  # dimension 0
    assert _reason(_with(p, 9, 7)) == "too-many"  # above max_dim
    assert _reason(_with(p, 9, True)) == "field"
    assert _reason(_with(p, 8, 3)) == "field"  # an unknown kind
    assert _reason(_with(p, 7, 1.0)) == "field"  # pruning not an int
    assert _reason(_with(p, 11, "x")) == "field"  # the rows not bytes
    assert _reason(_with(p, 10, [1])) == "field"  # the labels not bytes


def _rows(n: int, d: int = 2) -> np.ndarray:
    iu = np.triu_indices(d)
    return np.tile(np.r_[1.0, np.zeros(d), np.eye(d)[iu]], (n, 1))


@pytest.mark.parametrize("n", [1, 40])  # a few weights (Python) and many (NumPy)
def test_mixture_checks_refuse_in_the_same_order(n):
    def reason(rows):
        try:
            unpack_mixture(rows.tobytes(), n, 2)
        except Rejected as exc:
            return exc.reason
        return "ok"

    r = _rows(n)
    assert reason(r) == "ok"
    bad = r.copy()
    bad[-1, 1], bad[-1, 2] = np.inf, -np.inf  # their sum is NaN
    bad[-1, 0] = -1.0
    assert reason(bad) == "nonfinite"  # before the weight
    bad = r.copy()
    bad[-1, 1] = np.nan
    assert reason(bad) == "nonfinite"
    bad = r.copy()
    bad[-1, 0] = -1e-300
    bad[-1, 3] = -1.0
    assert reason(bad) == "weight"  # before the covariance
    bad = r.copy()
    bad[-1, 3] = -1.0
    assert reason(bad) == "not-psd"
    huge = r.copy()
    huge[:, 1:3] = 1e308  # finite, though their sum is not: taken, as always
    huge[:, 3] = huge[:, 5] = 1e308
    assert reason(huge) == "ok"
    with pytest.raises(Rejected) as exc:
        unpack_mixture(r.tobytes(), n + 1, 2)
    assert exc.value.reason == "shape"


@pytest.mark.parametrize("weights", [[0.9, np.nan], [np.nan, 0.9], [0.9, 0.5], [0.9, 0.2],
                                     [0.9] * 40 + [np.nan]])
def test_level2_drops_what_numpy_drops(weights):
    w = np.asarray(weights, float)
    n = len(w)
    mix = GaussianMixture.trusted(w, np.zeros((n, 2)), np.tile(np.eye(2), (n, 1, 1)))
    out = EstimateBudget(max_components=100, dim=2, level2=0.5).bound("s", mix, 2)
    keep = w > 0.5  # NumPy's answer: NaN and W0 itself are not kept
    assert len(out) == keep.sum()
    assert (out is mix) == bool(keep.all())


def test_taken_all_frees_the_inbox_as_taken_does():
    def admission():
        return Admission("net", 1.0, {"estimate": 1.0}, factor=4.0, burst=8.0)

    keys = ["sensornet/net/estimate/a", "sensornet/net/estimate/b",
            "sensornet/net/estimate/a", "sensornet/other/estimate/a"]
    one, many = admission(), admission()
    for adm in (one, many):
        for key in keys:
            adm.arrive(parse_key(key, "net"), 0.0, b"x" * 10)
    for key in keys[:3]:
        one.taken(key, 10)
    many.taken_all([(parse_key(key, "net"), 10) for key in [*keys, "sensornet/net/ctl"]])
    assert one.queued() == many.queued() == {"senders": {}, "messages": 0, "bytes": 0}
    assert many.admitted == one.admitted
    assert parse_key(keys[0], "net").tag == "estimate/a"
    assert DEFAULT_LIMITS.max_dim == 6  # the dimension bound the refusals above rely on


def test_a_shared_decode_is_reused_only_under_the_same_limits():
    from dataclasses import replace

    from sensornet.peers.host_parts import SharedDecode

    shared, payload = SharedDecode(), encode(_estimate(n=3))
    first = shared(payload, DEFAULT_LIMITS)
    assert shared(payload, DEFAULT_LIMITS) is first  # the co-hosted receivers' one decode
    assert shared(payload, replace(DEFAULT_LIMITS)) is first  # equal limits: the same
    assert shared.hits == 2
    with pytest.raises(Rejected) as exc:  # tighter limits decode again, and refuse
        shared(payload, replace(DEFAULT_LIMITS, max_components=2))
    assert exc.value.reason == "too-many"
    assert shared(payload, DEFAULT_LIMITS) is first and shared.hits == 3
    assert not first.mixture.weights.flags.writeable  # shared read-only
    assert not first.labels.flags.writeable  # its labels too: every receiver gets this array
