"""Stamps that stay young while uncorroborated (issue 33, docs/labelled-tracking.md,
"Stamps corroborated within a few scans").

:func:`peers.labelling.corroborated` moves an own label stamped at its first publication at
scan ``k`` to ``(o, k + 1, i)`` when no neighbour's track was paired with its fused component
(uncorroborated). Two cases on 20 peers' training runs kept an early label all the same, and it
replaced a target's id at most peers hop by hop (one dup in OSPA(2) a peer):

* a clutter track at a birth point published two scans before the target (``k - 2``, ``k -
  1``), no neighbour holding it: moved once, to ``k - 1``, it was still the earliest label
  when the target appeared (training run 107);
* a clutter track moved at its first publication went dark for two scans and came back on a
  new target's track (a merge keeps the heavier label), its label of the target's birth scan
  and a lower birth index than the target's own (training run 114).

:class:`MovingStamps` remembers the labels moved for want of corroboration. One is offered to
the rule again at the next scan, so it moves every scan it stays uncorroborated, up to
``scans`` scans after its first stamp (its scan is then its first corroborated one, the scan
most peers stamp the target, or its first plus ``scans``); and one that goes dark (unpublished)
within ``scans`` scans of its first stamp is stamped anew when it is published again
(:meth:`MovingStamps.returning`: ``(origin, k, RESTAMP_BASE + j)``, a later label, so it
cannot take over a track the network already names). Arrays: labels ``(n, 3)`` int64
``(origin, birth_scan, index)``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from sensornet.tracking.labels import PUBLISHED_BASE, label_keys, new_labels

RESTAMP_BASE = PUBLISHED_BASE + (1 << 30)
"""Index offset of the label a moved stamp takes when it returns after a dark scan, apart
from first-publication stamps (``PUBLISHED_BASE + i``, ``i`` small or a birth component)."""


def _find(keys: np.ndarray, table: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Whether each of ``keys`` is in ``table`` (label keys) and its row there."""
    if not len(table):
        return np.zeros(len(keys), dtype=bool), np.zeros(len(keys), dtype=np.int64)
    by = np.argsort(table)
    pos = np.searchsorted(table[by], keys).clip(max=len(table) - 1)
    hit = table[by][pos] == keys
    return hit, by[pos]


@dataclass
class MovingStamps:
    """The own labels moved a scan later for want of corroboration, each with the scan it was
    first stamped and whether it went dark while young: :meth:`note` after each relabel,
    :meth:`returning` and :meth:`offer` at each step. ``scans``: scans after its first stamp
    in which an uncorroborated label moves again, and in which going dark makes it be
    stamped anew on return (1: only the move at its first publication, the rule of
    af0ecdb)."""

    scans: int = 1
    labels: np.ndarray = field(default_factory=lambda: np.zeros((0, 3), dtype=np.int64))
    """``(m, 3)`` the remembered labels (after their last move)."""
    first: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    """``(m,)`` the scan each was first stamped (before any move)."""
    dark: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    """``(m,)`` whether it went unpublished within :attr:`scans` scans of its first stamp."""
    moved_at: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    """``(m,)`` the scan of its last move."""

    def __post_init__(self) -> None:
        if not isinstance(self.scans, int | np.integer) or self.scans < 1:
            raise ValueError(f"MovingStamps.scans must be an integer >= 1, got {self.scans!r}")

    def note(self, before: np.ndarray, after: np.ndarray, k: int) -> None:
        """Remember the rows of ``before (n, 3)`` that a move at scan ``k`` changed into
        ``after (n, 3)`` (the own labels before and after :func:`peers.labelling.take_moves`);
        a label moved before keeps the scan of its first stamp."""
        diff = (before != after).any(axis=1)
        if not diff.any() or self.scans == 1:
            return
        old_keys, idx = np.unique(label_keys(before[diff]), return_index=True)
        moved = after[diff][idx]
        first = before[diff][idx, 1].astype(np.int64)
        seen, row = _find(old_keys, label_keys(self.labels))
        first[seen] = self.first[row[seen]]
        keep = np.ones(len(self.labels), dtype=bool)
        keep[row[seen]] = False
        self.labels = np.concatenate([self.labels[keep], moved])
        self.first = np.concatenate([self.first[keep], first])
        self.dark = np.concatenate([self.dark[keep], np.zeros(len(moved), dtype=bool)])
        self.moved_at = np.concatenate([self.moved_at[keep], np.full(len(moved), int(k))])

    def returning(self, labels: np.ndarray, published: np.ndarray, origin: int, k: int
                  ) -> tuple[np.ndarray, np.ndarray]:
        """A step's own ``labels (n, 3)`` (``published (n,)``: the rows above the publication
        threshold at scan ``k``) with each remembered label that went dark while young and is
        published again stamped anew, ``(origin, k, RESTAMP_BASE + j)`` on every row carrying
        it; and the new labels ``(r, 3)``. Forgets labels no row carries, and those past
        :attr:`scans` scans that did not go dark."""
        if not len(self.labels):
            return labels, labels[:0]
        keys = label_keys(labels)
        mine = label_keys(self.labels)
        present = np.isin(mine, keys)
        on = np.isin(mine, keys[published])
        young = k - self.first <= self.scans
        dark = self.dark | (young & present & ~on)  # a new array: a failed step restores
        back = dark & on
        keep = present & ~back & (young | dark)
        out = labels
        new = labels[:0]
        if back.any():
            old = mine[back]
            new = new_labels(origin, k, len(old), RESTAMP_BASE)
            hit, row = _find(keys, old)
            out = labels.copy()
            out[hit] = new[row[hit]]
        self.labels, self.first = self.labels[keep], self.first[keep]
        self.dark, self.moved_at = dark[keep], self.moved_at[keep]
        return out, new

    def offer(self, k: int, present: np.ndarray) -> np.ndarray:
        """``(m, 3)`` the labels that may move again at scan ``k``: moved at scan ``k - 1``
        (now of scan ``k``), first stamped less than :attr:`scans` scans before ``k`` and among
        ``present (p, 3)`` (the own labels published this scan)."""
        if not len(self.labels) or not len(present):
            return self.labels[:0]
        ok = ((self.moved_at == k - 1) & (self.labels[:, 1] == k)
              & (k - self.first < self.scans)
              & np.isin(label_keys(self.labels), label_keys(np.asarray(present))))
        return self.labels[ok]


__all__ = ["RESTAMP_BASE", "MovingStamps"]
