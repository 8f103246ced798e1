"""The world's scans of a scan bundle decoded together for the live view (issue 38): at 50
peers the view hears ~50 scans a scan in a few bundles, and decoding each alone
(:func:`protocol.codec.decode`) cost ~18 us a scan, most of it per-call NumPy.

:func:`scans_together` makes the checks of :func:`protocol.codec_messages._decode_scan` with
each header read alone and every scan's points (and ages) converted and checked finite in one
NumPy call; when any check fails it gives None and the caller decodes each scan alone, which
refuses exactly the bad ones (and counts them). The codec's decoder stays the reference.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from sensornet.protocol.codec import DEFAULT_LIMITS, TRACKS_VERSION, Limits, Rejected
from sensornet.protocol.codec_format import _F8, read_header
from sensornet.protocol.messages import Scan

_INDEX_END = 1 << 53
"""Scan indices and sequence numbers are below this (as ``codec_format._index`` checks)."""


def scans_together(payloads: Sequence[bytes], limits: Limits = DEFAULT_LIMITS) -> list[Scan] | None:
    """Scan messages (protocol 1 or 2, mixed) decoded together, each the :class:`Scan`
    :func:`protocol.codec.decode` gives of it (the same values, dtypes and shapes); None when
    any payload is not a scan or fails one of the decoder's checks (header, points and ages
    bytes, row count, name, index, sequence, finite send time, finite points and ages)."""
    heads = []
    try:
        for p in payloads:
            version, kind, body = read_header(p, limits)
            if kind != "S":
                return None
            x, s, k, q, ts = body["x"], body["s"], body["k"], body["q"], body["ts"]
            if type(x) is not bytes or len(x) % 16 or len(x) // 16 > limits.max_measurements:
                return None
            n = len(x) // 16
            a = None
            if version == TRACKS_VERSION:  # each plot's age: one float64 per row of "x"
                a = body["a"]
                if type(a) is not bytes or len(a) != 8 * n:
                    return None
            if type(s) is not str or not 0 < len(s) <= limits.max_name:
                return None
            if type(k) is not int or not 0 <= k < _INDEX_END:
                return None
            if type(q) is not int or not 0 <= q < _INDEX_END:
                return None
            if type(ts) is int:
                ts = float(ts)
            if type(ts) is not float or not math.isfinite(ts):
                return None
            heads.append((n, x, a, s, k, q, ts))
    except Rejected:
        return None
    if not heads:
        return []
    total = sum(h[0] for h in heads)
    z = np.frombuffer(b"".join(h[1] for h in heads), dtype=_F8).reshape(total, 2).astype(float)
    aged = [h[2] for h in heads if h[2] is not None]
    ages = np.frombuffer(b"".join(aged), dtype=_F8).astype(float) if aged else None
    if not np.isfinite(z).all() or (ages is not None and not np.isfinite(ages).all()):
        return None
    out, i, j = [], 0, 0
    for n, _, a, s, k, q, ts in heads:
        out.append(Scan(sensor=s, k=k, z=z[i:i + n], seq=q, send_time=ts,
                        ages=None if a is None else ages[j:j + n]))
        i += n
        j += 0 if a is None else n
    return out
