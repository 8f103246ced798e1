"""A peer's lifecycle as explicit states and transition tables (in the style of h11's
``_state.py``): what the world's liveliness token and its "end" have told the peer, and whether
its scan numbering has been anchored.

:class:`peers.core.PeerCore` turns its inputs into :class:`Event` values, asks
:meth:`Lifecycle.step` for the next state and carries out the :class:`Action` the table names
(finish and stop, open or close an outage, count an early "end"). A pair the table does not
list is a bug in the caller, not something a message can cause: every event the network can
deliver is listed for every state, and :class:`LifecycleError` is raised for the rest.
"""

from __future__ import annotations

from enum import Enum


class World(Enum):
    """What this peer knows of the world process and the run's end."""

    WAITING = "waiting"
    """The world's token not seen yet."""
    WAITING_ENDED = "waiting-ended"
    """An "end" came before the world's token was seen (reordered): its leaving stops."""
    RUNNING = "running"
    """The world's token is there."""
    OUTAGE = "outage"
    """Its token went away without an "end": within the grace it may come back (an outage)."""
    ENDING = "ending"
    """An "end" came and the world is still there: the peer stops when it leaves."""
    STOPPED = "stopped"
    """The world left before ending the run (Stop sent)."""
    ENDED = "ended"
    """The world left after its "end" (Stop "end of run" sent)."""


class Event(Enum):
    JOINED = "joined"
    """The world's token appeared."""
    LOST = "lost"
    """The world's token went away and a grace applies (``CoreConfig.grace() > 0``)."""
    LEFT = "left"
    """The world's token went away, no grace."""
    GRACE_OVER = "grace-over"
    """The grace after :attr:`LOST` ran out without the token coming back."""
    END = "end"
    """A ``ctl`` "end" arrived."""


class Action(Enum):
    NONE = "none"
    OUTAGE_START = "outage-start"
    """Remember when the token went (the grace counts from then)."""
    OUTAGE_END = "outage-end"
    """Back within the grace: record the outage."""
    STOP_EARLY = "stop-early"
    """Finish and stop: "world left before ending the run"."""
    STOP_END = "stop-end"
    """Finish and stop: "end of run"."""
    END_EARLY = "end-early"
    """An "end" while the world is still there: counted, the peer waits for it to leave."""


W, E, A = World, Event, Action
WORLD_TABLE: dict[tuple[World, Event], tuple[World, Action]] = {
    (W.WAITING, E.JOINED): (W.RUNNING, A.NONE),
    (W.WAITING, E.LOST): (W.WAITING, A.NONE),
    (W.WAITING, E.LEFT): (W.WAITING, A.NONE),
    (W.WAITING, E.END): (W.WAITING_ENDED, A.END_EARLY),
    (W.WAITING_ENDED, E.JOINED): (W.ENDING, A.NONE),
    (W.WAITING_ENDED, E.LOST): (W.WAITING_ENDED, A.NONE),
    (W.WAITING_ENDED, E.LEFT): (W.WAITING_ENDED, A.NONE),
    (W.WAITING_ENDED, E.END): (W.WAITING_ENDED, A.END_EARLY),
    (W.RUNNING, E.JOINED): (W.RUNNING, A.NONE),
    (W.RUNNING, E.LOST): (W.OUTAGE, A.OUTAGE_START),
    (W.RUNNING, E.LEFT): (W.STOPPED, A.STOP_EARLY),
    (W.RUNNING, E.END): (W.ENDING, A.END_EARLY),
    (W.OUTAGE, E.JOINED): (W.RUNNING, A.OUTAGE_END),
    (W.OUTAGE, E.LOST): (W.OUTAGE, A.NONE),
    (W.OUTAGE, E.GRACE_OVER): (W.STOPPED, A.STOP_EARLY),
    # its token went first (Zenoh sends declarations at a higher priority than data, so a
    # starved world's "end" can come after): the world has ended the run, as if it left now
    (W.OUTAGE, E.END): (W.ENDED, A.STOP_END),
    (W.ENDING, E.JOINED): (W.ENDING, A.NONE),
    (W.ENDING, E.LOST): (W.ENDED, A.STOP_END),
    (W.ENDING, E.LEFT): (W.ENDED, A.STOP_END),
    (W.ENDING, E.END): (W.ENDING, A.END_EARLY),
    (W.STOPPED, E.JOINED): (W.RUNNING, A.NONE),
    (W.STOPPED, E.LOST): (W.STOPPED, A.NONE),
    (W.STOPPED, E.LEFT): (W.STOPPED, A.NONE),
    (W.STOPPED, E.END): (W.ENDED, A.NONE),
    (W.ENDED, E.JOINED): (W.ENDING, A.NONE),
    (W.ENDED, E.LOST): (W.ENDED, A.NONE),
    (W.ENDED, E.LEFT): (W.ENDED, A.NONE),
    (W.ENDED, E.END): (W.ENDED, A.NONE),
}
"""Every legal ``(state, event) -> (next state, action)`` of the world's lifecycle. Not listed
(a bug): :attr:`Event.GRACE_OVER` outside an outage, :attr:`Event.LEFT` in an outage (the grace
is a constant of the configuration)."""


