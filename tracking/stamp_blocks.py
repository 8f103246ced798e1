"""One reported id for a target's birth stamps: shared stamps shown by block (issue 33,
docs/labelled-tracking.md, "One id for a target's first stamps").

On 20 peers one target is stamped at its first publication ``(0, s, c)`` (``c``: its 200 m
birth cell, :func:`tracking.label_keys.cell_index`) by several peers: some in a neighbouring
cell (plot noise across an edge), some a scan later (a stamp moved for want of corroboration,
``peers.labelling.corroborated``). The network rule picks one winner, but labels and their
holder masks (``peers.label_support``) travel one hop a scan, so for a few scans a peer's row of
the target changes label, sometimes back and forth: each change is a second track of the target
in OSPA(2) ("dup"). Which stamp wins is known only once every stamp has arrived, so no rule can
name the winner early; but the id a peer *reports* need not tell the stamps apart.

:func:`block_ids` reports a shared label ``(0, s, i)`` as the class it falls in: its scan
rounded down to a multiple of ``block`` and, for a cell stamp, each axis' cell number rounded
down to a multiple of ``block`` (cells ``block`` x 200 m), flagged by :data:`BLOCK_FLAG` in the
index so it never equals a label. It is a fixed function of the label alone: every peer
reports the same id for the same label whatever stamps have reached it, so confirmed ids and
their agreement stay the network rule's (a settled label maps to one id), and a change between
two stamps of one block is not seen at all. Two stamps across a block edge still change (one
adjacent pair in ``block`` per axis, scan or cell); two rows of one peer and scan that would
show one id both show their labels (two targets never share an id). Extraction output only:
the fused density, its labels and everything sent to neighbours are unchanged.
"""

from __future__ import annotations

import numpy as np
from sensornet.tracking.label_keys import (
    CELL_BASE,
    CELL_BITS,
    PUBLISHED_BASE,
    SHARED_ORIGIN,
    as_labels,
)

BLOCK_FLAG = 1 << 35
"""Index bit of a reported block id: above every cell index (``CELL_BASE + code < 2^35``) and
below :data:`tracking.label_keys.PUBLISHED_BASE`, so a block id is never a label."""


def block_ids(ids: np.ndarray, block: int, axes: int = 2) -> np.ndarray:
    """``(p, 3)`` the ids to report for rows of one scan with labels ``ids (p, 3)`` (module
    docstring): shared labels by ``block`` scans and ``block`` x ``block`` cells (``axes``:
    the position axes the birth cells were made of), others unchanged; ``block`` 1: scans and
    cells as they are, still flagged; rows that would share an id keep their labels."""
    ids = as_labels(ids, what="ids")
    if int(block) != block or block < 1:
        raise ValueError(f"block must be a whole number of scans and cells >= 1, got {block}")
    if not 1 <= axes <= 4:
        raise ValueError(f"axes must be 1 to 4, got {axes}")
    out = ids.copy()
    shared = (ids[:, 0] == SHARED_ORIGIN) & (ids[:, 2] >= 0)
    if not shared.any():
        return out
    pub = ids[:, 2] >= PUBLISHED_BASE
    idx = ids[:, 2] - PUBLISHED_BASE * pub
    cell = shared & (idx >= CELL_BASE) & (idx < CELL_BASE + (1 << CELL_BITS))
    bits = CELL_BITS // axes
    shifts = bits * np.arange(axes, dtype=np.int64)
    per = ((idx - CELL_BASE)[:, None] >> shifts) & ((1 << bits) - 1)  # cell number per axis
    code = ((per // block * block) << shifts).sum(axis=1)
    out[shared, 1] = ids[shared, 1] // block * block
    out[:, 2] = np.where(cell, PUBLISHED_BASE * pub + CELL_BASE + code, idx + PUBLISHED_BASE * pub)
    out[shared, 2] += BLOCK_FLAG
    out[~shared] = ids[~shared]
    _, inv, cnt = np.unique(out, axis=0, return_inverse=True, return_counts=True)
    clash = cnt[inv.reshape(-1)] > 1
    out[clash] = ids[clash]
    return out


__all__ = ["BLOCK_FLAG", "block_ids"]
