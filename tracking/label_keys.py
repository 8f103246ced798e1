"""Label rows ``(origin, birth_scan, index)`` (checks, fresh labels, sortable keys, the network
rule's order) and the labelled mixture: the base of :mod:`tracking.labels` (issue 37 split).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from sensornet.tracking.mixture import GaussianMixture

LABEL_COLUMNS = ("origin", "birth_scan", "index")
"""Columns of a label array ``(n, 3)`` int64."""
PUBLISHED_BASE = 1 << 36
"""Index offset of the label an own track takes when it is first published (``(origin, k,
PUBLISHED_BASE + i)``: :class:`tracking.label_confirmation.Publication`), apart from births
and splits (small indices) and a fusion's fresh labels (``peers.labelling.FRESH_BASE``)."""
SHARED_ORIGIN = 0
"""Origin of the labels every peer makes alike (issue 33): a birth at a fixed birth point that
all peers share (seed 000's ``[[birth.paper]]``) is ``(SHARED_ORIGIN, k, i)``, ``i`` its birth
component, at every peer, and stamped ``(SHARED_ORIGIN, k', PUBLISHED_BASE + i)`` at its first
publication (:class:`tracking.label_confirmation.Publication` ``shared``). Peers' own origins
then start at 1, so in the network rule's order a shared label beats an own one of the same
scan: the id most peers already hold wins a tie."""
CELL_BASE = 1 << 34
"""Index offset of a shared label made from a grid cell (:func:`cell_index`): an LMB's
measurement-driven birth is ``(SHARED_ORIGIN, k, CELL_BASE + cell)`` at every peer whose birth
plot falls in that cell, apart from fixed birth components (small indices); below
:data:`PUBLISHED_BASE`, so it is stamped at first publication like any shared birth."""
CELL_BITS = 32
"""Bits of a cell code (:func:`cell_index`), split evenly over the position axes."""
_KEY = np.dtype([("origin", "<i8"), ("birth_scan", "<i8"), ("index", "<i8")])


def as_labels(labels, n: int | None = None, what: str = "labels") -> np.ndarray:
    """``labels`` as a contiguous int64 ``(n, 3)`` array, or ValueError naming ``what``."""
    a = np.asarray(labels)
    if a.size == 0:
        a = a.reshape(0, 3)
    if a.ndim != 2 or a.shape[1] != 3 or (n is not None and a.shape[0] != n):
        want = f"({n}, 3)" if n is not None else "(n, 3)"
        raise ValueError(f"{what} has shape {a.shape}, expected {want}")
    if a.dtype.kind not in "iu":
        raise ValueError(f"{what} has dtype {a.dtype}, expected integers")
    return np.ascontiguousarray(a, dtype=np.int64)


def new_labels(origin: int, k: int, count: int, start: int = 0) -> np.ndarray:
    """Fresh labels ``(origin, k, start + i)`` for ``i < count``: ``(count, 3)`` int64."""
    out = np.empty((count, 3), dtype=np.int64)
    out[:, 0] = origin
    out[:, 1] = k
    out[:, 2] = np.arange(start, start + count)
    return out


def cell_index(points: np.ndarray, size: float) -> np.ndarray:
    """The grid cell of each point ``(n, dz)`` (cells ``size`` wide, edges at multiples of
    ``size`` from the origin) as a label index ``CELL_BASE + code`` ``(n,)`` int64: the cell
    numbers per axis, offset and packed in :data:`CELL_BITS` bits (``CELL_BITS // dz`` each,
    the first axis highest), so every peer computes the same index for the same cell and the
    order of indices is a fixed order of cells. Cells beyond the packed range (2^15 cells from
    the origin per axis in 2-D: 6,500 km at 200 m) are clipped to the edge cell."""
    pts = np.asarray(points, dtype=float)
    if pts.ndim != 2 or not 1 <= pts.shape[1] <= 4:
        raise ValueError(f"points has shape {pts.shape}, expected (n, dz) with 1 <= dz <= 4")
    if not (np.isfinite(size) and size > 0):
        raise ValueError(f"cell size must be a positive finite number, got {size!r}")
    bits = CELL_BITS // pts.shape[1]
    half = 1 << (bits - 1)
    cells = np.clip(np.floor(pts / size), -half, half - 1).astype(np.int64) + half
    shifts = bits * np.arange(pts.shape[1] - 1, -1, -1, dtype=np.int64)
    return CELL_BASE + (cells << shifts).sum(axis=1)


def shared_births(index: np.ndarray, priority: np.ndarray, shared: int, origin: int, k: int,
                  start: int) -> np.ndarray:
    """Labels ``(n, 3)`` of ``n`` births at scan ``k`` that every peer makes alike: ``(shared,
    k, index[i])``, except where two births share an index (two plots in one cell): the one of
    highest ``priority (n,)`` (then the first) keeps it, the others take own labels ``(origin,
    k, start + i)`` (a label stays one track at a peer)."""
    index = np.asarray(index, dtype=np.int64).reshape(-1)
    n = len(index)
    order = np.lexsort((-np.asarray(priority, dtype=float), index))  # stable: ties, first
    first = np.ones(n, dtype=bool)
    first[1:] = index[order[1:]] != index[order[:-1]]
    keep = np.zeros(n, dtype=bool)
    keep[order] = first
    out = new_labels(origin, k, n, start)
    out[keep, 0] = shared
    out[keep, 2] = index[keep]
    return out


