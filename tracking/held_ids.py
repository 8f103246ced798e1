"""A young fused label does not replace the id a peer reported a target under a scan or two
before (issue 34, docs/real-traffic.md, "The tentative route's switches traced").

With LMB peers publishing their unconfirmed tracks (``lmb.tentative_threshold``) a fused row
can be reported from two one-plot tracks of far radars, their existences pooled
(``tracking.support.pooled_weights``). Traced on paris-8's training hour: an aircraft reported
for a few scans under ``L`` (three radars' own tracks, its AA weight 0.3-0.5 by the mean over
eight inputs, so reported only some scans) sat beside a new fused row of two radars' one-plot
tracks (``r`` 0.1 each, pooled 0.55) under a label ``L'`` born that scan; the new row was
reported, ``L`` was not, and the aircraft's id changed (at every peer; ``fusion.label_keep``
then kept ``L'``, and ``L`` came back 140 scans later: a second switch).

:class:`HeldIds` acts on the extracted rows only (the fused density, its labels and what
neighbours are sent are unchanged): a reported row whose label was born at most ``young``
scans ago and that this peer has not reported in the last ``memory`` scans is reported under
a label it did report then, born earlier, not reported this scan, whose row of the fused
density lies within ``gate`` of it; paired one to one by SciPy ``linear_sum_assignment`` on the
squared Mahalanobis distance ``(x - m)' (P + S)^-1 (x - m)`` (Y. Bar-Shalom, "On the
track-to-track correlation problem", IEEE TAC 26(2), 1981, without the cross-covariance).
The id a peer shows is then the one it showed; the next scan's label rule pairs the row with
that label (``peers.labelling.label_fused``, with ``fusion.label_keep`` the reported label
first) and the earlier label wins it by the network rule, at this peer and its neighbours.

:class:`ReportedIds` is the memory of the ids a peer reported in its last few scans, which
:class:`HeldIds` looks up and which ``fusion.label_keep_scans`` gives ``fusion.label_keep``'s
veto (``peers.labelling.kept_first``): traced on paris-8's training hour (aircraft 392af3 at
tick 774), a mature row every radar but one held was pooled below 0.5 and not reported for one
scan; with only the scan before's ids to keep, the next scan an en-route radar's remnant of
another aircraft's label, born 289 scans earlier, won the row by the earliest-birth rule (a
switch at every peer). Kept over the last N scans the reported label survives a one-scan drop.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import linear_sum_assignment
from sensornet.tracking.gaussian import inv_spd
from sensornet.tracking.label_keys import keys_find, keys_isin, label_keys
from sensornet.tracking.label_twins import check_hold


@dataclass
class ReportedIds:
    """The ids a peer reported at each of its last ``scans`` scans (sorted label keys and the
    scan each was last reported at): :meth:`remember` once per scan, :meth:`recent` the keys
    reported at scans ``j`` with ``k - j <= scans``, for a scan ``k`` after them."""

    scans: int = 3
    keys: np.ndarray = field(default_factory=lambda: label_keys(np.zeros((0, 3), np.int64)),
                             repr=False)
    last: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64), repr=False)

    def __post_init__(self) -> None:
        if isinstance(self.scans, bool) or not isinstance(self.scans, (int, np.integer)) \
                or self.scans < 1:
            raise ValueError(f"reported ids' memory must be an integer >= 1 scans, got "
                             f"{self.scans!r}")

    def recent(self, k: int) -> np.ndarray:
        """Sorted keys of the ids reported at scans ``k - scans .. k`` (at most ``scans`` ago)."""
        return self.keys[k - self.last <= self.scans] if len(self.keys) else self.keys

    def union(self, k: int, keys: np.ndarray) -> np.ndarray:
        """Sorted unique keys of ``keys`` (e.g. the last scan's, whenever it was) and
        :meth:`recent` at ``k``: what ``fusion.label_keep`` keeps with ``label_keep_scans``."""
        return np.union1d(keys, self.recent(k))

    def remember(self, k: int, ids: np.ndarray) -> None:
        """Keep ``ids (r, 3)`` as reported at ``k``; forget ids not reported for ``scans``
        scans (they are no longer recent at ``k + 1``)."""
        new = np.unique(label_keys(np.asarray(ids, dtype=np.int64).reshape(-1, 3)))
        keep = (k - self.last < self.scans) if len(self.keys) else np.zeros(0, dtype=bool)
        keys, last = self.keys[keep], self.last[keep]
        if len(keys) and len(new):
            seen, _ = keys_find(new, keys)
            keys, last = keys[~seen], last[~seen]
        keys = np.concatenate([keys, new])
        last = np.concatenate([last, np.full(len(new), k, dtype=np.int64)])
        order = np.argsort(keys)
        self.keys, self.last = keys[order], last[order]


@dataclass
class HeldIds:
    """A peer's memory of the ids it reported and the rule of the module docstring. One per
    peer; call :meth:`ids` once per scan with the scan's extracted rows and fused density.
    ``memory``: scans an id is remembered after it was last reported; ``young``: the oldest
    label (scans since its birth scan) that can be reported under a remembered id; ``gate``:
    the squared Mahalanobis distance of a row and the remembered id's fused row."""

    memory: int = 3
    young: int = 2
    gate: float = 26.0
    sub_from: np.ndarray = field(default_factory=lambda: label_keys(np.zeros((0, 3), np.int64)),
                                 repr=False)
    sub_to: np.ndarray = field(default_factory=lambda: np.zeros((0, 3), dtype=np.int64),
                               repr=False)

    def __post_init__(self) -> None:
        check_hold(self.gate, memory=(self.memory, 1), young=(self.young, 0))
        self.reported = ReportedIds(self.memory)
        """The ids this peer reported in its last ``memory`` scans."""

    def ids(self, k: int, ids: np.ndarray, means: np.ndarray, covs: np.ndarray,
            labels: np.ndarray, f_means: np.ndarray, f_covs: np.ndarray) -> np.ndarray:
        """The ids ``(r, 3)`` to report at scan ``k`` for the extracted rows ``ids (r, 3)``,
        ``means (r, d)``, ``covs (r, d, d)``, given the fused density's ``labels (n, 3)``,
        ``f_means (n, d)``, ``f_covs (n, d, d)``; remembers them as reported at ``k``. A row
        reported under another id keeps it while its label is reported and that id's own
        label is not (the label rule hands the row the earlier id within a scan or two)."""
        ids = np.asarray(ids, dtype=np.int64).reshape(-1, 3)
        out = ids.copy()
        rk = label_keys(ids)
        done = np.zeros(len(ids), dtype=bool)
        if len(self.sub_from) and len(ids):  # last scan's substitutions, still apart
            found, pos = keys_find(self.sub_from, rk)
            to = self.sub_to[pos]
            done = found & ~keys_isin(label_keys(to), rk)
            out[done] = to[done]
        recent = self.reported.recent(k)
        if len(ids) and len(recent) and len(labels):
            lk = label_keys(np.asarray(labels, dtype=np.int64))
            row = np.flatnonzero((k - ids[:, 1] <= self.young) & ~keys_isin(rk, recent)
                                 & ~done)
            col = np.flatnonzero(keys_isin(lk, recent) & ~keys_isin(lk, rk)
                                 & ~keys_isin(lk, label_keys(out[done])))
            if len(row) and len(col):
                got = self._pair(ids, means, covs, row, labels, f_means, f_covs, col)
                new = (got != ids).any(axis=1)  # only rows of ``row``, none of them done
                out[new] = got[new]
                done |= new
        order = np.argsort(rk[done])
        self.sub_from, self.sub_to = rk[done][order], out[done][order]
        self.reported.remember(k, out)
        return out

    def _pair(self, ids, means, covs, row, labels, f_means, f_covs, col) -> np.ndarray:
        """``ids`` with each row of ``row`` paired (assignment, within the gate) to a fused
        row of ``col`` whose label is born before its own taking that label."""
        diff = np.asarray(means)[row][:, None] - np.asarray(f_means)[col][None]  # (a, b, d)
        S = inv_spd(np.asarray(covs)[row][:, None] + np.asarray(f_covs)[col][None])
        q = np.einsum("abi,abij,abj->ab", diff, S, diff)
        ok = (q <= self.gate) & (labels[col, 1][None, :] < ids[row, 1][:, None])
        if not ok.any():
            return ids
        r, c = linear_sum_assignment(np.where(ok, q, self.gate + 1.0))
        hit = ok[r, c]
        out = ids.copy()
        out[row[r[hit]]] = labels[col[c[hit]]]
        return out


__all__ = ["HeldIds", "ReportedIds"]
