"""Track tables of a twin run's labelled peers, for the labelled-peer tests (one copy)."""

from __future__ import annotations

import numpy as np
from sensornet.sim.studies.labelled.study import peer_tables
from sensornet.tracking.track_metrics import TrackTable


def twin_tables(twin, names, which: str, confirmed: bool = False):
    """Per peer a TrackTable of its ``which`` tracks (ids coded to ints, shared by all peers:
    :func:`sim.studies.labelled.study.peer_tables`) and the truth's table, after checking that
    every row of every peer's results table carries one id and one status per track and one
    id per true target."""
    truth = None
    for p in names:
        t = twin.peers[p].scorer.results.table(p)
        TS, TI, TX = [], [], []
        for k, e, tr, ids, st, tru, tids in zip(t["scan"], t["estimate"], t["tracks"],
                                                t["track_ids"], t["track_status"], t["truth"],
                                                t["truth_ids"], strict=True):
            if e != which:
                continue
            assert len(ids) == len(tr) and len(st) == len(tr) and len(tids) == len(tru)
            TS += [k] * len(tru)
            TI += list(tids)
            TX += [[x[0], x[2]] for x in tru]
        truth = TrackTable(np.array(TS), np.array(TI), np.array(TX).reshape(-1, 2))
    return peer_tables(twin, list(names), which, {}, confirmed), truth
