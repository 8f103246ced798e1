"""Holder support of shared labels (issue 33): which peers stamped a shared label, so that a
tie between two labels of one scan is broken by support, alike at every peer.

Why (docs/labelled-tracking.md, "Same-scan ties broken by support"): a target's first plots
fall in two neighbouring birth cells at different peers, so two shared stamps of one scan
``(0, k, PUBLISHED_BASE + cell)`` name one target; the network rule (earliest scan, then
lowest origin, then lowest index) then picks the lower cell, often one that one or two peers
hold, and it replaces the id at the others hop by hop. With support the rule's order is
``(birth_scan, -holders, origin, index)``: ``holders`` the number of peers known to have
stamped the label at its scan, a bit mask per label (a peer's bit: its origin) OR-ed over what
the neighbours report, so it only grows and every peer ends with the same masks (OR is
idempotent and commutative; a label's mask travels with the label, one hop a scan).

On the wire the mask rides in bits :data:`SUPPORT_SHIFT` and up of a shared label's origin
column (a shared origin is 0; own origins are peer indices, far below ``2^24``), so Estimate
protocol 2 is unchanged; :meth:`LabelSupport.encode` and :func:`decode` are the two ends, at
``peers.consensus.Consensus``. Peers whose origin shares a bit modulo :data:`SUPPORT_BITS`
count once (more than 39 peers: a lower bound of the holders).

Masks are checked where they arrive (issue 33, hostile input; docs/security.md, "Label
masks"): a member that lies could set every bit and win every same-scan tie. A receiver takes
from a neighbour's mask only the bits that neighbour can vouch for (:func:`reach_masks`): its
own; never the receiver's or another neighbour's (those peers' own estimates say whether they
stamped the label: first-hand); and of the peers it does not hear itself, only those within
the hops the label can have travelled to the sender since its scan (one hop a consensus round,
plus a round's slack). Bits it drops that it did not already know are counted
(:attr:`LabelSupport.clipped`; the peer's ``rejected["label-mask"]``). Honest masks never
exceed this, so honest runs are unchanged.

Birth scans are checked too (:meth:`LabelSupport.vouched`): the earliest scan wins whatever the
support, so a member could stamp a label before the target's first plots. A label is first
published by its birth scan; an older one is taken only if a stamper this peer hears itself
published it so (or a far stamper within the sender's reach claims it); else the row is
re-stamped to the estimate's scan (:attr:`LabelSupport.backdated`; ``rejected["label-scan"]``).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import shortest_path
from sensornet.tracking.label_keys import (
    PUBLISHED_BASE,
    SHARED_ORIGIN,
    as_labels,
    keys_equal,
    keys_find,
    label_keys,
    unique_keys,
)

SUPPORT_SHIFT = 24
"""First bit of the origin column that carries the holder mask on the wire."""
SUPPORT_BITS = 39
"""Bits of the mask (``SUPPORT_SHIFT`` .. 62: the column stays a non-negative int64)."""
ORIGIN_MASK = (1 << SUPPORT_SHIFT) - 1
FIND_PAIRS = 4096
"""Up to this many (label, stored label) pairs a lookup compares them all at once
(:meth:`LabelSupport._find`), beyond it a binary search: the same answer, faster for small."""
FRESH_INDEX = 1 << 32
"""``peers.labelling.FRESH_BASE`` (not imported: labelling imports this module): own labels of
a fusion's fresh components, ``(origin, k, FRESH_INDEX + i)`` below ``PUBLISHED_BASE``,
first published as late as the next scan's local estimate (adopted by the estimator)."""
KEEP_SCANS = 64
"""Scans a label's mask is kept after its birth scan (ties are settled within the settle wait,
eccentricity + 2 scans; then the mask is no longer asked for)."""


def _early(lab: np.ndarray, k: int) -> np.ndarray:
    """``(n,)`` which of ``lab (n, 3)`` published at scan ``k`` are so by their birth scan: of
    scan ``k`` or later, or a fused fresh own label of scan ``k - 1`` (:data:`FRESH_INDEX`)."""
    scan = lab[:, 1]
    early = scan >= k
    prev = scan == k - 1
    if prev.any():  # the fresh test only where it can hold (most estimates have no such row)
        index = lab[:, 2]
        early |= (prev & (lab[:, 0] != SHARED_ORIGIN) & (index >= FRESH_INDEX)
                  & (index < PUBLISHED_BASE))
    return early


