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

A mask is a bit per peer (origin ``o``: bit ``o - 1``, any number of peers), held as words of
:data:`SUPPORT_BITS` bits, ``(n, W)`` int64 (:func:`as_words`; a Python int at the API's edge,
:func:`peer_bit`, :func:`mask_ints`). On the wire word 0 rides in bits :data:`SUPPORT_SHIFT` and
up of a shared label's origin column (a shared origin is 0; own origins are peer indices, far
below ``2^24``), so up to 39 peers Estimate protocol 2 is unchanged, byte for byte; words 1 and
up (peers 40 and beyond) travel in the Estimate's ``label_masks`` (protocol 3).
:meth:`LabelSupport.encode` and :func:`decode` are the two ends, at ``peers.consensus.Consensus``.
(Until 5 Dec the mask was one 39-bit word, peers sharing a bit modulo 39: above 39 peers a far
stamper's bit could alias a near peer's and its honest label fail the birth check.)

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
    label_keys,
    unique_keys,
)

SUPPORT_SHIFT = 24
"""First bit of the origin column that carries the holder mask on the wire."""
SUPPORT_BITS = 39
"""Bits of a mask word: word 0 fills the origin column's ``SUPPORT_SHIFT`` .. 62 (the column
stays a non-negative int64); every word has as many, so word ``w`` holds peers ``39 w + 1 ..``."""
WORD = (1 << SUPPORT_BITS) - 1
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
_nz = np.count_nonzero
"""Nonzero entries, a C call: ``ndarray.any()``/``all()`` go through a Python wrapper that costs
about four times as much on the few rows of one estimate (2.5 on average at 50 peers)."""


def _any_rows(m: np.ndarray) -> np.ndarray:
    """``(n,)`` which rows of mask words ``m (n, W)`` have a bit set."""
    w = m.shape[1]
    return (m[:, 0] != 0 if w == 1 else np.logical_or(m[:, 0], m[:, 1]) if w == 2
            else np.logical_or.reduce(m, axis=1))


def _early(lab: np.ndarray, k: int) -> np.ndarray:
    """``(n,)`` which of ``lab (n, 3)`` published at scan ``k`` are so by their birth scan: of
    scan ``k`` or later, or a fused fresh own label of scan ``k - 1`` (:data:`FRESH_INDEX`)."""
    scan = lab[:, 1]
    early = scan >= k
    prev = scan == k - 1
    if _nz(prev):  # the fresh test only where it can hold (most estimates have no such row)
        index = lab[:, 2]
        early |= (prev & (lab[:, 0] != SHARED_ORIGIN) & (index >= FRESH_INDEX)
                  & (index < PUBLISHED_BASE))
    return early


def peer_bit(origin: int) -> int:
    """The mask of the peer with label ``origin`` as a Python int (own origins start at 1 with
    shared births; bit ``origin - 1``, exact for any number of peers)."""
    return 1 << (max(int(origin), 1) - 1)


