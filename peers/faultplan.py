"""The typed link-fault plan: delay laws, the faults of one link, and the plan of a network.

Plain frozen (hashable, picklable) values, built by the scenario loader from a ``[faults]``
table (:func:`sim.scenario.load_scenario`; the syntax and its one-line errors live there) and
read by the injector (:mod:`peers.faults`). Nothing here parses text, draws a decision or
knows a message type.

Layering (:meth:`FaultPlan.layered`): for the link ``s -> r``, the last of ``default``,
``peers.s`` (every link out of ``s``), ``peers.r`` (every link into ``r``) and the link entry
``s -> r`` that sets a key wins; partitions of all these layers are joined, since a link is
down whenever either end, or the whole network, is cut off.

Delays in scan intervals (the papers' "short", "one-step", "multi-step" and random-scan
delays, docs/algorithms.md "NALE") carry the scan interval they were built with and sample seconds
like the others.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field, fields
from typing import Any, Protocol

import numpy as np

# --------------------------------------------------------------------------------------------
# Delay laws (seconds)
# --------------------------------------------------------------------------------------------


class Delay(Protocol):
    """A delay law: ``sample(rng)`` is one delay (s), ``sample(rng, n)`` an ``(n,)`` array."""

    def sample(self, rng: np.random.Generator, n: int | None = None) -> float | np.ndarray: ...

    @property
    def mean(self) -> float: ...


def _check(ok: bool, problem: str) -> None:
    if not ok:
        raise ValueError(problem)


def _nonneg(name: str, value: float) -> None:
    _check(math.isfinite(value) and value >= 0, f"{name} must be finite and >= 0, got {value!r}")


def _positive(name: str, value: float) -> None:
    _check(math.isfinite(value) and value > 0, f"{name} must be finite and > 0, got {value!r}")


def _steps(name: str, value: int, least: int) -> None:
    _check(isinstance(value, int) and not isinstance(value, bool) and value >= least,
           f"{name} must be an integer >= {least}, got {value!r}")


def _out(x: Any, n: int | None) -> float | np.ndarray:
    return float(x) if n is None else np.asarray(x, dtype=float)


@dataclass(frozen=True)
class Constant:
    """Always the same delay."""

    value: float = 0.0
    """Delay (s)."""

    def __post_init__(self) -> None:
        _nonneg("value", self.value)

    def sample(self, rng: np.random.Generator, n: int | None = None) -> float | np.ndarray:
        return float(self.value) if n is None else np.full(n, float(self.value))

    @property
    def mean(self) -> float:
        return float(self.value)


@dataclass(frozen=True)
class Uniform:
    """A delay uniform in ``[low, high)`` seconds."""

    low: float
    """Shortest delay (s)."""
    high: float
    """Longest delay (s), exclusive; ``high == low`` is a constant."""

    def __post_init__(self) -> None:
        _nonneg("low", self.low)
        _nonneg("high", self.high)
        _check(self.high >= self.low, f"high ({self.high!r}) must be >= low ({self.low!r})")

    def sample(self, rng: np.random.Generator, n: int | None = None) -> float | np.ndarray:
        return _out(rng.uniform(self.low, self.high, size=n), n)

    @property
    def mean(self) -> float:
        return 0.5 * (self.low + self.high)


@dataclass(frozen=True)
class Exponential:
    """An exponentially distributed delay: memoryless queueing, a long tail."""

    mean: float
    """Mean delay (s)."""

    def __post_init__(self) -> None:
        _positive("mean", self.mean)

    def sample(self, rng: np.random.Generator, n: int | None = None) -> float | np.ndarray:
        return _out(rng.exponential(self.mean, size=n), n)


@dataclass(frozen=True)
class Scans:
    """A whole number of scan intervals, uniform in ``low..high`` (both inclusive)."""

    low: int
    """Fewest scan intervals (>= 0)."""
    high: int
    """Most scan intervals (>= low)."""
    interval: float
    """Scan interval (s)."""

    def __post_init__(self) -> None:
        _steps("low", self.low, 0)
        _steps("high", self.high, 0)
        _check(self.high >= self.low, f"high ({self.high}) must be >= low ({self.low})")
        _positive("interval", self.interval)

    def sample(self, rng: np.random.Generator, n: int | None = None) -> float | np.ndarray:
        return _out(rng.integers(self.low, self.high + 1, size=n) * self.interval, n)

    @property
    def mean(self) -> float:
        return 0.5 * (self.low + self.high) * self.interval


@dataclass(frozen=True)
class ShortDelay:
    """The papers' short delay: less than one scan interval, uniform in ``[0, interval)``."""

    interval: float
    """Scan interval (s)."""

    def __post_init__(self) -> None:
        _positive("interval", self.interval)

    def sample(self, rng: np.random.Generator, n: int | None = None) -> float | np.ndarray:
        return _out(rng.uniform(0.0, self.interval, size=n), n)

    @property
    def mean(self) -> float:
        return 0.5 * self.interval