def peer_bit(origin: int) -> int:
    """The mask bit of the peer with label ``origin`` (own origins start at 1 with shared
    births; bit ``(origin - 1) mod SUPPORT_BITS``)."""
    return 1 << ((max(int(origin), 1) - 1) % SUPPORT_BITS)


def reach_masks(adjacency: np.ndarray, origins: Sequence[int], i: int) -> dict[int, np.ndarray]:
    """What peer ``i`` takes from each neighbour's masks: for neighbour ``j`` (a row of
    ``adjacency (n, n)``, nonzero = link), ``(H + 1,)`` int64 masks (``H``: the graph's
    diameter), entry ``h`` the bits ``j`` can vouch for on a label whose stamps had ``h`` hops to
    reach it: ``j``'s own and those of the peers ``i`` does not hear itself (not ``i``, not its
    neighbours) within ``h`` hops of ``j``. ``origins (n,)``: each peer's label origin."""
    A = np.asarray(adjacency) != 0
    n = len(A)
    hops = shortest_path(csr_matrix(A), unweighted=True) if n else np.zeros((0, 0))
    bits = np.left_shift(1, (np.maximum(np.asarray(origins, dtype=np.int64), 1) - 1)
                         % SUPPORT_BITS).astype(np.int64)
    far = ~A[i]
    far[i] = False
    finite = hops[np.isfinite(hops)]
    h = np.arange(int(finite.max()) + 1 if finite.size else 1)
    out = {}
    for j in np.flatnonzero(A[i]):  # per neighbour: a cumulative OR of the far bits by hops
        d = np.where(far, hops[j], np.inf)
        order = np.argsort(d, kind="stable")
        cum = np.bitwise_or.accumulate(np.r_[np.int64(0), bits[order]])
        out[int(j)] = cum[np.searchsorted(d[order], h, side="right")] | bits[j]
    return out


def reach_by_name(names: Sequence[str], adjacency: np.ndarray, origins: Sequence[int],
                  i: int) -> tuple[tuple[str, tuple[int, ...]], ...]:
    """:func:`reach_masks` keyed by the neighbours' names ``names (n,)``, as
    ``peers.consensus_types.ConsensusOptions.label_reach`` holds it."""
    return tuple((names[j], tuple(int(m) for m in t))
                 for j, t in reach_masks(adjacency, origins, i).items())


