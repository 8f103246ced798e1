"""Full garbage collections between scans (peers.idle_gc): automatic ones of the oldest
generation are off while a host runs; one is taken when due and the loop's idle gap fits it,
or regardless once overdue; the thresholds come back afterwards."""

from __future__ import annotations

import gc
import weakref

from sensornet.peers.idle_gc import OFF, OVERDUE, IdleCollector


def _young(n: int) -> None:
    for _ in range(n):  # each generation-1 collection counts one towards a full one
        gc.collect(1)


def test_full_collections_wait_for_an_idle_gap_that_fits():
    saved = gc.get_threshold()
    c = IdleCollector(margin_ms=5.0)
    c.start()
    try:
        assert gc.get_threshold() == (saved[0], saved[1], OFF)
        gc.collect()  # count from zero
        assert not c.due() and not c.idle(1e6)
        _young(c.every)
        assert c.due()
        c.last_ms = 20.0
        assert not c.idle(44.9)  # needs 2 x 20 + 5 ms
        assert c.due() and c.counts()["full_collections"] == 0
        assert c.idle(45.1)
        assert not c.due() and c.counts()["full_collections"] == 1
        assert c.counts()["overdue"] == 0 and c.worst_ms == c.last_ms > 0.0
        _young(OVERDUE * c.every)
        assert c.idle(0.0)  # overdue: taken even with no gap
        assert c.counts() == {"full_collections": 2, "overdue": 1,
                              "worst_ms": round(c.worst_ms, 2)}
    finally:
        c.stop()
    assert gc.get_threshold() == saved
    assert not c.due()  # stopped: nothing to do


def test_a_collection_frees_cycles_the_young_ones_left():
    """What moved to the oldest generation and then became garbage is freed by an idle
    collection (memory stays bounded), not by the young ones."""
    c = IdleCollector()
    c.start()
    try:
        class Node:
            pass

        a, b = Node(), Node()
        a.other, b.other = b, a
        _young(3)  # both now in the oldest generation
        ref = weakref.ref(a)
        del a, b
        gc.collect(1)
        assert ref() is not None  # the young collections do not reach it
        _young(OVERDUE * c.every)
        assert c.idle(0.0) and ref() is None
    finally:
        c.stop()