@dataclass(frozen=True)
class OneStep:
    """The papers' one-step delay: exactly one scan interval."""

    interval: float
    """Scan interval (s)."""

    def __post_init__(self) -> None:
        _positive("interval", self.interval)

    def sample(self, rng: np.random.Generator, n: int | None = None) -> float | np.ndarray:
        return float(self.interval) if n is None else np.full(n, float(self.interval))

    @property
    def mean(self) -> float:
        return float(self.interval)


@dataclass(frozen=True)
class MultiStep:
    """The papers' multi-step delay: a whole number of scan intervals, uniform in 1..max_steps."""

    max_steps: int
    """Most scan intervals (>= 1)."""
    interval: float
    """Scan interval (s)."""

    def __post_init__(self) -> None:
        _steps("max_steps", self.max_steps, 1)
        _positive("interval", self.interval)

    def sample(self, rng: np.random.Generator, n: int | None = None) -> float | np.ndarray:
        return _out(rng.integers(1, self.max_steps + 1, size=n) * self.interval, n)

    @property
    def mean(self) -> float:
        return 0.5 * (1 + self.max_steps) * self.interval


# --------------------------------------------------------------------------------------------
# One link
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class LinkFaults:
    """The faults of one directed link; the default is a perfect link."""

    delay: Delay = Constant(0.0)
    """Delay of every delivered copy."""
    loss: float = 0.0
    """Probability that a message is lost."""
    duplicate: float = 0.0
    """Probability that a message is delivered twice (each copy with its own delay)."""
    reorder: float = 0.0
    """Probability that a message is held back by a further ``reorder_delay``."""
    reorder_delay: Delay = Constant(0.0)
    """Extra delay of a reordered message; needs a positive mean when ``reorder > 0``."""
    partitions: tuple[tuple[float, float], ...] = ()
    """Run-clock intervals ``[start, end)`` (s) during which the link carries nothing."""

    def __post_init__(self) -> None:
        for name in ("loss", "duplicate", "reorder"):
            p = getattr(self, name)
            _check(isinstance(p, int | float) and 0.0 <= p <= 1.0,
                   f"{name} must be a probability in [0, 1], got {p!r}")
        _check(self.reorder == 0.0 or self.reorder_delay.mean > 0.0,
               "reorder > 0 needs a reorder_delay with a positive mean, or nothing is reordered")
        for i, part in enumerate(self.partitions):
            _check(len(part) == 2, f"partitions[{i}] must be [start, end], got {part!r}")
            start, end = part
            _check(math.isfinite(start) and start >= 0,
                   f"partitions[{i}] start must be finite and >= 0 s, got {start!r}")
            _check(end > start, f"partitions[{i}] end ({end!r}) must be > start ({start!r})")

    def partitioned(self, t0: float, t1: float | None = None) -> bool:
        """Whether the link is down at ``t0``, or at any time of ``[t0, t1]`` if ``t1`` is given."""
        t1 = t0 if t1 is None else t1
        return any(t0 < end and t1 >= start for start, end in self.partitions)


@dataclass(frozen=True)
class LinkLayer:
    """What one table of the plan sets (``None``: not set; the layers below show through)."""

    delay: Delay | None = None
    loss: float | None = None
    duplicate: float | None = None
    reorder: float | None = None
    reorder_delay: Delay | None = None
    partitions: tuple[tuple[float, float], ...] | None = None
    where: str = field(default="", compare=False)
    """The dotted key of the table (``"faults.links[0]"``), for errors."""


class PlanConflict(ValueError):
    """Layers that are fine alone but not together; ``key`` is the dotted key to blame."""

    def __init__(self, key: str, problem: str) -> None:
        super().__init__(f"key '{key}' {problem}")
        self.key, self.problem = key, problem


