"""A member that sets every bit of its shared labels' holder masks (issue 33, hostile input;
docs/security.md "Label masks"): what it does to the fused tracks on the twin, with the masks
checked where they arrive (``peers.label_support.reach_masks``, the default) and unchecked
(``label_reach`` empty, as before the check), beside the honest run both ways.

Per cell and variant: :func:`sim.studies.labelled.design_check.fused_row`'s columns (mean over
every peer, the liar's own fused tracks included: its filter and fusion are honest), the share
of the honest peers' fused track rows whose id is a label the liar stamped (``liar_ids``, %:
identities it holds; its stamps: the shared labels of its round-0 estimates of their own
scan), the estimates whose mask a receiver cut (``clipped``, summed over peers:
``rejected["label-mask"]``) and those refused their labels for a birth scan no first-hand
publication vouches for (``backdated``: ``rejected["label-scan"]``).

``python -m sensornet.sim.studies.labelled.mask_lie --runs 100 --graphs circ20 --pds 0.99``
"""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np
from sensornet.peers.core import Output, PeerCore
from sensornet.peers.label_support import ORIGIN_MASK, SUPPORT_BITS, SUPPORT_SHIFT
from sensornet.protocol.messages import Estimate
from sensornet.sim.run.peers import make_peer
from sensornet.sim.studies.labelled.design_check import COLUMNS, fused_row
from sensornet.sim.studies.labelled.ospa2_floor import GRAPHS, _overrides, cell_arguments
from sensornet.sim.studies.labelled.study import RULES, scenario_of
from sensornet.tracking.label_keys import SHARED_ORIGIN

ALL_BITS = ((1 << SUPPORT_BITS) - 1) << SUPPORT_SHIFT
"""Every holder bit, in the origin column."""
VARIANTS = ("honest-checked", "honest-unchecked", "liar-unchecked", "liar-checked",
            "forger-unchecked", "forger-checked", "backdater-unchecked", "backdater-checked")
"""``liar``: every holder bit set; ``forger``: also each shared label it stamps moved to the
next cell index, so that it ties with the label the other peers stamped and can win only by
its mask (a higher index loses a tie of equal support); ``backdater``: every shared label it
sends a scan earlier (masks as they are), which wins whatever the support unless the
receivers check birth scans (``LabelSupport.vouched``). "checked": both checks on."""


def all_bits(labels: np.ndarray, k: int | None = None) -> np.ndarray:
    """Labels on the wire ``(n, 3)`` with every holder bit set on the shared rows; with ``k``,
    the shared rows of scan ``k`` (own stamps) also moved to the next index."""
    lab = np.array(labels, dtype=np.int64, copy=True)
    shared = (lab[:, 0] & ORIGIN_MASK) == SHARED_ORIGIN
    if k is not None:
        lab[shared & (lab[:, 1] == k), 2] += 1
    lab[shared, 0] |= ALL_BITS
    return lab


def backdated(labels: np.ndarray, by: int = 1) -> np.ndarray:
    """Labels on the wire ``(n, 3)`` with every shared row's birth scan ``by`` scans earlier."""
    lab = np.array(labels, dtype=np.int64, copy=True)
    lab[(lab[:, 0] & ORIGIN_MASK) == SHARED_ORIGIN, 1] -= by
    return lab


class MaskLiarCore(PeerCore):
    """A peer that records the shared labels it stamps (those of its round-0 estimates of
    their own scan: :attr:`stamps`) and with ``lie`` (:data:`VARIANTS`' ``liar`` or ``forger``)
    sends every holder bit on each shared label (twin only; its filter and fusion stay
    honest). ``lies_told``: estimates changed."""

    def __init__(self, core: PeerCore, lie: str | None = "liar") -> None:
        super().__init__(core.cfg, core.consensus, core.scorer)
        self.lie = lie
        self.stamps: set[tuple[int, int, int]] = set()
        self.lies_told = 0

    def _wrap(self, messages: list) -> list[Output]:
        told = []
        for m in messages:
            if type(m) is Estimate and m.labels is not None and len(m.labels):
                clean = np.array(m.labels, dtype=np.int64, copy=True)
                clean[:, 0] &= ORIGIN_MASK
                if m.round == 0:
                    mine = clean[(clean[:, 0] == SHARED_ORIGIN) & (clean[:, 1] == m.k)]
                    self.stamps.update(map(tuple, mine.tolist()))
                if self.lie == "backdater":
                    m = replace(m, labels=backdated(m.labels))
                    self.lies_told += 1
                elif self.lie:
                    forge = m.k if self.lie == "forger" and m.round == 0 else None
                    m = replace(m, labels=all_bits(m.labels, forge))
                    self.lies_told += 1
            told.append(m)
        return super()._wrap(told)