class Numbering(Enum):
    """Whether this peer has a scan numbering to follow."""

    UNANCHORED = "unanchored"
    """No scan accepted yet."""
    ANCHORED = "anchored"
    """Following the numbering of the first scan accepted (or of a re-anchoring)."""


class ScanEvent(Enum):
    FIRST = "first"
    """The first scan accepted: its index anchors the numbering."""
    NEXT = "next"
    """A scan within the horizon after the last one."""
    REANCHOR = "reanchor"
    """After a quiet spell, a scan outside the horizon: a pause or a new numbering."""


N, S = Numbering, ScanEvent
SCAN_TABLE: dict[tuple[Numbering, ScanEvent], Numbering] = {
    (N.UNANCHORED, S.FIRST): N.ANCHORED,
    (N.ANCHORED, S.NEXT): N.ANCHORED,
    (N.ANCHORED, S.REANCHOR): N.ANCHORED,
}
"""Every legal scan-numbering transition (a refused scan, stale or future, is none)."""

STOP_REASONS = {A.STOP_EARLY: "world left before ending the run", A.STOP_END: "end of run"}
"""The :class:`peers.core_types.Stop` reason of each stopping action."""


class LifecycleError(RuntimeError):
    """A transition the tables do not list (a bug in the caller)."""


class Lifecycle:
    """The current states and the transitions taken (counted per ``(state, event)``)."""

    def __init__(self) -> None:
        self.world = World.WAITING
        self.numbering = Numbering.UNANCHORED
        self.taken: dict[tuple[Enum, Enum], int] = {}
        """Transitions taken so far, per ``(state, event)`` (tests: every row reachable)."""

    def step(self, event: Event) -> Action:
        """Take the world's transition for ``event``; the action to carry out."""
        try:
            nxt, action = WORLD_TABLE[(self.world, event)]
        except KeyError:
            raise LifecycleError(f"no transition from {self.world.value} on "
                                 f"{event.value}") from None
        self._count(self.world, event)
        self.world = nxt
        return action

    def scan(self, event: ScanEvent) -> None:
        """Take the scan numbering's transition for ``event``."""
        try:
            nxt = SCAN_TABLE[(self.numbering, event)]
        except KeyError:
            raise LifecycleError(f"no transition from {self.numbering.value} on "
                                 f"{event.value}") from None
        self._count(self.numbering, event)
        self.numbering = nxt

    def _count(self, state: Enum, event: Enum) -> None:
        self.taken[(state, event)] = self.taken.get((state, event), 0) + 1

    @property
    def world_seen(self) -> str:
        """``"unseen"``, ``"alive"`` or ``"left"`` (the summary's and the old attribute's)."""
        if self.world in (W.WAITING, W.WAITING_ENDED):
            return "unseen"
        return "left" if self.world in (W.STOPPED, W.ENDED) else "alive"

    @property
    def end_requested(self) -> bool:
        """Whether the world has sent its "end"."""
        return self.world in (W.WAITING_ENDED, W.ENDING, W.ENDED)