_LINK_FIELDS = tuple(f.name for f in fields(LinkFaults))


def _resolve(layers: Iterable[LinkLayer], link: str) -> LinkFaults:
    merged: dict[str, Any] = {}
    setter: dict[str, str] = {}
    parts: set[tuple[float, float]] = set()
    for layer in layers:
        for name in _LINK_FIELDS:
            value = getattr(layer, name)
            if value is None:
                continue
            if name == "partitions":
                parts.update(value)
            else:
                merged[name], setter[name] = value, layer.where
    merged["partitions"] = tuple(sorted(parts))
    reorder, extra = merged.get("reorder", 0.0), merged.get("reorder_delay", Constant(0.0))
    if reorder > 0 and not extra.mean > 0:
        reorder_key = f"{setter['reorder']}.reorder"
        if setter.get("reorder_delay"):
            raise PlanConflict(f"{setter['reorder_delay']}.reorder_delay",
                               f"has mean {extra.mean:g} s, so '{reorder_key}' = {reorder:g} "
                               f"holds nothing back on {link}; give it a positive mean")
        raise PlanConflict(reorder_key, f"is {reorder:g} on {link} but no reorder_delay is set")
    return LinkFaults(**merged)


# --------------------------------------------------------------------------------------------
# The plan: faults per directed link
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class FaultPlan:
    """Faults per directed link: ``links[(sender, receiver)]``, else ``default``."""

    default: LinkFaults = LinkFaults()
    """Faults of every link without an entry in ``links``."""
    links: tuple[tuple[tuple[str, str], LinkFaults], ...] = ()
    """Fully resolved faults of particular directed links, ``((sender, receiver), faults)``
    sorted by link (a mapping is accepted and converted, so the plan stays hashable)."""
    interval: float | None = None
    """The scan interval (run-clock s) the plan was built with: its delays in scans are
    multiples of it, and a message of scan ``k`` is at ``k * interval`` for the partitions.
    ``None``: the injector takes the time its caller passes."""

    def __post_init__(self) -> None:
        links = self.links.items() if isinstance(self.links, Mapping) else self.links
        object.__setattr__(self, "links", tuple(sorted(
            ((str(s), str(r)), f) for (s, r), f in links)))
        _check(self.interval is None or (math.isfinite(self.interval) and self.interval > 0),
               f"interval must be > 0 s or None, got {self.interval!r}")

    @functools.cached_property
    def _by_link(self) -> dict[tuple[str, str], LinkFaults]:
        return dict(self.links)

    def for_link(self, sender: str, receiver: str) -> LinkFaults:
        """The faults of the link ``sender -> receiver``."""
        return self._by_link.get((sender, receiver), self.default)

    @classmethod
    def layered(cls, names: Iterable[str], interval: float, default: LinkLayer = LinkLayer(),
                peers: Mapping[str, LinkLayer] | None = None,
                links: Mapping[tuple[str, str], LinkLayer] | None = None) -> FaultPlan:
        """The plan of the peers ``names`` from its layers: ``default`` < ``peers[s]`` (links
        out of ``s``) < ``peers[r]`` (links into ``r``) < ``links[(s, r)]``, per key;
        partitions joined. Below them all, a ``reorder`` without a ``reorder_delay`` holds
        reordered messages a further uniform ``[0, 2)`` scan intervals, so they fall behind
        the next scan's messages. :class:`PlanConflict` names the key when layers clash.
        """
        names = list(names)
        peers, links = dict(peers or {}), dict(links or {})
        base = LinkLayer(reorder_delay=Uniform(0.0, 2.0 * interval))
        plan_default = _resolve([base, default], "every link")
        resolved = {}
        for s in names:
            for r in names:
                if s == r:
                    continue
                layers = [base, default, peers.get(s, LinkLayer()), peers.get(r, LinkLayer()),
                          links.get((s, r), LinkLayer())]
                faults = _resolve(layers, f"the link {s} -> {r}")
                if faults != plan_default:
                    resolved[(s, r)] = faults
        return cls(default=plan_default, links=resolved, interval=interval)


__all__ = [
    "Constant",
    "Delay",
    "Exponential",
    "FaultPlan",
    "LinkFaults",
    "LinkLayer",
    "MultiStep",
    "OneStep",
    "PlanConflict",
    "Scans",
    "ShortDelay",
    "Uniform",
]