def decode(labels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Labels received ``(n, 3)`` -> the labels without masks ``(n, 3)`` and each row's mask
    ``(n,)`` int64 (0: none)."""
    lab = as_labels(labels)
    masks = lab[:, 0] >> SUPPORT_SHIFT
    if not masks.any():
        return lab, masks
    clean = lab.copy()
    clean[:, 0] &= ORIGIN_MASK
    return clean, masks


_ROW = np.dtype((np.void, 24))
"""A label row's three int64 as one unstructured value (equal iff every column is)."""


def _columns(keys: np.ndarray) -> np.ndarray:
    """Label keys ``(n,)`` (:func:`tracking.label_keys.label_keys`) back as ``(n, 3)`` int64
    rows (a view): compared row-wise in C, where a structured ``==`` costs a Python call."""
    return keys.view(np.int64).reshape(-1, 3)


def popcount(masks: np.ndarray) -> np.ndarray:
    """Bits set in each mask ``(n,)`` int64 -> ``(n,)`` int64."""
    return np.bitwise_count(np.asarray(masks, dtype=np.int64)).astype(np.int64)


class LabelSupport:
    """A peer's holder masks of shared labels: sorted label keys, their masks and birth
    scans. ``bit``: this peer's own bit (:func:`peer_bit`)."""

    def __init__(self, bit: int, reach: Mapping[str, Sequence[int]] | None = None,
                 rounds: int = 1) -> None:
        self.bit = int(bit)
        self.keys = label_keys(np.zeros((0, 3), dtype=np.int64))
        self.masks = np.zeros(0, dtype=np.int64)
        self.scans = np.zeros(0, dtype=np.int64)
        self.reach = (None if reach is None else
                      {s: np.asarray(t, dtype=np.int64) for s, t in reach.items()})
        """Per neighbour, the bits it can vouch for by hops (:func:`reach_masks`); None:
        masks taken as received (unchecked)."""
        self.rounds = max(int(rounds), 1)
        self._near = np.bitwise_or.reduce([self.bit, *(int(t[0]) for t in self.reach.values())]
                                          if self.reach else [self.bit]).astype(np.int64)
        """This peer's bit and its neighbours' (their publications are heard first-hand)."""
        """Consensus rounds a scan: hops a mask can travel a scan."""
        self.clipped = 0
        """Labels received whose mask named peers the sender cannot vouch for, bits not known
        here otherwise (those bits dropped)."""
        self.backdated = 0
        """Estimates refused labels by :meth:`vouched` (a label older than any first-hand
        publication of it: the peer's ``rejected["label-scan"]``)."""
        self._early = label_keys(np.zeros((0, 3), dtype=np.int64))
        self._early_bits = np.zeros(0, dtype=np.int64)
        """Sorted keys of labels (any origin) seen published at or before their birth scan,
        and the bits of the peers seen so (first-hand: this peer's own and its neighbours')."""

    def add(self, labels: np.ndarray, masks: np.ndarray | int) -> None:
        """OR ``masks`` (``(n,)`` or one for all) into the masks of ``labels (n, 3)``; only
        shared labels (origin :data:`SHARED_ORIGIN`) with a nonzero mask are kept."""
        lab = as_labels(labels)
        m = np.asarray(masks, dtype=np.int64)
        m = (np.full(len(lab), m) if m.ndim == 0 else m if m.shape == (len(lab),)
             else np.broadcast_to(m, (len(lab),)))
        self._or_in(lab, m)

    def _or_in(self, lab: np.ndarray, m: np.ndarray,
               found: tuple[np.ndarray, np.ndarray] | None = None) -> None:
        """:meth:`add` of checked ``lab (n, 3)`` int64 and ``m (n,)`` int64 (``found``:
        :meth:`_find` of ``lab`` in the store as it is, if the caller has it)."""
        ok = (lab[:, 0] == SHARED_ORIGIN) & (m != 0)
        if not ok.any():
            return
        if not ok.all():
            lab, m = lab[ok], m[ok]
            if found is not None:
                found = found[0][ok], found[1][ok]
        if len(self.keys):  # every label known (the usual case): OR in place, no re-sort
            hit, pos = self._find(lab) if found is None else found
            if hit.all():
                np.bitwise_or.at(self.masks, pos, m)
                return
        keys = np.concatenate([self.keys, label_keys(lab)])
        allm = np.concatenate([self.masks, m])
        scans = np.concatenate([self.scans, lab[:, 1]])
        order = np.argsort(keys, kind="stable")
        keys, allm, scans = keys[order], allm[order], scans[order]
        first = np.ones(len(keys), dtype=bool)
        first[1:] = ~keys_equal(keys[1:], keys[:-1])  # a structured != costs a Python call
        starts = np.flatnonzero(first)
        self.keys, self.scans = keys[starts], scans[starts]
        self.masks = np.bitwise_or.reduceat(allm, starts)

    def heard(self, sender: str, labels: np.ndarray, masks: np.ndarray, k: int,
              rnd: int = 0) -> int:
        """OR in the masks ``(n,)`` of decoded ``labels (n, 3)`` from neighbour ``sender``'s
        estimate of scan ``k``, round ``rnd``, each cut to what it can vouch for: its
        :attr:`reach` entry at ``(k - scan + 1) * rounds + rnd`` hops (one hop a round since
        the label's scan, a round of slack for a peer a scan ahead); nothing on own labels;
        labels older than :data:`KEEP_SCANS` (no longer kept) pass. Returns the labels that
        lost bits not known here, also added to :attr:`clipped`."""
        lab = as_labels(labels)
        m = np.asarray(masks, dtype=np.int64)
        if self.reach is None or not m.any():
            self.add(lab, m)
            return 0
        known = np.zeros(len(lab), dtype=np.int64)
        found = self._find(lab) if len(self.keys) and len(lab) else None
        if found is not None:  # mask_of's answer; the lookup serves _or_in below too
            known[found[0]] = self.masks[found[1][found[0]]]
        if not (m & ~known).any():  # every bit known here already: nothing to add or count
            return 0
        table = self.reach.get(sender)
        if table is None:  # not a neighbour we know: it vouches for nothing
            allowed = np.zeros(len(lab), dtype=np.int64)
        else:
            h = (np.maximum(k - lab[:, 1], 0) + 1) * self.rounds + rnd
            allowed = table[np.minimum(np.maximum(h, 0), len(table) - 1)]  # np.clip's, cheaper
        old = lab[:, 1] < k - KEEP_SCANS
        if old.any():
            allowed = np.where(old, np.int64(-1), allowed)
        allowed[lab[:, 0] != SHARED_ORIGIN] = 0
        kept = m & allowed
        cut = m & ~kept
        lost = int(((cut & ~known) != 0).sum()) if cut.any() else 0
        self.clipped += lost
        self._or_in(lab, kept, found)  # (n,): m & allowed
        return lost

    def own(self, labels: np.ndarray, k: int) -> None:
        """Our published ``labels (n, 3)`` at scan ``k``: the shared ones of scan ``k`` (stamped
        by us this scan, or moved to it) take our bit."""
        lab = as_labels(labels)
        self.add(lab[lab[:, 1] == k], self.bit)
        if self.reach is not None:
            self._saw_early(lab[_early(lab, k)], self.bit)

    def vouched(self, sender: str, labels: np.ndarray, masks: np.ndarray, k: int,
                rnd: int = 0) -> bool:
        """Whether every label of the estimate passes :meth:`refused` (recorded and counted)."""
        return self.refused(sender, labels, masks, k, rnd) is None

    def checked(self, sender: str, labels: np.ndarray, masks: np.ndarray, k: int,
                rnd: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """``labels (n, 3)`` and ``masks (n,)`` with the rows :meth:`refused` re-stamped to
        scan ``k`` (a label that loses to every older one, so the row stays the same target's
        copy, not a second track) and their masks dropped."""
        bad = self.refused(sender, labels, masks, k, rnd)
        if bad is None:
            return labels, masks
        lab, m = np.array(labels, dtype=np.int64, copy=True), np.array(masks, dtype=np.int64)
        lab[bad, 1] = k
        m[bad] = 0
        return lab, m

    def refused(self, sender: str, labels: np.ndarray, masks: np.ndarray, k: int,
                rnd: int = 0) -> np.ndarray | None:
        """Which of decoded ``labels (n, 3)`` (masks ``(n,)``) of neighbour ``sender``'s
        estimate of scan ``k`` are refused: a lying member could stamp a label earlier than
        the target's first plots and win it everywhere (the earliest scan wins whatever the
        support; docs/security.md "Label masks"). A label is first published at or before its
        birth scan (a stamp at first publication, an edge cell's next scan; a fused fresh label
        by the next scan: :func:`_early`), relays later; so an older one needs a stamper (its
        origin, or a shared label's mask bits) that this peer saw publish it so (itself or a
        neighbour: first-hand), or a far stamper within ``sender``'s reach at its age
        (unverifiable without signatures), or is a stamp moved a scan later by its stamper
        (``peers.labelling.corroborated``: ``(o, s - 1, i)`` seen so, ``(o, s, i)`` published
        when its track is next published, maskless). ``(n,)`` bool, the rows refused (the
        estimate counted in :attr:`backdated`), or None: every row taken."""
        if self.reach is None:
            return None
        table = self.reach.get(sender)
        lab = as_labels(labels)
        if table is None or not len(lab):
            return None
        early = _early(lab, k)
        if early.any():
            self._saw_early(lab[early], table[0])  # table[0]: the sender's own bit
        old = ~early & (lab[:, 1] >= k - KEEP_SCANS)
        if not old.any():
            return None
        lo = lab[old]
        m = np.asarray(masks, dtype=np.int64)[old]
        origin = lo[:, 0] & ORIGIN_MASK
        shared = origin == SHARED_ORIGIN
        claim = np.where(shared, m, np.left_shift(1, (np.maximum(origin, 1) - 1)
                                                  % SUPPORT_BITS))
        h = (k - lo[:, 1] + 1) * self.rounds + rnd
        far = claim & table[np.minimum(np.maximum(h, 0), len(table) - 1)] & ~self._near
        ok = far != 0  # vouched by a far stamper: not looked up
        if ok.all():
            return None
        seen, moved = np.zeros(len(lo), dtype=np.int64), np.zeros(len(lo), dtype=np.int64)
        seen[~ok] = self._seen(lo[~ok])
        ok |= (claim & seen) != 0
        if not ok.all():  # a stamp moved a scan later (uncorroborated), published after that
            moved[~ok] = self._seen(lo[~ok] - np.array([0, 1, 0]))
            ok |= moved != 0
        if ok.all():
            return None
        self.backdated += 1
        bad = np.zeros(len(lab), dtype=bool)
        bad[np.flatnonzero(old)[~ok]] = True
        return bad

    def _seen(self, lab: np.ndarray) -> np.ndarray:
        """``(n,)`` bits of the peers seen publishing each of ``lab (n, 3)`` by its scan."""
        seen = np.zeros(len(lab), dtype=np.int64)
        if len(self._early) and len(lab):
            hit, pos = keys_find(self._early, label_keys(lab))
            seen[hit] = self._early_bits[pos[hit]]
        return seen

    def _saw_early(self, lab: np.ndarray, bit: int) -> None:
        """Record ``lab (n, 3)`` as published by the peer of ``bit`` at or before their scan."""
        if not len(lab):
            return
        keys = unique_keys(label_keys(lab))  # sorted, each once
        if len(self._early):  # the known ones take the bit in place, the others go in at
            hit, pos = keys_find(self._early, keys)  # their places (no re-sort of the store)
            if hit.any():
                self._early_bits[pos[hit]] |= np.int64(bit)
                keys = keys[~hit]
            if not len(keys):
                return
            at = np.searchsorted(self._early, keys) + np.arange(len(keys))  # in the result
            rest = np.ones(len(self._early) + len(keys), dtype=bool)
            rest[at] = False  # np.insert's arrays, without its Python-side checks
            early = np.empty(len(rest), dtype=self._early.dtype)
            early[at], early[rest] = keys, self._early
            bits = np.empty(len(rest), dtype=np.int64)
            bits[at], bits[rest] = bit, self._early_bits
            self._early, self._early_bits = early, bits
        else:
            self._early, self._early_bits = keys, np.full(len(keys), bit, dtype=np.int64)

    def mask_of(self, labels: np.ndarray) -> np.ndarray:
        """``(n,)`` int64 masks of ``labels (n, 3)`` (0: not known, or not shared)."""
        lab = as_labels(labels)
        out = np.zeros(len(lab), dtype=np.int64)
        if not len(self.keys) or not len(lab):
            return out
        hit, pos = self._find(lab)
        out[hit] = self.masks[pos[hit]]
        return out

    def _find(self, lab: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Whether each of ``lab (n, 3)`` is in the store (non-empty) and where: ``(n,)``
        bool and index. Few rows against a small store: every pair compared at once (a
        structured searchsorted costs more there); else a binary search."""
        if len(lab) * len(self.keys) <= FIND_PAIRS:  # rows equal as 24 bytes: a C compare
            eq = (np.ascontiguousarray(lab).view(_ROW).reshape(-1)[:, None]
                  == self.keys.view(_ROW)[None, :])
            return eq.any(axis=1), eq.argmax(axis=1)
        pos = np.searchsorted(self.keys, label_keys(lab)).clip(max=len(self.keys) - 1)
        return (_columns(self.keys)[pos] == lab).all(axis=1), pos

    def counts(self, labels: np.ndarray) -> np.ndarray:
        """``(n,)`` holders known of each of ``labels (n, 3)`` (0: own labels)."""
        return popcount(self.mask_of(labels))

    def encode(self, labels: np.ndarray) -> np.ndarray:
        """``labels (n, 3)`` for the wire: each shared row's origin carries its mask."""
        lab = as_labels(labels)
        m = self.mask_of(lab) & ((1 << SUPPORT_BITS) - 1)
        if not m.any():
            return lab
        out = lab.copy()
        out[:, 0] |= m << SUPPORT_SHIFT
        return out

    def prune(self, k: int, keep: int = KEEP_SCANS) -> None:
        """Forget the masks of labels born more than ``keep`` scans before scan ``k``, or
        after it: a neighbour's label of a far-future birth scan (no honest estimate has one)
        would otherwise stay for the run, and a sender could grow the store without bound."""
        ok = np.abs(self.scans - k) <= keep
        if not ok.all():
            self.keys, self.masks, self.scans = self.keys[ok], self.masks[ok], self.scans[ok]
        if len(self._early):
            ok = np.abs(_columns(self._early)[:, 1] - k) <= keep
            if not ok.all():
                self._early, self._early_bits = self._early[ok], self._early_bits[ok]


__all__ = ["KEEP_SCANS", "ORIGIN_MASK", "SUPPORT_BITS", "SUPPORT_SHIFT", "LabelSupport",
           "decode", "peer_bit", "popcount", "reach_by_name", "reach_masks"]
