"""peers.label_support.LabelSupport's in-place path (every label added already known: its
mask OR-ed where it is) keeps what the full merge it skips would keep, to the bit, over random
sequences of adds, own stamps and prunes; mask_of's row-wise lookups (all pairs at once, or a
binary search) as the structured one."""

from __future__ import annotations

import numpy as np
import pytest
from sensornet.peers import label_support
from sensornet.peers.label_support import SHARED_ORIGIN, LabelSupport
from sensornet.tracking.label_keys import label_keys


def merged_add(s: LabelSupport, labels: np.ndarray, masks) -> None:
    """LabelSupport.add as it was before the in-place path: always the full merge."""
    lab = np.asarray(labels, dtype=np.int64).reshape(-1, 3)
    m = np.broadcast_to(np.asarray(masks, dtype=np.int64), (len(lab),))
    ok = (lab[:, 0] == SHARED_ORIGIN) & (m != 0)
    if not ok.any():
        return
    keys = np.concatenate([s.keys, label_keys(lab[ok])])
    allm = np.concatenate([s.masks, m[ok]])
    scans = np.concatenate([s.scans, lab[ok, 1]])
    order = np.argsort(keys, kind="stable")
    keys, allm, scans = keys[order], allm[order], scans[order]
    first = np.ones(len(keys), dtype=bool)
    first[1:] = keys[1:] != keys[:-1]
    starts = np.flatnonzero(first)
    s.keys, s.scans = keys[starts], scans[starts]
    s.masks = np.bitwise_or.reduceat(allm, starts)


@pytest.mark.parametrize("pairs", [0, 4096])  # lookups by binary search / all pairs at once
def test_in_place_adds_keep_what_the_merge_keeps(pairs, monkeypatch):
    monkeypatch.setattr(label_support, "FIND_PAIRS", pairs)
    rng = np.random.default_rng(38)
    fast_hits = 0
    for _ in range(40):
        a, b = LabelSupport(4), LabelSupport(4)
        b.masks = np.zeros(0, dtype=np.int64)  # the reference keeps one int64 a label
        for k in range(60):
            n = int(rng.integers(0, 12))
            lab = np.column_stack((rng.choice([0, 0, 0, 3], n), rng.integers(k - 5, k + 1, n),
                                   (1 << 36) + rng.integers(0, 8, n)))
            if rng.random() < 0.2:  # only labels known already: the in-place path
                lab = np.asarray(a.keys.view(np.int64).reshape(-1, 3))[:n]
                fast_hits += len(lab) > 0
            r = rng.random()
            masks = (rng.integers(0, 1 << 12, len(lab)) if r < 0.7 else 1 << 5 if r < 0.85
                     else np.array([1 << 6]))  # one mask for all rows, as a scalar or (1,)
            if rng.random() < 0.3:
                a.own(lab, k)
                merged_add(b, lab[lab[:, 1] == k], 4)
            else:
                a.add(lab, masks)
                merged_add(b, lab, masks)
            if rng.random() < 0.1:
                a.prune(k, 8)
                b.prune(k, 8)
            assert a.keys.tobytes() == b.keys.tobytes()
            assert a.masks.shape[1] == 1  # every bit below 39: one word
            np.testing.assert_array_equal(a.masks[:, 0], b.masks)
            np.testing.assert_array_equal(a.scans, b.scans)
            probe = np.concatenate([lab, np.array([[0, k, 5], [2, k, 1 << 36]])])
            want = np.zeros(len(probe), dtype=np.int64)
            if len(b.keys):
                pos = np.searchsorted(b.keys, label_keys(probe)).clip(max=len(b.keys) - 1)
                hit = b.keys[pos] == label_keys(probe)
                want[hit] = b.masks[pos[hit]]
            np.testing.assert_array_equal(a.mask_of(probe)[:, 0], want)
    assert fast_hits > 100