def words_for(bits: int) -> int:
    """Mask words that hold ``bits`` bits (at least one)."""
    return max(-(-int(bits) // SUPPORT_BITS), 1)


def as_words(masks, width: int | None = None) -> np.ndarray:
    """Masks as words: a Python int -> ``(W,)``; ``(n,)`` int64 (each a mask of bits 0..62,
    as before words) -> ``(n, W)``; ``(n, W)`` words as they are. ``width``: pad with zero
    words or cut to it."""
    if isinstance(masks, int | np.integer):
        x = int(masks)
        if x < 0:
            raise ValueError(f"a holder mask is negative: {x}")
        w = [(x >> (SUPPORT_BITS * i)) & WORD for i in range(words_for(x.bit_length()))]
        out = np.array(w, dtype=np.int64)
    else:
        out = np.asarray(masks, dtype=np.int64)
        if out.ndim == 0:
            return as_words(int(out), width)
        if out.ndim == 1:  # one int64 a row: at most two words
            high = out >> SUPPORT_BITS
            out = (np.stack([out & WORD, high], axis=1) if high.any()
                   else out.reshape(-1, 1) & WORD)
    return out if width is None else _fit(out, width)


def _fit(m: np.ndarray, width: int) -> np.ndarray:
    """Words ``(..., W)`` padded with zero words or cut to ``width``."""
    w = m.shape[-1]
    if w == width:
        return m
    if w > width:
        return m[..., :width]
    pad = np.zeros((*m.shape[:-1], width - w), dtype=np.int64)
    return np.concatenate([m, pad], axis=-1)


def mask_ints(words: np.ndarray) -> list:
    """Words ``(W,)`` or ``(n, W)`` back as Python ints (one, or a list of ``n``)."""
    w = np.asarray(words, dtype=np.int64)
    if w.ndim == 1:
        return sum(int(x) << (SUPPORT_BITS * i) for i, x in enumerate(w.tolist()))
    return [mask_ints(r) for r in w]


def origin_words(origins: np.ndarray, width: int) -> np.ndarray:
    """``(n, width)`` words of each origin's bit (:func:`peer_bit`; none if beyond ``width``
    words)."""
    o = np.maximum(np.asarray(origins, dtype=np.int64), 1) - 1
    out = np.zeros((len(o), width), dtype=np.int64)
    word = o // SUPPORT_BITS
    ok = word < width
    out[np.flatnonzero(ok), word[ok]] = np.left_shift(1, o[ok] % SUPPORT_BITS)
    return out


def reach_masks(adjacency: np.ndarray, origins: Sequence[int], i: int) -> dict[int, np.ndarray]:
    """What peer ``i`` takes from each neighbour's masks: for neighbour ``j`` (a row of
    ``adjacency (n, n)``, nonzero = link), ``(H + 1, W)`` mask words (``H``: the graph's
    diameter, ``W``: words of the largest origin), entry ``h`` the bits ``j`` can vouch for on
    a label whose stamps had ``h`` hops to reach it: ``j``'s own and those of the peers ``i``
    does not hear itself (not ``i``, not its neighbours) within ``h`` hops of ``j``.
    ``origins (n,)``: each peer's label origin."""
    A = np.asarray(adjacency) != 0
    n = len(A)
    hops = shortest_path(csr_matrix(A), unweighted=True) if n else np.zeros((0, 0))
    o = np.asarray(origins, dtype=np.int64)
    bits = origin_words(o, words_for(int(o.max()) if len(o) else 1))
    far = ~A[i]
    far[i] = False
    finite = hops[np.isfinite(hops)]
    h = np.arange(int(finite.max()) + 1 if finite.size else 1)
    out = {}
    for j in np.flatnonzero(A[i]):  # per neighbour: a cumulative OR of the far bits by hops
        d = np.where(far, hops[j], np.inf)
        order = np.argsort(d, kind="stable")
        cum = np.bitwise_or.accumulate(
            np.concatenate([np.zeros((1, bits.shape[1]), dtype=np.int64), bits[order]]), axis=0)
        out[int(j)] = cum[np.searchsorted(d[order], h, side="right")] | bits[j]
    return out


def reach_by_name(names: Sequence[str], adjacency: np.ndarray, origins: Sequence[int],
                  i: int) -> tuple[tuple[str, tuple[int, ...]], ...]:
    """:func:`reach_masks` keyed by the neighbours' names ``names (n,)``, as
    ``peers.consensus_types.ConsensusOptions.label_reach`` holds it."""
    return tuple((names[j], tuple(mask_ints(t)))
                 for j, t in reach_masks(adjacency, origins, i).items())


DECODED = 256
"""Estimates' decoded labels kept (:func:`decode`): an estimate reaches each co-hosted
neighbour of its sender (4 on a ring of degree 4), which decode and check the same rows."""
_decoded: dict[tuple, tuple[np.ndarray, np.ndarray, dict]] = {}
"""(label bytes, mask-word bytes) -> (labels, masks, :func:`_parts` by scan and round): read-only
arrays, shared by every receiver of those rows (none writes into them: checked() copies)."""
_by_id: dict[int, tuple[np.ndarray, np.ndarray, dict]] = {}
"""The same entries by ``id`` of their labels array (held by the entry, so the id stays its)."""


def decode(labels: np.ndarray, extra: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Labels received ``(n, 3)`` (and the Estimate's ``label_masks``, words 1 and up, ``(n,
    W - 1)``, or None) -> the labels without masks ``(n, 3)`` and each row's mask words
    ``(n, W)`` int64 (0: none), read-only: the same rows decode once for every co-hosted
    receiver (by their bytes, :data:`DECODED` kept; a pure function of them)."""
    lab = as_labels(labels)
    ext = None if extra is None or not np.size(extra) else np.asarray(extra, dtype=np.int64)
    key = (lab.tobytes(), None if ext is None else ext.tobytes())
    got = _decoded.get(key)
    if got is not None:
        return got[0], got[1]
    clean, masks = _decode(lab, ext)
    if clean is lab:
        clean = lab.copy()
    clean.flags.writeable = masks.flags.writeable = False
    entry = (clean, masks, {})
    if len(_decoded) >= DECODED:
        _by_id.pop(id(_decoded.pop(next(iter(_decoded)))[0]), None)  # the oldest
    _decoded[key] = _by_id[id(clean)] = entry
    return clean, masks


def _decode(lab: np.ndarray, extra: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """:func:`decode` of checked rows ``lab (n, 3)`` int64 and words 1.. (or None)."""
    word0 = lab[:, 0] >> SUPPORT_SHIFT
    masks = word0[:, None]
    if extra is not None:
        masks = np.concatenate([masks, extra.reshape(len(lab), -1) & WORD], axis=1)
    if not _nz(word0):
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


def _find_rows(keys: np.ndarray, lab: np.ndarray, rows: np.ndarray | None = None
               ) -> tuple[np.ndarray, np.ndarray]:
    """Whether each of ``lab (n, 3)`` int64 is in sorted unique ``keys`` (non-empty) and where:
    ``(n,)`` bool and index (``rows``: ``keys`` as :data:`_ROW` values, if the caller keeps
    them). Few rows against a small store: every pair compared at once (a structured
    searchsorted costs more there); else a binary search."""
    if len(lab) * len(keys) <= FIND_PAIRS:  # rows equal as 24 bytes: a C compare
        if rows is None:
            rows = keys.view(_ROW)
        eq = np.ascontiguousarray(lab).view(_ROW).reshape(-1)[:, None] == rows[None, :]
        return np.logical_or.reduce(eq, axis=1), eq.argmax(axis=1)
    pos = np.searchsorted(keys, label_keys(lab)).clip(max=len(keys) - 1)
    return (_columns(keys)[pos] == lab).all(axis=1), pos


def popcount(masks: np.ndarray) -> np.ndarray:
    """Bits set in each mask, ``(n, W)`` words (or ``(n,)`` int64) -> ``(n,)`` int64."""
    m = np.asarray(masks, dtype=np.int64)
    c = np.bitwise_count(m).astype(np.int64)
    return c.sum(axis=1) if m.ndim == 2 else c


def _parts(labels: np.ndarray, masks: np.ndarray, k: int, rnd: int, words: int, rounds: int,
           hops: int) -> tuple | None:
    """What :meth:`LabelSupport.refused` asks of an estimate's rows whatever the receiver:
    ``(lab, early rows, their count, old (n,) bool, its count, old rows, their claimed stampers
    (n_old, words), hops since their scan capped at hops - 1)``, None: no rows. Kept with
    :func:`decode`'s entry of ``labels`` and ``masks`` (every co-hosted receiver of an
    estimate asks the same), else computed."""
    entry = _by_id.get(id(labels))
    if entry is not None and entry[0] is labels and entry[1] is masks:
        key = (k, rnd, words, rounds, hops)
        got = entry[2].get(key, entry)
        if got is entry:
            got = entry[2][key] = _parts_of(labels, masks, k, rnd, words, rounds, hops)
        return got
    return _parts_of(as_labels(labels), masks, k, rnd, words, rounds, hops)


def _parts_of(lab: np.ndarray, masks: np.ndarray, k: int, rnd: int, words: int, rounds: int,
              hops: int) -> tuple | None:
    """:func:`_parts`, computed."""
    n = len(lab)
    if not n:
        return None
    early = _early(lab, k)
    n_early = _nz(early)
    rows = lab if n_early == n else lab[early]
    if n_early == n:
        return lab, rows, n_early, None, 0, None, None, None
    old = ~early & (lab[:, 1] >= k - KEEP_SCANS)
    n_old = _nz(old)
    if not n_old:
        return lab, rows, n_early, old, 0, None, None, None
    m = as_words(masks)
    lo, m = (lab, m) if n_old == n else (lab[old], m[old])
    m = _fit(m, words)  # bits beyond the network's: no stamper
    origin = lo[:, 0] & ORIGIN_MASK
    shared = origin == SHARED_ORIGIN
    claim = (m if _nz(shared) == n_old else
             np.where(shared[:, None], m, origin_words(origin, words)))
    # hops since the label's scan: (k - scan + 1) rounds + rnd, at least 2 for these rows
    h = (k + 1 + rnd) - lo[:, 1] if rounds == 1 else (k - lo[:, 1] + 1) * rounds + rnd
    if rnd < 0:
        h = np.maximum(h, 0)
    return lab, rows, n_early, old, n_old, lo, claim, np.minimum(h, hops - 1)


class LabelSupport:
    """A peer's holder masks of shared labels: sorted label keys, their mask words and birth
    scans. ``bit``: this peer's own mask (:func:`peer_bit`, a Python int); ``words``: at least
    this many mask words (more if ``bit`` or ``reach`` need them; unchecked, the store widens
    to what it is given)."""

    def __init__(self, bit: int, reach: Mapping[str, Sequence[int]] | None = None,
                 rounds: int = 1, words: int = 1) -> None:
        tables = ({} if reach is None else
                  {s: [as_words(int(x)) for x in t] for s, t in reach.items()})
        width = max([int(words), len(as_words(int(bit)))]
                    + [len(w) for t in tables.values() for w in t])
        self.words = width
        """Mask words of :attr:`bit`, the reach tables and the first-hand records."""
        self.bit = as_words(int(bit), width)
        self.keys = label_keys(np.zeros((0, 3), dtype=np.int64))
        self.masks = np.zeros((0, width), dtype=np.int64)
        self.scans = np.zeros(0, dtype=np.int64)
        self.reach = (None if reach is None else
                      {s: np.array([_fit(w, width) for w in t], dtype=np.int64
                                   ).reshape(-1, width) for s, t in tables.items()})
        """Per neighbour, the bits it can vouch for by hops (:func:`reach_masks`), ``(H + 1,
        W)`` words; None: masks taken as received (unchecked)."""
        self.rounds = max(int(rounds), 1)
        """Consensus rounds a scan: hops a mask can travel a scan."""
        near = self.bit.copy()
        for t in (self.reach or {}).values():
            if len(t):
                near |= t[0]
        self._near = near
        """This peer's bit and its neighbours' (their publications are heard first-hand)."""
        self._far = {s: t & ~near for s, t in (self.reach or {}).items()}
        self._views: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        """Per store (``"keys"``, ``"early"``), its keys array and their :data:`_ROW` view, kept
        while the store's array is the same object (a view costs a Python-side check)."""
        """:attr:`reach` without :attr:`_near`'s bits: what a far stamper can vouch for."""
        self.clipped = 0
        """Labels received whose mask named peers the sender cannot vouch for, bits not known
        here otherwise (those bits dropped)."""
        self.backdated = 0
        """Estimates refused labels by :meth:`vouched` (a label older than any first-hand
        publication of it: the peer's ``rejected["label-scan"]``)."""
        self._early = label_keys(np.zeros((0, 3), dtype=np.int64))
        self._early_bits = np.zeros((0, width), dtype=np.int64)
        """Sorted keys of labels (any origin) seen published at or before their birth scan,
        and the bits of the peers seen so (first-hand: this peer's own and its neighbours')."""

    def add(self, labels: np.ndarray, masks) -> None:
        """OR ``masks`` into the masks of ``labels (n, 3)``: one for all (a Python int, or
        ``(1,)``) or one a row, ``(n,)`` int64 (bits 0..62) or words ``(n, W)``; only shared
        labels (origin :data:`SHARED_ORIGIN`) with a nonzero mask are kept."""
        lab = as_labels(labels)
        m = as_words(masks)
        if m.ndim == 1:
            m = m[None, :]
        self._or_in(lab, np.broadcast_to(m, (len(lab), m.shape[1])))

    def _widen(self, width: int) -> None:
        """Store masks of at least ``width`` words (unchecked stores take any peer's bits)."""
        if width > self.masks.shape[1]:
            self.masks = _fit(self.masks, width)

    def _or_in(self, lab: np.ndarray, m: np.ndarray,
               found: tuple[np.ndarray, np.ndarray] | None = None) -> None:
        """:meth:`add` of checked ``lab (n, 3)`` int64 and mask words ``m (n, W)`` int64
        (``found``: :meth:`_find` of ``lab`` in the store as it is, if the caller has it)."""
        ok = (lab[:, 0] == SHARED_ORIGIN) & _any_rows(m)
        n = _nz(ok)
        if not n:
            return
        if n < len(ok):
            lab, m = lab[ok], m[ok]
            if found is not None:
                found = found[0][ok], found[1][ok]
        width = self.masks.shape[1]
        if m.shape[1] != width:
            used = np.flatnonzero(m.any(axis=0))
            self._widen(int(used[-1]) + 1 if len(used) else 1)
            m = _fit(m, self.masks.shape[1])
        if len(self.keys):  # every label known (the usual case): OR in place, no re-sort
            hit, pos = self._find(lab) if found is None else found
            if _nz(hit) == len(hit):
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
        self.masks = np.bitwise_or.reduceat(allm, starts, axis=0)

    def heard(self, sender: str, labels: np.ndarray, masks: np.ndarray, k: int,
              rnd: int = 0) -> int:
        """OR in the masks (``(n, W)`` words, or ``(n,)`` int64) of decoded ``labels (n, 3)``
        from neighbour ``sender``'s estimate of scan ``k``, round ``rnd``, each cut to what it
        can vouch for: its :attr:`reach` entry at ``(k - scan + 1) * rounds + rnd`` hops (one
        hop a round since the label's scan, a round of slack for a peer a scan ahead); nothing
        on own labels; labels older than :data:`KEEP_SCANS` (no longer kept) pass, within the
        network's words. Returns the labels that lost bits not known here, also added to
        :attr:`clipped`."""
        lab = as_labels(labels)
        m = as_words(masks)
        if self.reach is None or not _nz(m):
            self.add(lab, m)
            return 0
        words = self.words  # checked: the store is as wide as the reach tables
        width = max(m.shape[1], self.masks.shape[1])
        m = _fit(m, width)
        found = self._find(lab) if len(self.keys) and len(lab) else None
        if found is not None and self.masks.shape[1] == width:  # mask_of's answer; the
            known = self.masks[found[1]]  # lookup serves _or_in below too
            if _nz(found[0]) < len(lab):
                known[~found[0]] = 0
        else:
            known = np.zeros((len(lab), width), dtype=np.int64)
            if found is not None:
                known[found[0], :self.masks.shape[1]] = self.masks[found[1][found[0]]]
        if not _nz(m & ~known):  # every bit known here already: nothing to add or count
            return 0
        table = self.reach.get(sender)
        if table is None:  # not a neighbour we know: it vouches for nothing
            allowed = np.zeros((len(lab), width), dtype=np.int64)
        else:
            h = (np.maximum(k - lab[:, 1], 0) + 1) * self.rounds + rnd
            allowed = _fit(table[np.minimum(np.maximum(h, 0), len(table) - 1)], width)
        old = lab[:, 1] < k - KEEP_SCANS
        if _nz(old):
            allowed = np.where(old[:, None], _fit(np.full((1, words), -1, dtype=np.int64),
                                                  width), allowed)
        allowed[lab[:, 0] != SHARED_ORIGIN] = 0
        kept = m & allowed
        cut = m & ~kept
        lost = int(_nz(_any_rows(cut & ~known))) if _nz(cut) else 0
        self.clipped += lost
        self._or_in(lab, kept, found)  # (n, width): m & allowed
        return lost

    def own(self, labels: np.ndarray, k: int) -> None:
        """Our published ``labels (n, 3)`` at scan ``k``: the shared ones of scan ``k`` (stamped
        by us this scan, or moved to it) take our bit."""
        lab = as_labels(labels)
        mine = lab[lab[:, 1] == k]
        self._or_in(mine, np.broadcast_to(self.bit, (len(mine), self.words)))
        if self.reach is not None:
            early = _early(lab, k)
            if _nz(early):
                self._saw_early(lab[early], self.bit)

    def sent(self, labels: np.ndarray, k: int) -> None:
        """Our estimate's ``labels (n, 3)`` of scan ``k`` in a later round: those published by
        their birth scan (a fused fresh own label of this scan) are recorded as published by
        us, first-hand, as :meth:`own` records the local estimate's; else a neighbour relaying
        it later was refused it as backdated (its stamper: us, never seen publishing it).
        Masks unchanged."""
        if self.reach is None:
            return
        lab = as_labels(labels)
        early = _early(lab, k)
        if _nz(early):
            self._saw_early(lab[early], self.bit)

    def vouched(self, sender: str, labels: np.ndarray, masks: np.ndarray, k: int,
                rnd: int = 0) -> bool:
        """Whether every label of the estimate passes :meth:`refused` (recorded and counted)."""
        return self.refused(sender, labels, masks, k, rnd) is None

    def checked(self, sender: str, labels: np.ndarray, masks: np.ndarray, k: int,
                rnd: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """``labels (n, 3)`` and ``masks`` (``(n, W)`` words or ``(n,)``) with the rows
        :meth:`refused` re-stamped to scan ``k`` (a label that loses to every older one, so the
        row stays the same target's copy, not a second track) and their masks dropped."""
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
        if table is None:
            return None
        parts = _parts(labels, masks, k, rnd, self.words, self.rounds, len(table))
        if parts is None:
            return None
        lab, early, n_early, old, n_old, lo, claim, h = parts
        if n_early:
            self._saw_early(early, table[0])  # the sender's bit
        if not n_old:
            return None
        far = claim & self._far[sender][h]
        ok = _any_rows(far)  # vouched by a far stamper: not looked up
        if _nz(ok) == n_old:
            return None
        seen = np.zeros((n_old, self.words), dtype=np.int64)
        seen[~ok] = self._seen(lo[~ok])
        ok |= _any_rows(claim & seen)
        if _nz(ok) < n_old:  # a stamp moved a scan later (uncorroborated), published after that
            moved = np.zeros(n_old, dtype=bool)
            moved[~ok] = _any_rows(self._seen(lo[~ok] - np.array([0, 1, 0])))
            ok |= moved
        if _nz(ok) == n_old:
            return None
        self.backdated += 1
        bad = np.zeros(len(lab), dtype=bool)
        bad[np.flatnonzero(old)[~ok]] = True
        return bad

    def _seen(self, lab: np.ndarray) -> np.ndarray:
        """``(n, W)`` bits of the peers seen publishing each of ``lab (n, 3)`` by its scan."""
        seen = np.zeros((len(lab), self.words), dtype=np.int64)
        if len(self._early) and len(lab):
            hit, pos = _find_rows(self._early, lab, self._rows("early", self._early))
            seen[hit] = self._early_bits[pos[hit]]
        return seen

    def _saw_early(self, lab: np.ndarray, bit: np.ndarray) -> None:
        """Record ``lab (n, 3)`` as published by the peer of ``bit`` (``(W,)`` words) at or
        before their scan."""
        if not len(lab):
            return
        if len(self._early):  # the known ones take the bit in place (a row twice: the same
            # OR), the others go in at their places (no re-sort of the store)
            hit, pos = _find_rows(self._early, lab, self._rows("early", self._early))
            n_hit = _nz(hit)
            if n_hit:
                self._early_bits[pos[hit]] |= bit
                if n_hit == len(lab):
                    return
                lab = lab[~hit]
            keys = unique_keys(label_keys(lab)) if len(lab) > 1 else label_keys(lab)
            at = np.searchsorted(self._early, keys) + np.arange(len(keys))  # in the result
            rest = np.ones(len(self._early) + len(keys), dtype=bool)
            rest[at] = False  # np.insert's arrays, without its Python-side checks
            early = np.empty(len(rest), dtype=self._early.dtype)
            early[at], early[rest] = keys, self._early
            bits = np.empty((len(rest), self.words), dtype=np.int64)
            bits[at], bits[rest] = bit, self._early_bits
            self._early, self._early_bits = early, bits
        else:
            keys = unique_keys(label_keys(lab))  # sorted, each once
            self._early, self._early_bits = keys, np.tile(bit, (len(keys), 1))

    def mask_of(self, labels: np.ndarray) -> np.ndarray:
        """``(n, W)`` mask words of ``labels (n, 3)`` (0: not known, or not shared)."""
        lab = as_labels(labels)
        out = np.zeros((len(lab), self.masks.shape[1]), dtype=np.int64)
        if not len(self.keys) or not len(lab):
            return out
        hit, pos = self._find(lab)
        out[hit] = self.masks[pos[hit]]
        return out

    def _find(self, lab: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Whether each of ``lab (n, 3)`` is in the store (non-empty) and where: ``(n,)``
        bool and index (:func:`_find_rows`)."""
        return _find_rows(self.keys, lab, self._rows("keys", self.keys))

    def _rows(self, store: str, keys: np.ndarray) -> np.ndarray:
        """``keys`` of ``store`` as :data:`_ROW` values, made once per array (:attr:`_views`)."""
        got = self._views.get(store)
        if got is None or got[0] is not keys:
            got = self._views[store] = (keys, keys.view(_ROW))
        return got[1]

    def counts(self, labels: np.ndarray) -> np.ndarray:
        """``(n,)`` holders known of each of ``labels (n, 3)`` (0: own labels)."""
        return popcount(self.mask_of(labels))

    def encode(self, labels: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """``labels (n, 3)`` for the wire: each shared row's origin carries its mask's word 0;
        and words 1 and up ``(n, W - 1)`` for the Estimate's ``label_masks`` (None: all zero,
        the usual case up to 39 peers: protocol 2 as before)."""
        lab = as_labels(labels)
        m = self.mask_of(lab)
        if not _nz(m):
            return lab, None
        out = lab
        if _nz(m[:, 0]):
            out = lab.copy()
            out[:, 0] |= (m[:, 0] & WORD) << SUPPORT_SHIFT
        extra = m[:, 1:] if m.shape[1] > 1 and _nz(m[:, 1:]) else None
        return out, extra

    def prune(self, k: int, keep: int = KEEP_SCANS) -> None:
        """Forget the masks of labels born more than ``keep`` scans before scan ``k``, or
        after it: a neighbour's label of a far-future birth scan (no honest estimate has one)
        would otherwise stay for the run, and a sender could grow the store without bound."""
        ok = np.abs(self.scans - k) <= keep
        if _nz(ok) < len(ok):
            self.keys, self.masks, self.scans = self.keys[ok], self.masks[ok], self.scans[ok]
        if len(self._early):
            ok = np.abs(_columns(self._early)[:, 1] - k) <= keep
            if _nz(ok) < len(ok):
                self._early, self._early_bits = self._early[ok], self._early_bits[ok]


__all__ = ["KEEP_SCANS", "ORIGIN_MASK", "SUPPORT_BITS", "SUPPORT_SHIFT", "WORD", "LabelSupport",
           "as_words", "decode", "mask_ints", "origin_words", "peer_bit", "popcount",
           "reach_by_name", "reach_masks", "words_for"]
