"""Track confirmation and first publication of labels (:class:`Confirmation`,
:class:`Publication`): when a label is a confirmed track, and what it means on the network.

Split from :mod:`tracking.labels` (issue 37), whose docstring gives the rules.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from sensornet.tracking.label_keys import (
    _KEY,
    PUBLISHED_BASE,
    LabelledMixture,
    as_labels,
    keys_equal,
    keys_find,
    keys_isin,
    label_keys,
    new_labels,
    unique_keys,
)


@dataclass
class Confirmation:
    """Track confirmation: a label is confirmed once a component carrying it weighed more than
    ``threshold`` in ``scans`` :meth:`observe` calls (one per scan, not necessarily
    consecutive: a missed detection, which cuts a PHD weight to ``(1 - Pd) w``, does not undo
    it) and its ``birth_scan`` is at least ``settle`` scans before the scan observed last. A
    label is forgotten (its count restarts) once no component of the mixture carries it.

    ``settle`` is for networks (issue 33): the network rule (:func:`adopt_labels`) lets the
    earliest label of a target win, and a label spreads one hop per scan, so a label a peer
    holds can still be beaten by an earlier one on its way. A label born (first published,
    :class:`Publication`) at scan ``b`` can only be beaten by one published at ``b' <= b``,
    which has reached every peer within ``e`` hops by scan ``b' + e - 1``; with ``settle`` the
    peer's eccentricity in hops, a confirmed id is one no later arrival replaces (while the
    label spreads unhindered). The price is latency: a track is tentative for
    ``max(scans, settle - (k_first - b))`` scans after it appears at ``k_first``."""

    scans: int = 3
    threshold: float = 0.5
    settle: int = 0
    """Scans a label must be old (the scan observed minus its ``birth_scan``) to be confirmed;
    0: no such wait (a single filter, or labels that never change)."""
    _keys: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=_KEY), init=False,
                              repr=False)
    """Sorted keys of the labels in the mixture at the last scan."""
    _counts: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64),
                                init=False, repr=False)
    """Their counts of scans above the threshold."""
    _k: int | None = field(default=None, init=False, repr=False)
    """The scan of the last :meth:`observe` (None: not given)."""
    _seen: tuple | None = field(default=None, init=False, repr=False, compare=False)
    """``(labels, each row's count)`` of the last :meth:`observe`: :meth:`status_rows` of
    those very labels without a lookup."""

    def __post_init__(self) -> None:
        if self.scans < 1:
            raise ValueError(f"Confirmation.scans must be at least 1, got {self.scans}")
        if self.settle < 0:
            raise ValueError(f"Confirmation.settle must be at least 0, got {self.settle}")

    def observe(self, lm: LabelledMixture, k: int | None = None) -> None:
        """Count scan ``k``: every label with a component above ``threshold`` goes up by one;
        labels no longer in the mixture are dropped. ``k`` is needed when ``settle > 0``."""
        if self.settle and k is None:
            raise ValueError("Confirmation with settle > 0 needs the scan k of each observe")
        self._k = None if k is None else int(k)
        present, above, at = _present_rows(lm.labels, lm.mixture.weights, self.threshold)
        counts = above.astype(np.int64)
        if self._keys.size and present.size:
            if present.size == self._keys.size and keys_equal(present, self._keys).all():
                counts += self._counts  # the same labels as last scan (the usual scan)
            else:
                seen, pos = keys_find(self._keys, present)
                counts[seen] += self._counts[pos[seen]]
        self._keys, self._counts = present, counts
        self._seen = (lm.labels, counts[at])

    def count(self, labels: np.ndarray) -> np.ndarray:
        """Scans above the threshold so far, per label row (0 if unknown): ``(n,)``."""
        return self._count(label_keys(as_labels(labels)))

    def _count(self, keys: np.ndarray) -> np.ndarray:
        """:meth:`count` of the labels' keys ``(n,)``."""
        if not self._keys.size:
            return np.zeros(keys.size, dtype=np.int64)
        hit, pos = keys_find(self._keys, keys)
        return np.where(hit, self._counts[pos], 0)

    def status_rows(self, labels: np.ndarray, rows: np.ndarray) -> np.ndarray:
        """:meth:`status` of ``labels[rows]``; of the labels last observed (the very array: a
        track extraction right after its :meth:`observe`) from their rows' counts kept then,
        not a lookup of their keys."""
        seen = self._seen
        if seen is None or seen[0] is not labels:
            return self.status(labels[rows])
        ok = seen[1][rows] >= self.scans
        if self.settle and self._k is not None:
            ok &= self._k - labels[rows, 1] >= self.settle
        return ok.astype(np.int8)

    def status(self, labels: np.ndarray) -> np.ndarray:
        """``(n,)`` int8: 1 confirmed, 0 tentative (the ``Tracks.status`` codes)."""
        labels = as_labels(labels)
        ok = self._count(label_keys(labels)) >= self.scans
        if self.settle and self._k is not None:
            ok &= self._k - labels[:, 1] >= self.settle
        return ok.astype(np.int8)


def _present_above(labels: np.ndarray, weights: np.ndarray, threshold: float
                   ) -> tuple[np.ndarray, np.ndarray]:
    """The labels' keys, sorted and each once (``unique_keys(label_keys(labels))``), and for
    each whether a row carrying it weighs more than ``threshold`` (``np.isin`` of those keys in
    the heavy rows' keys): one column lexsort and a segment ``or``, not a structured sort and a
    pairwise compare."""
    return _present_rows(labels, weights, threshold)[:2]


def _present_rows(labels: np.ndarray, weights: np.ndarray, threshold: float
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`_present_above` and each row's place among the keys ``(n,)``."""
    keys = label_keys(labels)
    if not keys.size:
        return keys, np.zeros(0, dtype=bool), np.zeros(0, dtype=np.intp)
    order = np.lexsort((labels[:, 2], labels[:, 1], labels[:, 0]))
    s = keys[order]
    heavy = weights[order] > threshold
    dup = keys_equal(s[1:], s[:-1])
    at = np.empty(len(s), dtype=np.intp)
    if not dup.any():  # each label on one row (the usual mixture): its own row's test
        at[order] = np.arange(len(s))
        return s, heavy, at
    first = np.concatenate(([True], ~dup))
    starts = first.nonzero()[0]
    at[order] = np.cumsum(first) - 1
    return s[starts], np.logical_or.reduceat(heavy, starts), at


def stamp_shared(labels: np.ndarray, keys: np.ndarray, alike: np.ndarray, new: np.ndarray,
                 k: int) -> np.ndarray:
    """Stamp the shared births ``alike (n,)`` of ``labels (n, 3)`` (in place) ``(shared, k,
    PUBLISHED_BASE + i)`` at their first publication at scan ``k``, one old label per stamp
    (the earliest birth) and none that a label not stamped now (``~new``; ``keys`` the rows'
    :func:`label_keys`) holds; returns the rows stamped so (the others need an own stamp).
    :class:`Publication` (GM-PHD peers) and ``peers.lmb_estimator`` (LMB peers) share it."""
    rows = np.flatnonzero(alike)
    birth = labels[rows, 1]
    stamp = labels[rows].copy()
    stamp[:, 1] = k
    stamp[:, 2] += PUBLISHED_BASE
    by = np.lexsort((birth, stamp[:, 2]))  # per stamp, the earliest birth first
    start = np.ones(len(by), dtype=bool)
    start[1:] = stamp[by[1:], 2] != stamp[by[:-1], 2]
    winner = birth[by][np.flatnonzero(start)][np.cumsum(start) - 1]
    ok = np.zeros(len(rows), dtype=bool)
    ok[by] = birth[by] == winner
    ok &= ~keys_isin(label_keys(stamp), keys[~new])
    labels[rows[ok]] = stamp[ok]
    out = np.zeros(len(labels), dtype=bool)
    out[rows[ok]] = True
    return out


def _unique_first(labels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``np.unique(label_keys(labels), return_index=True)`` (sorted keys, each once, and the
    row of its first occurrence), by a stable lexsort of the columns and a byte compare of
    neighbours instead of NumPy's Python compare of structured keys."""
    keys = label_keys(labels)
    if not keys.size:
        return keys, np.zeros(0, dtype=np.intp)
    order = np.lexsort((labels[:, 2], labels[:, 1], labels[:, 0]))
    s = keys[order]
    first = np.concatenate(([True], ~keys_equal(s[1:], s[:-1])))
    return s[first], order[first]


REPUBLISH_GAP = 3
"""Looks a published label may stay unpublished at a peer and keep its stamp
(:class:`Publication`); longer, and it is stamped anew when it returns. A look is a scan, or a
rotation of a rotating radar whose plots are spread over the scans (``Publication.revisit``)."""


@dataclass
class Publication:
    """First publication (issue 33): what a peer's labels mean on the network.

    Each label whose components include one heavier than the publication threshold is
    published; :meth:`stamp` gives it ``(origin, k, PUBLISHED_BASE + i)`` (on every component
    carrying it, in the order of the old labels) when it is an own label (``origin``, index
    below :data:`PUBLISHED_BASE`) never published before, or any label returning after more
    than ``gap`` scans unpublished. So the network rule's "earliest birth" means "earliest on
    the network" (the LMB peers' rule, ``peers.lmb_estimator``), and

    * a GM-PHD birth component that lingered light cannot beat an id a neighbour already
      published;
    * a label that went dark but lingered light (a clutter track at a birth point, a track
      lost for a while) cannot take a target over later with its old, early stamp (a case
      traced in docs/labelled-tracking.md: such a label merged into a target's track scans
      later and replaced the target's confirmed id at 15 of 20 peers).

    A label the network gave us (:meth:`adopt`) counts as published. ``gap`` is chosen on
    training runs (docs/labelled-tracking.md); a miss or two at Pd 0.9 stays under it, and if
    the network still carries the old id the fusion gives it back (the new stamp is later)."""

    origin: int
    gap: int | None = REPUBLISH_GAP
    """None: a label once published keeps its stamp while any component carries it."""
    revisit: int = 1
    """Scans between two looks of the sensor at a target (a rotating radar's rotation in
    scans, rounded up; 1: every scan sees every target). A label returns only at a look, so
    the gap is counted in looks: more than ``(gap + 1) * revisit`` scans since it was last
    published (with ``revisit`` 1 scans, a gap of 3 meant 6 s at a 2 s tick, less than one
    rotation of a 10 s radar: every missed plot re-stamped its track, issue 34)."""
    shared: int | None = None
    """The origin of births every peer labels alike (:data:`tracking.label_keys.SHARED_ORIGIN`;
    None: none). Such a birth ``(shared, b, i)`` first published at ``k`` is stamped ``(shared,
    k, PUBLISHED_BASE + i)``, the label every peer that publishes a track of birth component
    ``i`` at scan ``k`` gives it, so those peers need no spreading to agree. Should two of our
    tracks map to one stamp (or the stamp be held already), the earliest birth takes it and the
    others an own stamp: a label stays one track at a peer."""
    _keys: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=_KEY), init=False,
                              repr=False)
    """Sorted keys of the present labels that have been published."""
    _last: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64),
                              init=False, repr=False)
    """The scan each was last published."""
    _k: int = field(default=0, init=False, repr=False)
    stamped: np.ndarray = field(default_factory=lambda: np.zeros((0, 3), dtype=np.int64),
                                init=False, repr=False)
    """The labels ``(b, 3)`` the last :meth:`stamp` gave (each once)."""

    def __post_init__(self) -> None:
        if self.revisit < 1:
            raise ValueError(f"Publication.revisit must be at least 1, got {self.revisit}")

    def _lookup(self, keys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Whether each key was published, and its last scan (``(n,)`` bool, int64)."""
        return self._find(keys)[:2]

    def _find(self, keys: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """:meth:`_lookup` and each key's row in :attr:`_keys` (meaningful where known;
        None with nothing published)."""
        if not self._keys.size:
            return (np.zeros(keys.size, dtype=bool), np.zeros(keys.size, dtype=np.int64),
                    None)
        known, pos = keys_find(self._keys, keys)
        return known, np.where(known, self._last[pos], 0), pos

    def stamp(self, labels: np.ndarray, weights: np.ndarray, threshold: float,
              k: int) -> np.ndarray:
        """The labels ``(n, 3)`` of a mixture with weights ``(n,)`` at scan ``k``, the newly
        published stamped; remembers what is published (the present labels only)."""
        labels = as_labels(labels, len(weights))
        keys = label_keys(labels)
        on = keys_isin(keys, keys[np.asarray(weights) > threshold])
        known, last, pos = self._find(keys)
        unstamped = labels[:, 2] < PUBLISHED_BASE
        fresh = ~known & (labels[:, 0] == self.origin) & unstamped
        alike = np.zeros(len(labels), dtype=bool)
        if self.shared is not None:
            alike = on & ~known & (labels[:, 0] == self.shared) & unstamped
        back = (known & (self.gap is not None)
                & (k - last > ((self.gap or 0) + 1) * self.revisit))
        new = on & (fresh | back) | alike
        self.stamped = np.zeros((0, 3), dtype=np.int64)
        if new.any():
            labels = labels.copy()
            if alike.any():
                alike = stamp_shared(labels, keys, alike, new, k)
            own = new & ~alike
            if own.any():
                uniq, inv = np.unique(keys[own], return_inverse=True)
                labels[own] = new_labels(self.origin, k, len(uniq), PUBLISHED_BASE)[inv]
            keys = label_keys(labels)
            known[new] = False
            _, first = np.unique(keys[new], return_index=True)
            self.stamped = labels[np.flatnonzero(new)[first]]
        if not self.stamped.size and pos is not None and not (on & ~known).any():
            self._keep_known(pos, known, on, k)  # every published row's label known
        else:
            keep = on | known
            when = np.where(on, k, last)[keep]
            self._keys, idx = _unique_first(labels[keep])
            self._last = when[idx] if self._keys.size else np.zeros(0, dtype=np.int64)
        self._k = int(k)
        return labels

    def _keep_known(self, pos: np.ndarray, known: np.ndarray, on: np.ndarray, k: int) -> None:
        """:meth:`stamp`'s memory when nothing was stamped and every row published now is a
        known label (the usual scan): the known labels still carried, in their sorted order,
        those published now at scan ``k``; what ``_unique_first`` of the kept rows gives (a
        label's rows share ``on``, :func:`keys_isin` of the keys), without its sort."""
        held = np.zeros(self._keys.size, dtype=bool)
        held[pos[known]] = True
        now = np.zeros(self._keys.size, dtype=bool)
        now[pos[on]] = True
        self._keys = self._keys[held]
        self._last = np.where(now, k, self._last)[held]

    def take_known(self, known: tuple, k: int) -> None:
        """:meth:`stamp` at scan ``k`` where :func:`stamp_known_many` found nothing to stamp:
        its memory ``known`` taken (the labels stay as they are)."""
        self._keys, self._last = known
        self.stamped = np.zeros((0, 3), dtype=np.int64)
        self._k = int(k)

    def adopt(self, labels: np.ndarray) -> None:
        """Labels the network gave us (a relabel's winners): published as of the last scan."""
        keys = unique_keys(label_keys(as_labels(labels)))
        if not keys.size:
            return
        known, _ = self._lookup(keys)
        if (~known).any():
            add = keys[~known]
            allk = np.concatenate((self._keys, add))
            alll = np.concatenate((self._last, np.full(add.size, self._k, dtype=np.int64)))
            by = np.argsort(allk)
            self._keys, self._last = allk[by], alll[by]


def stamp_known_many(pubs: list[Publication], labels: list[np.ndarray],
                     weights: list[np.ndarray], thresholds: list[float],
                     ks: list[int]) -> list[tuple | None]:
    """:meth:`Publication.stamp` of many peers' steps at once where it stamps nothing (the
    usual scan): each published label already published and none back after a gap. Per
    problem ``(keys, last)``, the memory that stamp leaves (its :meth:`Publication._keep_known`,
    to the bit: the same rows of the same arrays), for :meth:`Publication.take_known`; None
    where the stamp must run (something to stamp, nothing published yet). Why: ~20 small NumPy
    calls per peer and scan; here every problem's rows are one array, each row keyed by its
    problem, the lookup in the memories one merge of the sorted keys (issues 33/38)."""
    P = len(pubs)
    out: list[tuple | None] = [None] * P
    n = np.array([len(x) for x in labels], dtype=np.int64)
    m = np.array([p._keys.size for p in pubs], dtype=np.int64)
    if P == 0 or not n.sum() or not m.sum():
        return out
    prob = np.repeat(np.arange(P), n)
    lab = np.concatenate(labels).astype(np.int64, copy=False)
    above = np.concatenate(weights) > np.asarray(thresholds, dtype=float)[prob]
    # a row is on when its (problem, label) has a row above the threshold: per group, any
    order = np.lexsort((lab[:, 2], lab[:, 1], lab[:, 0], prob))
    key = np.column_stack((prob, lab))
    ks_ = key[order]
    start = np.r_[True, (ks_[1:] != ks_[:-1]).any(axis=1)]
    grp = np.cumsum(start) - 1
    any_on = np.zeros(int(start.sum()), dtype=bool)
    np.logical_or.at(any_on, grp, above[order])
    on = np.empty(len(lab), dtype=bool)
    on[order] = any_on[grp]
    # each row's place in its problem's memory (sorted by label, each once): one merge
    tab = np.concatenate([p._keys for p in pubs]).view(np.int64).reshape(-1, 3)
    tprob = np.repeat(np.arange(P), m)
    last_all = np.concatenate([p._last for p in pubs])
    allk = np.concatenate((np.column_stack((tprob, tab)), key))
    flag = np.r_[np.zeros(len(tab), dtype=np.int64), np.ones(len(lab), dtype=np.int64)]
    by = np.lexsort((flag, allk[:, 3], allk[:, 2], allk[:, 1], allk[:, 0]))
    is_t = flag[by] == 0
    tpos = np.maximum.accumulate(np.where(is_t, by, -1))  # the last memory row up to here
    q = by[~is_t] - len(tab)
    g = tpos[~is_t]
    pos = np.empty(len(lab), dtype=np.int64)
    pos[q] = g
    known = (pos >= 0) & (np.concatenate((tab, np.zeros((1, 3), dtype=np.int64)))[pos]
                          == lab).all(axis=1) & (tprob[np.maximum(pos, 0)] == prob)
    k = np.asarray(ks, dtype=np.int64)
    gaps = np.array([0 if p.gap is None else (p.gap + 1) * p.revisit for p in pubs])
    gapped = np.array([p.gap is not None for p in pubs], dtype=bool)
    back = known & gapped[prob] & (k[prob] - last_all[np.maximum(pos, 0)] > gaps[prob])
    bad = np.zeros(P, dtype=bool)
    bad[prob[on & (~known | back)]] = True
    bad |= m == 0
    held = np.zeros(len(tab), dtype=bool)
    held[pos[known]] = True
    now = np.zeros(len(tab), dtype=bool)
    now[pos[known & on]] = True
    last = np.where(now, k[tprob], last_all)
    ends = np.cumsum(m).tolist()
    for i, pub in enumerate(pubs):
        if not bad[i]:
            h = held[ends[i] - m[i]:ends[i]]
            out[i] = (pub._keys[h], last[ends[i] - m[i]:ends[i]][h])
    return out


__all__ = ["REPUBLISH_GAP", "Confirmation", "Publication", "stamp_known_many", "stamp_shared"]
