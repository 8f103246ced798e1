"""The world's "end" and its leaving, in either order: the run ended (issue 37).

The world puts ``ctl`` "end", then undeclares its liveliness token. Zenoh sends declarations at
a higher priority than data, so on a loaded machine the token's going can reach a peer before
the "end" (seen as "world left before ending the run" in a 5-process test under load 5-10):
within the world's grace an "end" that comes after the token went ends the run as one before.
"""

from __future__ import annotations

from dataclasses import replace

from sensornet.peers.core import Stop
from sensornet.protocol.codec import encode
from sensornet.protocol.keys import Keys
from sensornet.protocol.messages import Control
from sensornet.sim.run.peers import make_peer
from sensornet.sim.scenario import load_scenario


def _core(grace: float):
    core = make_peer(load_scenario("seed000"), "s1", 0, network="order")
    core.cfg = replace(core.cfg, world_grace=grace)
    return core


def _stops(outputs) -> list[Stop]:
    return [o for o in outputs if isinstance(o, Stop)]


def test_an_end_after_the_world_left_ends_the_run_at_once():
    core = _core(5.0)
    assert core.liveliness("world", True, 0.0) == []
    assert core.liveliness("world", False, 1.0) == []  # within the grace: maybe an outage
    end = encode(Control("end", "r", {"last_k": 3}))
    assert _stops(core.receive(Keys("order").ctl(), end, 1.1)) == [Stop("end of run")]
    assert core.next_due() is None and not _stops(core.tick(10.0))  # no second stop later
    assert core.world_outages == [] and core.ctl_end_early == 0
    assert core.end_k is None  # finish() scored the world's last scans (misses here)


def test_an_end_before_the_world_left_still_waits_for_it_to_leave():
    core = _core(5.0)
    core.liveliness("world", True, 0.0)
    assert not _stops(core.receive(Keys("order").ctl(), encode(Control("end", "r")), 0.5))
    assert core.ctl_end_early == 1
    assert _stops(core.liveliness("world", False, 1.0)) == [Stop("end of run")]


def test_without_an_end_the_grace_still_runs_out():
    core = _core(5.0)
    core.liveliness("world", True, 0.0)
    core.liveliness("world", False, 1.0)
    assert not _stops(core.tick(5.9))
    assert _stops(core.tick(6.0)) == [Stop("world left before ending the run")]
