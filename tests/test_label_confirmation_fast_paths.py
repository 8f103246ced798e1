"""The usual-scan fast paths of tracking.label_confirmation give what the general paths give.

:meth:`Publication.stamp`'s memory when nothing is stamped and every published row's label is
known (:meth:`Publication._keep_known`), :meth:`Confirmation.observe` when the labels are last
scan's, ``_present_above`` when each label is on one row, and :meth:`Confirmation.status_rows`
of the labels just observed (their rows' counts kept): each against the general path on
random label sequences that hit both (labels kept, dropped, re-published, duplicated rows)."""

from __future__ import annotations

import numpy as np
from sensornet.tracking.label_confirmation import Confirmation, Publication, _present_above
from sensornet.tracking.label_keys import PUBLISHED_BASE, LabelledMixture, label_keys
from sensornet.tracking.mixture import GaussianMixture


class _General(Publication):
    """A :class:`Publication` that always takes the general path (no table rows given)."""

    def _find(self, keys):
        return (*super()._find(keys)[:2], None)


class _GeneralConfirmation(Confirmation):
    """:meth:`Confirmation.observe` as it was: a lookup of every present label."""

    def observe(self, lm, k=None):
        from sensornet.tracking.label_keys import keys_find
        present, above = _present_above(lm.labels, lm.mixture.weights, self.threshold)
        counts = above.astype(np.int64)
        if self._keys.size and present.size:
            seen, pos = keys_find(self._keys, present)
            counts[seen] += self._counts[pos[seen]]
        self._keys, self._counts, self._k = present, counts, k


def _scan(rng, pool: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    rows = rng.integers(0, len(pool), n)  # duplicates: a label on several rows
    return pool[rows].copy(), rng.random(n) * 1.2


def _pool(rng, size: int) -> np.ndarray:
    origin = rng.integers(0, 3, size)  # 0 shared, 1 own, 2 a neighbour
    index = rng.integers(0, 4, size) + np.where(rng.random(size) < 0.5, PUBLISHED_BASE, 0)
    return np.column_stack((origin, rng.integers(0, 5, size), index)).astype(np.int64)


def test_stamp_memory_equals_the_general_path():
    rng = np.random.default_rng(7)
    fast_hits = 0
    for _ in range(60):
        pool = _pool(rng, int(rng.integers(1, 12)))
        a, b = Publication(1, shared=0), _General(1, shared=0)
        for k in range(1, 25):
            labels, w = _scan(rng, pool, int(rng.integers(0, 10)))
            if rng.random() < 0.3:  # the same rows again, re-weighted
                w = rng.random(len(labels)) * 1.2
            before = a._keys.size
            la = a.stamp(labels, w, 0.5, k)
            lb = b.stamp(labels, w, 0.5, k)
            fast_hits += before > 0 and not a.stamped.size
            np.testing.assert_array_equal(la, lb)
            np.testing.assert_array_equal(a.stamped, b.stamped)
            assert a._keys.dtype == b._keys.dtype and a._last.dtype == b._last.dtype
            np.testing.assert_array_equal(a._keys, b._keys)
            np.testing.assert_array_equal(a._last, b._last)
            if rng.random() < 0.2:
                adopted = pool[rng.integers(0, len(pool), 2)]
                a.adopt(adopted)
                b.adopt(adopted)
    assert fast_hits > 100  # the fast path was taken often


def test_observe_and_present_above_equal_the_general_path():
    rng = np.random.default_rng(11)
    same = 0
    for _ in range(60):
        pool = _pool(rng, int(rng.integers(1, 10)))
        a, b = Confirmation(3, settle=1), _GeneralConfirmation(3, settle=1)
        labels, w = _scan(rng, pool, int(rng.integers(1, 8)))
        for k in range(1, 20):
            if rng.random() < 0.5:  # a new set of rows (else the same labels again)
                labels, w = _scan(rng, pool, int(rng.integers(0, 8)))
            else:
                w = rng.random(len(labels)) * 1.2
                same += 1
            mix = GaussianMixture(w, np.zeros((len(w), 2)), np.tile(np.eye(2), (len(w), 1, 1)))
            lm = LabelledMixture(mix, labels)
            a.observe(lm, k)
            b.observe(lm, k)
            np.testing.assert_array_equal(a._keys, b._keys)
            np.testing.assert_array_equal(a._counts, b._counts)
            np.testing.assert_array_equal(a.status(pool), b.status(pool))
            rows = rng.integers(0, max(1, len(labels)), rng.integers(0, 5)) if len(labels) \
                else np.zeros(0, dtype=np.intp)
            for arr in (lm.labels, lm.labels.copy()):  # the rows kept at observe; a lookup
                np.testing.assert_array_equal(a.status_rows(arr, rows), b.status(arr[rows]))
                assert a.status_rows(arr, rows).dtype == np.int8
            keys, above = _present_above(labels, w, 0.5)
            ref, inv = np.unique(label_keys(labels), return_inverse=True)
            heavy = np.zeros(len(ref), dtype=bool)
            np.logical_or.at(heavy, inv.reshape(-1), w > 0.5)
            np.testing.assert_array_equal(keys, ref)
            np.testing.assert_array_equal(above, heavy)
    assert same > 100