def liar_share(peers: dict[str, PeerCore], liar: str, stamps: set) -> float:
    """% of the honest peers' fused track rows whose id is one of ``stamps``."""
    hit = rows = 0
    for name, core in peers.items():
        if name == liar:
            continue
        t = core.scorer.results.table(name)
        for e, ids in zip(t["estimate"], t["track_ids"], strict=True):
            if e == "fused":
                rows += len(ids)
                hit += sum(tuple(i) in stamps for i in ids)
    return 100.0 * hit / max(rows, 1)


def variant_row(scn, run: int, variant: str, liar: str) -> dict[str, float]:
    """:func:`fused_row` of one variant (:data:`VARIANTS`) with ``liar_ids`` and
    ``clipped``."""
    changes = {} if variant.endswith("-checked") else {"label_reach": ()}
    peers = {n: make_peer(scn, n, run, **changes) for n in scn.sensor_names}
    lie = variant.split("-")[0]
    peers[liar] = MaskLiarCore(peers[liar], None if lie == "honest" else lie)
    row = fused_row(scn, run, peers)
    stamps = peers[liar].stamps
    if lie == "forger":  # the labels it sent: its stamps moved
        stamps = {(o, k, i + 1) for o, k, i in stamps}
    elif lie == "backdater":  # the labels it sent: its stamps a scan earlier
        stamps = {(o, k - 1, i) for o, k, i in stamps}
    row["liar_ids"] = liar_share(peers, liar, stamps)
    row["clipped"] = float(sum(c.rejected["label-mask"] for c in peers.values()))
    row["backdated"] = float(sum(c.rejected["label-scan"] for c in peers.values()))
    return row


def main(argv: list[str] | None = None) -> int:
    ap = cell_arguments("mask_lie", __doc__, "override of the twin's scenario", kinds="lmb")
    ap.add_argument("--liar", default="p00",
                    help="the peer that lies (default p00; the last peer if absent)")
    ap.add_argument("--variants", default=",".join(VARIANTS),
                    help=f"which of {', '.join(VARIANTS)}")
    a = ap.parse_args(argv)
    extra = _overrides(a.set)
    runs = [int(x) for x in a.runs.split(",")]
    cols = (*COLUMNS, "liar_ids", "clipped", "backdated")
    t0 = time.perf_counter()
    print("| graph | kind | Pd | variant | " + " | ".join(cols) + " |")
    print("|---|---|---:|---|" + "---:|" * len(cols))
    for g in a.graphs.split(","):
        for kind in a.kinds.split(","):
            for pd in (float(x) for x in a.pds.split(",")):
                scn = scenario_of(GRAPHS[g], kind, pd, 10.0, a.scans, {**RULES[a.rule], **extra})
                liar = a.liar if a.liar in scn.sensor_names else scn.sensor_names[-1]
                for v in a.variants.split(","):
                    rows = [variant_row(scn, r, v, liar) for r in runs]
                    r = {c: float(np.max([x[c] for x in rows]) if c.endswith("_max")
                                  else np.mean([x[c] for x in rows])) for c in cols}
                    print(f"| {g} | {kind} | {pd} | {v} (liar {liar}) | "
                          + " | ".join(f"{r[c]:.3g}" for c in cols) + " |", flush=True)
    print(f"\nruns {a.runs}, {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
