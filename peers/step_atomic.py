"""A labelled estimator's step is all or nothing (issue 33, robustness).

A GM-PHD peer's step changes its mixture, its labels and the label bookkeeping beside them
(:class:`tracking.labels.Publication`, :class:`tracking.reidentify.Reidentification`,
:class:`peers.stamp_moves.MovingStamps`); an LMB peer's step its state, its publication memory
and its filter's Gibbs stream. One exception half-way (an IndexError in the re-identification,
0156cca) left the labels out of step with the components for the rest of the run: 32 counted
internal errors, the peer alive but not fusing. :func:`atomic` makes a method commit only when
it completes: it keeps each part's attributes (references, a shallow copy of ``__dict__``) and
its Generators' states, and puts them back if the method raises, so the next scan steps from
the state before the failing one, as if that scan had never come.

References suffice because these methods never write into an array they hold: they compute
new arrays and rebind attributes (tests/test_step_atomic.py checks the arrays after a failure
at several points of a step). Cost: a dict copy per part and one Generator state per step
(``python benchmarks/bench_step_atomic.py``).
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Iterable
from typing import Protocol, TypeVar

import numpy as np

F = TypeVar("F", bound=Callable)


class Atomic(Protocol):
    """What :func:`atomic` needs of the object whose method it wraps."""

    def atomic_parts(self) -> Iterable[object | None]:
        """The objects a step may change (itself first; None entries are skipped)."""

    def atomic_streams(self) -> Iterable[np.random.Generator | None]:
        """The random Generators a step may draw from."""


def snapshot(owner: Atomic) -> tuple[list[tuple[object, dict]], list[tuple[object, dict]]]:
    """``owner``'s parts' attributes and its Generators' states, to :func:`restore`."""
    parts = [(p, p.__dict__.copy()) for p in owner.atomic_parts() if p is not None]
    streams = [(g.bit_generator, g.bit_generator.state) for g in owner.atomic_streams()
               if g is not None]
    return parts, streams


def restore(saved: tuple[list[tuple[object, dict]], list[tuple[object, dict]]]) -> None:
    """Put back what :func:`snapshot` kept (attributes added since are dropped)."""
    parts, streams = saved
    for p, attrs in parts:
        p.__dict__.clear()
        p.__dict__.update(attrs)
    for bg, state in streams:
        bg.state = state


def atomic(method: F) -> F:
    """``method`` of an :class:`Atomic` object, committing only when it returns: if it raises,
    every part is as before the call (then the exception goes on, to be counted by the
    caller as before: ``peers.consensus.Consensus.on_scan``)."""

    @functools.wraps(method)
    def run(self, *args, **kwargs):
        saved = snapshot(self)
        try:
            return method(self, *args, **kwargs)
        except BaseException:
            restore(saved)
            raise

    return run  # type: ignore[return-value]


__all__ = ["Atomic", "atomic", "restore", "snapshot"]
