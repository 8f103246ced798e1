"""A measured prototype of the label release proposed for :mod:`peers.labelling` (issue 34).

The defect (traced with :mod:`.switches` on Paris 12:00-13:00 UTC, docs/real-traffic.md): a
label two fused components both win (two aircraft whose tracks carry the same id at different
peers) stays with the heavier; :func:`peers.labelling.label_fused` gives the lighter a fresh
label ``(origin, k, FRESH_BASE + i)`` and tells no estimator, so the peers' tracks of the
lighter aircraft keep the duplicated id and the next scan does the same: a new fresh id every
scan, and the heavier side alternates between the two aircraft (654 of the fused LMB's 654
switches at CDG in that hour, on 3 pairs of aircraft).

The release: an own track paired with a component that lost its label that way takes the
component's fresh label (its pair goes into ``FusedLabels.own`` flagged with cost -1), and the
estimators' ``adopt_labels`` applies flagged pairs whatever the earliest-birth rule says
(a fresh label is later than the one it replaces), unless the fresh label is already one of
the estimator's. The peers' fresh labels of one aircraft then meet at the next scan and the
earliest wins, as for any new target.

Here the two functions are installed by replacing the names the consensus and the estimators
import (measurement only; the change belongs in :mod:`peers.labelling` and
:mod:`tracking.label_matching`)::

    python -m sensornet.sim.studies.traffic.heal_prototype MODULE [ARGS ...]

runs ``python -m MODULE ARGS`` with the release installed (e.g. ``sensornet.sim.studies.
traffic.study`` with ``--jobs 1``: worker processes would not have it).
"""

from __future__ import annotations

import runpy
import sys

import numpy as np
import sensornet.peers.consensus as consensus
import sensornet.peers.estimators as estimators
import sensornet.peers.labelling as labelling
import sensornet.peers.lmb_estimator as lmb_estimator
from sensornet.tracking.label_matching import LabelMatch
from sensornet.tracking.label_matching import adopt_labels as _adopt
from sensornet.tracking.labels import label_keys

_label_fused = labelling.label_fused

RELEASE = -1.0
"""The cost that flags a release pair in a :class:`LabelMatch`."""


def label_fused(fused, inputs, origin: int, k: int, fresh_start: int = 0,
                gate: float = labelling.LABEL_GATE, **kw) -> labelling.FusedLabels:
    """:func:`peers.labelling.label_fused` (whatever its other keywords), and the release
    pairs (module docstring) added to ``own`` with cost :data:`RELEASE`: an own track paired
    with a row that ends with a fresh label. A row paired with any input wins a label, so a
    paired row with a fresh one lost its label to a heavier row."""
    out = _label_fused(fused, inputs, origin, k, fresh_start, gate=gate, **kw)
    t_lab, t_m, t_P, t_src = labelling._all_tracks(inputs)
    if not len(fused) or not len(t_lab):
        return out
    J, t = labelling._pairs(fused, t_m, t_P, t_src, gate)
    lab = out.labels[J]
    rel = ((t_src[t] == 0) & (lab[:, 0] == origin) & (lab[:, 1] == k)
           & (lab[:, 2] >= labelling.FRESH_BASE))
    if not rel.any():
        return out
    own = out.own
    match = LabelMatch(np.concatenate([own.own, t_lab[t[rel]]]),
                       np.concatenate([own.nbr, lab[rel]]),
                       np.concatenate([own.cost, np.full(int(rel.sum()), RELEASE)]))
    return labelling.FusedLabels(out.labels, match, out.fresh)


def adopt_labels(labels: np.ndarray, match: LabelMatch) -> np.ndarray:
    """:func:`tracking.label_matching.adopt_labels` for the unflagged pairs; a release pair's
    own label replaced by its fresh label on every row that carries it, unless the fresh
    label is already there."""
    rel = match.cost == RELEASE
    out = _adopt(labels, LabelMatch(match.own[~rel], match.nbr[~rel], match.cost[~rel]))
    if not rel.any() or not len(out):
        return out
    keys = label_keys(out)
    own_k, new = label_keys(match.own[rel]), match.nbr[rel]
    ok = ~np.isin(label_keys(new), keys)
    own_k, new = own_k[ok], new[ok]
    if not len(own_k):
        return out
    by = np.argsort(own_k)
    pos = np.searchsorted(own_k[by], keys).clip(max=len(own_k) - 1)
    hit = own_k[by][pos] == keys
    out = out.copy()
    out[hit] = new[by][pos[hit]]
    return out


def install() -> None:
    """Replace the names the consensus and the estimators call (this process only)."""
    consensus.label_fused = label_fused
    estimators.adopt_labels = adopt_labels
    lmb_estimator.adopt_labels = adopt_labels


def main(argv: list[str] | None = None) -> None:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv:
        raise SystemExit("usage: python -m sensornet.sim.studies.traffic.heal_prototype "
                         "MODULE [ARGS ...]")
    install()
    sys.argv = argv
    runpy.run_module(argv[0], run_name="__main__", alter_sys=True)


if __name__ == "__main__":
    main()
