"""The peer's lifecycle tables (peers.core_lifecycle): every listed transition is reached by a
sequence of real inputs to a PeerCore, and a transition the tables do not list is refused."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from sensornet.peers.core import Stop
from sensornet.peers.core_lifecycle import (
    SCAN_TABLE,
    WORLD_TABLE,
    Event,
    Lifecycle,
    LifecycleError,
    Numbering,
    ScanEvent,
    World,
)
from sensornet.protocol.codec import encode
from sensornet.protocol.keys import Keys
from sensornet.protocol.messages import Control, Scan
from sensornet.sim.run.peers import make_peer
from sensornet.sim.scenario import load_scenario

KEYS = Keys("life")


def _core(grace: float):
    core = make_peer(load_scenario("seed000"), "s1", 0, network="life")
    core.cfg = replace(core.cfg, world_grace=grace)
    return core


def _end(core, now: float):
    return core.receive(KEYS.ctl(), encode(Control("end", "w")), now)


def _scan(core, k: int, now: float):
    return core.receive(KEYS.scan("s1"), encode(Scan("s1", k, np.zeros((0, 2)))), now)


def _join(core, now: float):
    return core.liveliness("world", True, now)


def _leave(core, now: float):
    return core.liveliness("world", False, now)


SEQUENCES = {
    # name: (grace, the inputs in order, each a function of the core and the time)
    "outage and back, end, leave, rejoin": (5.0, [
        _leave, _join, _join, _leave, _leave, _join, _end, _end, _join, _leave, _leave, _end,
        _join]),
    "the grace runs out, rejoin, end in an outage": (5.0, [
        _join, _leave, lambda c, t: c.tick(t + 10.0), _leave, _join, _leave, _end]),
    "end before the world is seen": (5.0, [_end, _end, _leave, _join]),
    "no grace": (0.0, [_leave, _join, _leave, _leave, _end, _leave, _join, _leave]),
    "no grace, end before the world is seen": (0.0, [_end, _leave, _join]),
}


def test_every_transition_of_the_tables_is_reached_by_some_input_sequence():
    taken: set = set()
    for grace, steps in SEQUENCES.values():
        core = _core(grace)
        for i, step in enumerate(steps):
            step(core, float(i))
        taken |= set(core.life.taken)
    core = _core(5.0)
    _join(core, 0.0)
    _scan(core, 1, 0.0)  # the first scan anchors the numbering
    _scan(core, 2, 0.1)  # the next
    far = 2 + core.cfg.horizon + 5
    _scan(core, far, 0.1 + 10 * core.cfg.quiet * core.cfg.interval)  # after a quiet spell
    assert core.reanchored == 1 and core.first_k == 1
    taken |= set(core.life.taken)
    missing = (set(WORLD_TABLE) | set(SCAN_TABLE)) - taken
    assert not missing, sorted((s.value, e.value) for s, e in missing)


def test_the_states_say_what_the_old_attributes_said():
    core = _core(5.0)
    assert (core.world, core.end_requested) == ("unseen", False)
    _join(core, 0.0)
    _leave(core, 1.0)
    assert core.life.world is World.OUTAGE and core.world == "alive"  # within the grace
    assert _stops(_end(core, 1.5)) == [Stop("end of run")]
    assert core.life.world is World.ENDED and (core.world, core.end_requested) == ("left", True)


def _stops(outputs) -> list[Stop]:
    return [o for o in outputs if isinstance(o, Stop)]


def test_a_transition_the_tables_do_not_list_is_refused():
    life = Lifecycle()
    with pytest.raises(LifecycleError, match="no transition from waiting on grace-over"):
        life.step(Event.GRACE_OVER)
    assert life.world is World.WAITING and life.taken == {}  # nothing taken
    life.step(Event.JOINED)
    life.step(Event.LOST)
    with pytest.raises(LifecycleError, match="outage on left"):
        life.step(Event.LEFT)
    with pytest.raises(LifecycleError, match="unanchored on next"):
        life.scan(ScanEvent.NEXT)
    assert life.numbering is Numbering.UNANCHORED


def test_every_event_the_network_can_bring_is_listed_in_every_state():
    network = (Event.JOINED, Event.END)  # a token's going is LOST or LEFT by configuration
    for state in World:
        for event in network:
            assert (state, event) in WORLD_TABLE, (state, event)
        assert (state, Event.LOST) in WORLD_TABLE
        assert (state, Event.LEFT) in WORLD_TABLE or state is World.OUTAGE
