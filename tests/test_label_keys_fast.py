"""tracking.label_keys.keys_isin / keys_equal / unique_keys / keys_find give np.isin / == /
np.unique / searchsorted's answers on label keys to the bit, both ways (all pairs at once,
NumPy's own beyond KEY_PAIRS), with repeats, negatives and empty arrays."""

from __future__ import annotations

import numpy as np
import pytest
from sensornet.tracking import label_keys as lk
from sensornet.tracking.label_keys import (
    keys_equal,
    keys_find,
    keys_isin,
    label_keys,
    unique_keys,
)


def _labels(rng, n):
    return np.column_stack((rng.integers(-2, 3, n), rng.integers(-3, 4, n),
                            rng.choice([0, 1, 1 << 36, -(1 << 40), 5], n)))


@pytest.mark.parametrize("pairs", [0, 4096])
def test_the_fast_key_ops_answer_as_numpy(pairs, monkeypatch):
    monkeypatch.setattr(lk, "KEY_PAIRS", pairs)
    rng = np.random.default_rng(33)
    for _ in range(300):
        a = label_keys(_labels(rng, int(rng.integers(0, 30))))
        b = label_keys(_labels(rng, int(rng.integers(0, 30))))
        np.testing.assert_array_equal(keys_isin(a, b), np.isin(a, b))
        np.testing.assert_array_equal(keys_isin(a[::2], b[1:]), np.isin(a[::2], b[1:]))
        u = unique_keys(a)
        assert u.dtype == np.unique(a).dtype and u.tobytes() == np.unique(a).tobytes()
        c = a[rng.permutation(len(a))]
        np.testing.assert_array_equal(keys_equal(a, c), a == c)
        if len(a) > 1:
            np.testing.assert_array_equal(keys_equal(a[1:], a[:-1]), a[1:] == a[:-1])
        if len(u):  # a sorted table of unique keys: found where searchsorted finds them
            hit, pos = keys_find(u, b)
            want = np.searchsorted(u, b).clip(max=len(u) - 1)
            np.testing.assert_array_equal(hit, u[want] == b)
            np.testing.assert_array_equal(pos[hit], want[hit])
            assert ((pos >= 0) & (pos < len(u))).all()
