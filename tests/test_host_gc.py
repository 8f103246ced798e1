"""A peer host's collector settings (peers.host.PeerHost._loop): while its loop runs the
young generation collects at :data:`peers.host.YOUNG_GC` and the oldest only between scans
(peers.idle_gc); CPython's thresholds come back when the loop ends, also by an error."""

from __future__ import annotations

import gc

import pytest
from sensornet.peers.host import YOUNG_GC, PeerHost
from sensornet.peers.idle_gc import OFF, IdleCollector


def _host(run) -> PeerHost:
    """A host with only what ``_loop`` touches: its idle collector and ``run`` as its loop."""
    host = object.__new__(PeerHost)
    host.gc = IdleCollector()
    host._run_loop = run
    return host


def test_the_loop_runs_with_the_hosts_thresholds_and_restores_cpythons():
    saved = gc.get_threshold()
    assert saved[0] != YOUNG_GC
    seen = []
    try:
        _host(lambda: seen.append(gc.get_threshold()))._loop()
        assert seen == [(YOUNG_GC, saved[1], OFF)]
        assert gc.get_threshold() == saved

        def fails():
            seen.append(gc.get_threshold())
            raise RuntimeError("boom")

        with pytest.raises(RuntimeError, match="boom"):
            _host(fails)._loop()
        assert seen[-1] == (YOUNG_GC, saved[1], OFF) and gc.get_threshold() == saved
    finally:
        gc.unfreeze()  # _loop froze the test process's heap
        gc.set_threshold(*saved)
