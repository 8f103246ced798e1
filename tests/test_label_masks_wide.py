"""Holder masks for any number of peers (issue 33): a bit per peer in words of 39 bits
(peers.label_support), word 0 in the labels' origin column (Estimate protocol 2, unchanged up to
39 peers), words 1.. in the Estimate's ``label_masks`` (protocol 3). Until 5 Dec peers shared a
bit modulo 39, and above 39 peers an honest far stamper whose bit aliased a near peer's failed
the birth check (176 honest labels refused as ``label-scan`` on the 50-peer LMB twin)."""

from __future__ import annotations

import msgpack
import numpy as np
import pytest
from sensornet.peers.label_support import (
    SUPPORT_BITS,
    SUPPORT_SHIFT,
    LabelSupport,
    as_words,
    decode,
    mask_ints,
    origin_words,
    peer_bit,
    reach_by_name,
    reach_masks,
)
from sensornet.protocol.codec import LABELS_VERSION, MASKS_VERSION, Rejected
from sensornet.protocol.codec import decode as wire_decode
from sensornet.protocol.codec import encode as wire_encode
from sensornet.protocol.messages import Estimate
from sensornet.tracking.label_keys import PUBLISHED_BASE as PB
from sensornet.tracking.label_keys import SHARED_ORIGIN as S
from sensornet.tracking.mixture import GaussianMixture


def _ring(n: int) -> np.ndarray:
    A = np.zeros((n, n), dtype=int)
    for i in range(n):
        A[i, (i + 1) % n] = A[(i + 1) % n, i] = 1
    return A


def _mixture(n: int) -> GaussianMixture:
    return GaussianMixture(np.full(n, 0.5), np.arange(4.0 * n).reshape(n, 4),
                           np.tile(np.eye(4), (n, 1, 1)))


def test_words_hold_any_peers_bit_exactly():
    for origin in (1, 39, 40, 41, 50, 78, 79, 200):
        w = as_words(peer_bit(origin))
        assert len(w) == (origin - 1) // SUPPORT_BITS + 1 and mask_ints(w) == peer_bit(origin)
        np.testing.assert_array_equal(origin_words(np.array([origin]), len(w))[0], w)
    x = sum(peer_bit(o) for o in (1, 2, 39, 40, 45, 50))
    assert mask_ints(as_words(x)) == x
    # one int64 a row (bits 0..62), as callers passed masks before words: split alike
    row = np.array([peer_bit(3), peer_bit(39) | peer_bit(40), peer_bit(63)], dtype=np.int64)
    assert mask_ints(as_words(row)) == [int(v) for v in row]
    with pytest.raises(ValueError, match="negative"):
        as_words(-1)


def test_fifty_peers_have_fifty_bits_in_every_reach_table():
    n = 50
    r = reach_masks(_ring(n), list(range(1, n + 1)), 0)
    assert set(r) == {1, n - 1} and r[1].shape[1] == 2
    # at the last hop, neighbour 1 vouches for itself and every peer 0 does not hear: 48 bits
    assert bin(mask_ints(r[1][-1])).count("1") == n - 2
    assert mask_ints(r[1][-1]) & (peer_bit(1) | peer_bit(n)) == 0


def test_a_far_stamper_beyond_39_peers_is_vouched_and_a_near_one_is_still_checked():
    # a ring of 45 seen from peer 0 (origin 1), neighbours 1 and 44 (origins 2 and 45). Peer 40
    # (origin 41) is 4 hops from 44; its bit was origin 2's modulo 39 (a near peer, first-hand)
    n = 45
    names = [f"p{i}" for i in range(n)]
    sup = LabelSupport(peer_bit(1), dict(reach_by_name(names, _ring(n), range(1, n + 1), 0)))
    lab = np.array([[S, 10, PB + 3]], dtype=np.int64)
    far = as_words(peer_bit(41), sup.words)[None, :]
    assert sup.refused("p44", lab, far, 14) is None and sup.backdated == 0
    # the same label claimed by origin 2 alone (a neighbour never seen publishing it): refused
    near = as_words(peer_bit(2), sup.words)[None, :]
    assert sup.refused("p44", lab, near, 14) is not None and sup.backdated == 1
    # and before origin 41's stamp can have come 4 hops (scan 11: 2 hops), refused too
    assert sup.refused("p44", lab, far, 11) is not None and sup.backdated == 2


