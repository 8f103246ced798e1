"""A host gathering ready rounds before fusing them (``SENSORNET_HOST_GATHER_MS``).

Off (the default) the rounds of a pass are fused at its end, as before. On, they wait while
fewer than the batched peers' rounds are queued, none is forced by its deadline and the first
has waited less than the window; the loop is told when the window ends.
"""

from __future__ import annotations

from types import SimpleNamespace

import pytest
from sensornet.peers import host_batching
from sensornet.peers.host_batching import HostBatching


class Host(HostBatching):
    """The attributes of a host that the gathering reads; ``_fuse`` counted, not run."""

    def __init__(self, peers: int, jobs: list) -> None:
        self.batch = SimpleNamespace(jobs=jobs)
        self._batched = frozenset(range(peers))
        self._active = list(range(peers))
        self._stop = False
        self.fused = 0

    def _fuse(self) -> None:
        self.fused += 1
        self.batch.jobs = []


def _jobs(n: int, forced: bool = False, settled: int = 0) -> list:
    return [SimpleNamespace(forced=forced and i == 0, settled=i < settled) for i in range(n)]


@pytest.fixture
def clock(monkeypatch):
    t = [100.0]
    monkeypatch.setattr(host_batching.time, "monotonic", lambda: t[0])
    return t


def test_off_fuses_every_pass(monkeypatch, clock):
    monkeypatch.setattr(host_batching, "GATHER_MS", 0.0)
    h = Host(4, _jobs(1))
    h._fuse_gathered()
    assert h.fused == 1 and h._gather_left(clock[0]) is None
    h._fuse_gathered()  # nothing waiting: nothing to fuse
    assert h.fused == 1


def test_on_waits_for_more_rounds_up_to_the_window(monkeypatch, clock):
    monkeypatch.setattr(host_batching, "GATHER_MS", 5.0)
    h = Host(4, _jobs(2))
    h._fuse_gathered()
    assert h.fused == 0 and h._gather_left(clock[0]) == pytest.approx(0.005)
    clock[0] += 0.003
    h.batch.jobs = _jobs(3)  # a third round became ready meanwhile
    h._fuse_gathered()
    assert h.fused == 0 and h._gather_left(clock[0]) == pytest.approx(0.002)
    clock[0] += 0.0025  # the first has waited the whole window
    h._fuse_gathered()
    assert h.fused == 1 and h._gather_left(clock[0]) is None


@pytest.mark.parametrize("case", ["every peer", "forced", "stopping"])
def test_on_fuses_at_once_when_no_more_can_come_or_one_must_go(monkeypatch, clock, case):
    monkeypatch.setattr(host_batching, "GATHER_MS", 5.0)
    h = Host(4, _jobs(4) if case == "every peer" else _jobs(2, forced=case == "forced"))
    h._stop = case == "stopping"
    h._fuse_gathered()
    assert h.fused == 1


def test_peers_that_ended_are_not_waited_for(monkeypatch, clock):
    """Two rounds queued, four batched peers of which two ended: nothing more can come."""
    monkeypatch.setattr(host_batching, "GATHER_MS", 5.0)
    h = Host(4, _jobs(2))
    h._active = [0, 2]
    h._fuse_gathered()
    assert h.fused == 1


def test_settled_rounds_do_not_count(monkeypatch, clock):
    """Rounds settled on the spot meanwhile (their peer needed them at once) are not
    among those waiting: four queued, two settled, four peers: still gathering."""
    monkeypatch.setattr(host_batching, "GATHER_MS", 5.0)
    h = Host(4, _jobs(4, settled=2))
    h._fuse_gathered()
    assert h.fused == 0


def test_the_setting_is_read_or_refused_in_one_line():
    assert host_batching.gather_ms(None) == 0.0 and host_batching.gather_ms("") == 0.0
    assert host_batching.gather_ms("5") == 5.0
    for bad in ("abc", "-1", "nan", "inf", "1e9"):
        with pytest.raises(ValueError, match="SENSORNET_HOST_GATHER_MS"):
            host_batching.gather_ms(bad)