def label_keys(labels: np.ndarray) -> np.ndarray:
    """One structured scalar per label row ``(n,)``: comparable, sortable, ``np.isin``-able."""
    return np.ascontiguousarray(labels, dtype=np.int64).view(_KEY).reshape(-1)


KEY_PAIRS = 4096
"""Up to this many (key, key) pairs :func:`keys_isin` compares them all at once; beyond it,
``np.isin``."""


_VOID: dict[int, np.dtype] = {}
"""The unstructured byte dtype of each key size (:func:`_rows`: made once, not per call)."""


def _rows(keys: np.ndarray) -> np.ndarray:
    """Keys ``(n,)`` of one fixed-size dtype as unstructured bytes (equal iff every field is):
    their ``==`` is one C compare, a structured ``==`` a Python call (numpy _promote_fields)."""
    keys = np.ascontiguousarray(keys)
    size = keys.dtype.itemsize
    void = _VOID.get(size)
    if void is None:
        void = _VOID[size] = np.dtype((np.void, size))
    return keys.view(void)


def keys_equal(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a == b`` element-wise for keys of one dtype (e.g. :func:`label_keys`'s): the same
    answer, cheaper."""
    return _rows(a) == _rows(b)


def keys_isin(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``np.isin(a, b)`` for 1-D keys of one dtype (e.g. :func:`label_keys`'s): the same
    answer; few keys every pair compared at once (np.isin on structured keys sorts and compares
    in Python: ~100 us for ten keys), else np.isin itself."""
    if a.size == 0 or b.size == 0:
        return np.zeros(a.shape, dtype=bool)
    if a.size * b.size > KEY_PAIRS or a.dtype != b.dtype or a.ndim != 1 or b.ndim != 1:
        return np.isin(a, b)
    return (_rows(a)[:, None] == _rows(b)[None, :]).any(axis=1)


def keys_find(table: np.ndarray, keys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Where each of ``keys (n,)`` is in ``table (m,)`` (sorted, each once; m > 0): ``(n,)``
    bool found and ``(n,)`` index (meaningful where found, always a valid index), as
    ``np.searchsorted(table, keys).clip(max=m - 1)`` and an equality test of the keys there
    give; few keys every pair compared at once (a structured binary search costs more)."""
    if keys.size * table.size > KEY_PAIRS or keys.dtype != table.dtype:
        pos = np.searchsorted(table, keys).clip(max=table.size - 1)
        return keys_equal(table[pos], keys), pos
    eq = _rows(keys)[:, None] == _rows(table)[None, :]
    return eq.any(axis=1), eq.argmax(axis=1)


def unique_keys(keys: np.ndarray) -> np.ndarray:
    """``np.unique(keys)`` for 1-D keys (e.g. :func:`label_keys`'s): sorted, each once; the
    same array (equal keys are equal bytes), without its Python compare of neighbours."""
    s = np.sort(keys)
    if s.size < 2:
        return s
    r = _rows(s)
    return s[np.concatenate(([True], r[1:] != r[:-1]))]


def replace_labels(labels: np.ndarray, old: np.ndarray, new: np.ndarray) -> np.ndarray:
    """``labels (n, 3)`` with each of the labels ``old (r, 3)`` replaced by its ``new (r, 3)`` on
    every row carrying it (a copy; sorted-key lookup, no loop over rows)."""
    was = label_keys(old)
    if not was.size:
        return labels
    keys = label_keys(labels)
    by = np.argsort(was)
    pos = np.searchsorted(was[by], keys).clip(max=was.size - 1)
    hit = was[by][pos] == keys
    out = labels.copy()
    out[hit] = np.asarray(new)[by][pos[hit]]
    return out


def precedes(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise ``a < b`` for label arrays ``(n, 3)`` in the network rule's order ``(birth_scan,
    origin, index)`` (earliest birth first, then the lowest origin id): ``(n,)`` bool."""
    a = np.asarray(a, dtype=np.int64)[:, [1, 0, 2]]
    b = np.asarray(b, dtype=np.int64)[:, [1, 0, 2]]
    differ = a != b
    first = differ.argmax(axis=1)  # the first column that differs (0 if none does)
    rows = np.arange(len(a))
    return differ.any(axis=1) & (a[rows, first] < b[rows, first])


@dataclass(frozen=True)
class LabelledMixture:
    """A Gaussian mixture with one label per component.

    mixture: the intensity (``n`` components), unchanged by labelling.
    labels:  (n, 3) int64 ``(origin, birth_scan, index)``.
    """

    mixture: GaussianMixture
    labels: np.ndarray

    def __post_init__(self) -> None:
        object.__setattr__(self, "labels", as_labels(self.labels, len(self.mixture)))

    @classmethod
    def empty(cls, dim: int) -> LabelledMixture:
        return cls(GaussianMixture.empty(dim), np.zeros((0, 3), dtype=np.int64))

    def __len__(self) -> int:
        return len(self.mixture)

    def select(self, index: np.ndarray) -> LabelledMixture:
        """Components (and labels) picked by a boolean mask or an index array."""
        index = np.asarray(index)
        return LabelledMixture(self.mixture.select(index), self.labels[index])


__all__ = ["CELL_BASE", "CELL_BITS", "LABEL_COLUMNS", "PUBLISHED_BASE", "SHARED_ORIGIN",
           "LabelledMixture", "as_labels", "cell_index", "keys_equal", "keys_find", "keys_isin",
           "label_keys",
           "new_labels", "precedes", "shared_births", "unique_keys"]