def test_masks_of_fifty_peers_on_the_wire_and_back():
    sup = LabelSupport(peer_bit(50), words=2)
    lab = np.array([[S, 4, PB + 1], [7, 4, PB + 2], [S, 4, PB + 3], [S, 4, PB + 4]],
                   dtype=np.int64)
    sup.own(lab[:1], 4)
    sup.add(lab[2:3], peer_bit(2) | peer_bit(41))
    sup.add(lab[3:], peer_bit(5))
    wire, extra = sup.encode(lab)
    assert wire.min() >= 0 and wire[1, 0] == 7 and extra.shape == (4, 1)
    est = Estimate("s1", 4, _mixture(4), labels=wire, label_masks=extra)
    data = wire_encode(est)
    assert msgpack.unpackb(data)[0] == MASKS_VERSION
    got = wire_decode(data)
    np.testing.assert_array_equal(got.labels, wire)
    back, masks = decode(got.labels, got.label_masks)
    np.testing.assert_array_equal(back, lab)
    assert mask_ints(masks) == [peer_bit(50), 0, peer_bit(2) | peer_bit(41), peer_bit(5)]
    np.testing.assert_array_equal(sup.counts(lab), [1, 0, 2, 1])
    # a receiver ORs them in as they are (unchecked), so counts agree on both sides
    other = LabelSupport(peer_bit(1))
    other.add(back, masks)
    np.testing.assert_array_equal(other.counts(lab), [1, 0, 2, 1])


def test_up_to_39_peers_the_estimate_is_protocol_2_byte_for_byte():
    sup = LabelSupport(peer_bit(3))
    lab = np.array([[S, 4, PB + 1], [S, 4, PB + 2]], dtype=np.int64)
    sup.own(lab, 4)
    sup.add(lab[1:], peer_bit(39))
    wire, extra = sup.encode(lab)
    assert extra is None and wire[1, 0] == (peer_bit(3) | peer_bit(39)) << SUPPORT_SHIFT
    est = Estimate("s1", 4, _mixture(2), labels=wire)
    data = wire_encode(est)
    body = msgpack.unpackb(data)
    assert body[0] == LABELS_VERSION
    # what protocol 2 always was: its fields in order, labels as (n, 3) int64 bytes
    assert body[10] == wire.astype("<i8").tobytes() and len(body) == 12
    got = wire_decode(data)
    assert got.label_masks is None
    np.testing.assert_array_equal(got.labels, wire)


def test_bad_mask_words_are_rejected_with_a_reason():
    lab = np.zeros((2, 3), dtype=np.int64)
    good = wire_encode(Estimate("s1", 4, _mixture(2), labels=lab,
                                label_masks=np.ones((2, 1), dtype=np.int64)))
    body = msgpack.unpackb(good)
    short = list(body)
    short[11] = short[11][:-3]  # not a whole number of words a component
    with pytest.raises(Rejected) as e:
        wire_decode(msgpack.packb(short))
    assert e.value.reason == "shape"
    neg = list(body)
    neg[11] = np.array([[1], [-1]], dtype="<i8").tobytes()
    with pytest.raises(Rejected) as e:
        wire_decode(msgpack.packb(neg))
    assert e.value.reason == "field"
    with pytest.raises(ValueError, match="label_masks"):
        wire_encode(Estimate("s1", 4, _mixture(2), labels=lab,
                             label_masks=np.ones((3, 1), dtype=np.int64)))


def test_a_fresh_own_label_sent_in_a_later_round_is_ours_first_hand():
    # peer 0 of a ring of 45 (origin 1) fuses at scan 3 and sends a fresh own label in round 1;
    # neighbour 1 publishes it at scan 4 and relays it later: peer 0 saw itself publish it by
    # its scan (LabelSupport.sent), so the relay is no backdated label. Before, only the local
    # estimate's labels were recorded (own), and the 50-peer twin refused 172 such relays
    from sensornet.peers.label_support import FRESH_INDEX

    n = 45
    names = [f"p{i}" for i in range(n)]
    reach = dict(reach_by_name(names, _ring(n), range(1, n + 1), 0))
    fresh = np.array([[1, 3, FRESH_INDEX + 2]], dtype=np.int64)
    none = np.zeros((1, 1), dtype=np.int64)
    told, untold = LabelSupport(peer_bit(1), reach), LabelSupport(peer_bit(1), reach)
    told.sent(fresh, 3)
    assert told.refused("p1", fresh, none, 4) is None and told.refused("p1", fresh, none, 9) is None
    assert told.backdated == 0
    assert untold.refused("p1", fresh, none, 4) is None  # p1 publishes it by its scan
    assert untold.refused("p1", fresh, none, 9) is not None and untold.backdated == 1
    # what sent records is first-hand publication only: no mask bit is added
    assert not told.mask_of(fresh).any()


def test_mask_words_beyond_the_limit_are_refused_before_they_are_read():
    """One component's words could fill the message (and widen every label a receiver stores):
    more than ``Limits.max_mask_words`` a component is refused as ``too-many``; at the limit
    it decodes."""
    from sensornet.protocol.codec import DEFAULT_LIMITS
    lab = np.zeros((2, 3), dtype=np.int64)
    cap = DEFAULT_LIMITS.max_mask_words
    at = wire_encode(Estimate("s1", 4, _mixture(2), labels=lab,
                              label_masks=np.ones((2, cap), dtype=np.int64)))
    assert wire_decode(at).label_masks.shape == (2, cap)
    over = wire_encode(Estimate("s1", 4, _mixture(2), labels=lab,
                                label_masks=np.ones((2, cap + 1), dtype=np.int64)))
    with pytest.raises(Rejected) as e:
        wire_decode(over)
    assert e.value.reason == "too-many"
