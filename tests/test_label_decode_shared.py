"""An estimate's labels decode once for every co-hosted receiver (issue 33, the 50-peer LMB
twin's CPU; peers.label_support.decode): by their bytes, into read-only arrays (a receiver
cannot change its neighbours' rows), the caller's array free to change after."""

from __future__ import annotations

import numpy as np
import pytest
from sensornet.peers import label_support
from sensornet.peers.label_support import decode
from sensornet.tracking.label_keys import PUBLISHED_BASE as PB
from sensornet.tracking.label_keys import SHARED_ORIGIN as S


def test_the_same_rows_decode_once_read_only_and_by_their_bytes():
    lab = np.array([[S | (5 << label_support.SUPPORT_SHIFT), 3, PB], [2, 3, 7]], dtype=np.int64)
    a, ma = decode(lab)
    b, mb = decode(lab.copy())  # another array, the same bytes: the same answer, kept
    assert a is b and ma is mb
    assert not a.flags.writeable and not ma.flags.writeable
    np.testing.assert_array_equal(a, [[S, 3, PB], [2, 3, 7]])
    np.testing.assert_array_equal(ma, [[5], [0]])
    lab[0, 1] = 4  # the caller's array changed: other bytes, decoded anew
    c, _ = decode(lab)
    assert c[0, 1] == 4 and a[0, 1] == 3
    extra = np.array([[1], [0]], dtype=np.int64)  # words 1..: part of the key
    d, md = decode(lab, extra)
    assert d is not c and md.shape == (2, 2) and md[0, 1] == 1
    with pytest.raises(ValueError):
        a[0, 0] = 1  # a receiver cannot change its neighbours' rows
