"""Link faults: seeded, logged delay, loss, duplication, reordering and partitions per link.

One model, two drivers. The discrete-event twin (``sim.twin``) asks
:meth:`FaultInjector.deliveries` when a peer's estimate leaves for another peer and schedules
one delivery per returned delay; the Zenoh runtime can ask the same question and hold the
message that long (:class:`HoldQueue`) before handing it on. Nothing here imports Zenoh or
touches a clock: the caller passes the run-clock time ``t`` (seconds since the run started;
scan ``k`` is at about ``k * interval``), so the same plan and seed give the same faults in
both drivers.

Per message on the link ``sender -> receiver`` at time ``t`` (:meth:`FaultInjector.decide`):

1. sent inside a partition interval of the link: dropped (``"drop-partition"``);
2. lost with probability ``loss`` (``"drop-loss"``);
3. otherwise one copy, or two with probability ``duplicate``; each copy waits a draw of the
   link's ``delay``; with probability ``reorder`` the message is *reordered*: each copy waits a
   further draw of ``reorder_delay``, so later messages overtake it;
4. a copy whose flight ``[t, t + delay]`` reaches into a partition is lost with the link
   (``"drop-partition"`` if no copy is left).

The action logged is the first that applies of ``drop-partition``, ``drop-loss``,
``duplicate`` (two copies delivered), ``reorder``, ``deliver``; :attr:`FaultRecord.reordered`
says whether the extra delay was applied, also for a duplicate.

Random numbers: every link has its own generator, seeded from ``(seed, crc32(sender),
crc32(receiver))``, and every message consumes the same draws whatever happens to it (three
uniforms, two delays, two extra delays). So adding a link, or a partition, or changing a
probability leaves the other draws of every link where they were: two plans differ only in
the faults they differ in (common random numbers across experiments).

Delays in scan intervals (the papers' "short", "one-step", "multi-step" and random-scan
delays, ALGORITHMS.md §5) are built with the scan interval once, by :func:`parse_delay` or
:meth:`FaultPlan.from_spec`, and sample seconds like the others.
"""

from __future__ import annotations

import csv
import difflib
import heapq
import itertools
import math
import zlib
from collections import Counter
from collections.abc import Callable, Hashable, Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import numpy as np

ACTIONS = ("deliver", "drop-loss", "drop-partition", "duplicate", "reorder")
"""Every action a :class:`FaultRecord` can carry."""

DELAY_KINDS = ("constant", "uniform", "exponential", "scans", "short", "one-step", "multi-step")
"""The ``kind`` values :func:`parse_delay` accepts."""

LINK_KEYS = ("delay", "loss", "duplicate", "reorder", "reorder_delay", "partitions")
"""The keys of a ``default``, ``peers.<name>`` or ``links[i]`` table."""


# --------------------------------------------------------------------------------------------
# Delay distributions (seconds)
# --------------------------------------------------------------------------------------------


class Delay(Protocol):
    """A delay distribution: ``sample(rng)`` is one delay (s), ``sample(rng, n)`` an ``(n,)``."""

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
        x = rng.uniform(self.low, self.high, size=n)
        return float(x) if n is None else x

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
        x = rng.exponential(self.mean, size=n)
        return float(x) if n is None else x


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
        x = rng.integers(self.low, self.high + 1, size=n) * self.interval
        return float(x) if n is None else x.astype(float)

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
        x = rng.uniform(0.0, self.interval, size=n)
        return float(x) if n is None else x

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
        x = rng.integers(1, self.max_steps + 1, size=n) * self.interval
        return float(x) if n is None else x.astype(float)

    @property
    def mean(self) -> float:
        return 0.5 * (1 + self.max_steps) * self.interval


# --------------------------------------------------------------------------------------------
# Spec parsing helpers: one-line errors naming the dotted key
# --------------------------------------------------------------------------------------------


def _key(path: str, name: str | int) -> str:
    if isinstance(name, int):
        return f"{path}[{name}]"
    return f"{path}.{name}" if path else name


def _short(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


def _unknown_keys(table: Mapping, known: Iterable[str], path: str) -> None:
    known = list(known)
    for name in table:
        if name not in known:
            close = difflib.get_close_matches(str(name), known, n=1, cutoff=0.6)
            hint = f" (did you mean '{_key(path, close[0])}'?)" if close else ""
            raise ValueError(f"unknown key '{_key(path, str(name))}'{hint}")


def _table(value: Any, path: str) -> Mapping:
    if not isinstance(value, Mapping):
        raise ValueError(f"key '{path}' must be a table, got {_short(value)}")
    return value


def _number(value: Any, path: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ValueError(f"key '{path}' must be a number, got {_short(value)}")
    return float(value)


def _integer(value: Any, path: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise ValueError(f"key '{path}' must be an integer, got {_short(value)}")
    return value


def _probability(value: Any, path: str) -> float:
    p = _number(value, path)
    if not 0.0 <= p <= 1.0:
        raise ValueError(f"key '{path}' must be a probability in [0, 1], got {value!r}")
    return p


_DELAY_PARAMS = {
    "constant": ("value",), "uniform": ("low", "high"), "exponential": ("mean",),
    "scans": ("low", "high"), "short": (), "one-step": (), "multi-step": ("max_steps",),
}


def parse_delay(spec: Mapping | str | float, interval: float, *, path: str = "delay") -> Delay:
    """A delay distribution from a scenario-file value.

    ``spec`` is a number (a constant delay in seconds), a parameterless kind (``"short"``,
    ``"one-step"``) or a table with ``kind`` and its parameters: ``constant`` (``value``),
    ``uniform`` (``low``, ``high`` in s), ``exponential`` (``mean`` in s), ``scans`` (``low``,
    ``high`` whole scan intervals), ``short``, ``one-step``, ``multi-step`` (``max_steps``).
    ``interval`` is the scan interval (s) the scan kinds multiply by. ``path`` is the dotted
    key the errors name. A bad spec raises :class:`ValueError` with a one-line message.
    """
    if isinstance(spec, bool):
        raise ValueError(f"key '{path}' must be a number, a kind or a table, got {spec!r}")
    if isinstance(spec, int | float):
        if not (math.isfinite(spec) and spec >= 0):
            raise ValueError(f"key '{path}' must be a delay >= 0 s, got {spec!r}")
        return Constant(float(spec))
    if isinstance(spec, str):
        spec_table: Mapping = {"kind": spec}
        kind_path = path
    else:
        spec_table = _table(spec, path)
        kind_path = _key(path, "kind")
        if "kind" not in spec_table:
            raise ValueError(f"missing required key '{kind_path}' "
                             f"(one of {', '.join(DELAY_KINDS)})")
    kind = spec_table["kind"]
    if kind not in _DELAY_PARAMS:
        close = difflib.get_close_matches(str(kind), DELAY_KINDS, n=1, cutoff=0.6)
        hint = f" (did you mean '{close[0]}'?)" if close else ""
        raise ValueError(f"key '{kind_path}': unknown delay kind {_short(kind)}{hint}; "
                         f"one of {', '.join(DELAY_KINDS)}")
    params = _DELAY_PARAMS[kind]
    if isinstance(spec, str) and params:
        raise ValueError(f"key '{path}': delay kind '{kind}' needs a table with "
                         f"{', '.join(params)}")
    _unknown_keys(spec_table, ("kind", *params), path)
    for name in params:
        if name not in spec_table:
            raise ValueError(f"missing required key '{_key(path, name)}' for delay kind '{kind}'")
    get = {n: spec_table[n] for n in params}
    try:
        if kind == "constant":
            return Constant(_number(get["value"], _key(path, "value")))
        if kind == "uniform":
            return Uniform(_number(get["low"], _key(path, "low")),
                           _number(get["high"], _key(path, "high")))
        if kind == "exponential":
            return Exponential(_number(get["mean"], _key(path, "mean")))
        if kind == "scans":
            return Scans(_integer(get["low"], _key(path, "low")),
                         _integer(get["high"], _key(path, "high")), interval)
        if kind == "short":
            return ShortDelay(interval)
        if kind == "one-step":
            return OneStep(interval)
        return MultiStep(_integer(get["max_steps"], _key(path, "max_steps")), interval)
    except ValueError as e:
        if str(e).startswith(("key ", "missing ", "unknown ")):
            raise
        raise ValueError(f"key '{path}': {e}") from None


# --------------------------------------------------------------------------------------------
# What can go wrong on one link
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


def _parse_partitions(value: Any, path: str) -> tuple[tuple[float, float], ...]:
    if not isinstance(value, list | tuple):
        raise ValueError(f"key '{path}' must be a list of [start, end] pairs, got {_short(value)}")
    out = []
    for i, part in enumerate(value):
        where = _key(path, i)
        if not isinstance(part, list | tuple) or len(part) != 2:
            raise ValueError(f"key '{where}' must be [start, end] (s), got {_short(part)}")
        start, end = _number(part[0], where), _number(part[1], where)
        if not (math.isfinite(start) and start >= 0):
            raise ValueError(f"key '{where}' start must be finite and >= 0 s, got {part[0]!r}")
        if not end > start:
            raise ValueError(f"key '{where}' end must be > start, got {_short(part)}")
        out.append((start, end))
    return tuple(out)


def _parse_layer(table: Any, path: str, interval: float, skip: tuple[str, ...] = ()) -> dict:
    """One ``default`` / ``peers.<p>`` / ``links[i]`` table, checked, as LinkFaults kwargs."""
    table = _table(table, path)
    _unknown_keys(table, (*skip, *LINK_KEYS), path)
    out: dict[str, Any] = {}
    for name, value in table.items():
        where = _key(path, name)
        if name in skip:
            continue
        if name in ("delay", "reorder_delay"):
            out[name] = parse_delay(value, interval, path=where)
        elif name == "partitions":
            out[name] = _parse_partitions(value, where)
        else:
            out[name] = _probability(value, where)
    return out


# --------------------------------------------------------------------------------------------
# The plan: faults per directed link
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class FaultPlan:
    """Faults per directed link: ``links[(sender, receiver)]``, else ``default``."""

    default: LinkFaults = LinkFaults()
    """Faults of every link without an entry in ``links``."""
    links: Mapping[tuple[str, str], LinkFaults] = field(default_factory=dict)
    """Fully resolved faults of particular directed links ``(sender, receiver)``."""

    def for_link(self, sender: str, receiver: str) -> LinkFaults:
        """The faults of the link ``sender -> receiver``."""
        return self.links.get((sender, receiver), self.default)

    @classmethod
    def from_spec(cls, spec: Mapping, interval: float, peers: Iterable[str], *,
                  path: str = "") -> FaultPlan:
        """A plan from a TOML-like table ``{"default": {...}, "peers": {...}, "links": [...]}``.

        Each of ``default``, ``peers.<name>`` and ``links[i]`` (which also has ``from`` and
        ``to``) may set ``delay``, ``loss``, ``duplicate``, ``reorder``, ``reorder_delay`` and
        ``partitions``. Precedence, per key, for the link ``s -> r``: ``default``, then
        ``peers.s`` (every link out of ``s``), then ``peers.r`` (every link into ``r``), then the
        ``links`` entry ``s -> r``; the last one that sets a key wins, so a link entry that sets
        only ``loss`` keeps the default's delay. ``partitions`` is the exception: the intervals
        of all these layers are joined, since a link is down whenever either end, or the whole
        network, is cut off. A ``reorder`` without a ``reorder_delay`` anywhere holds reordered
        messages a further uniform ``[0, 2)`` scan intervals, so they fall behind the next
        scan's messages. ``interval`` is the scan interval (s) for the delays in scans;
        ``peers`` the peer names (sensor names). ``path`` prefixes the dotted keys in errors
        (e.g. ``"faults"``). A bad spec raises :class:`ValueError` naming the key.
        """
        if not (isinstance(interval, int | float) and math.isfinite(interval) and interval > 0):
            raise ValueError(f"scan interval must be > 0 s, got {interval!r}")
        names = list(peers)
        spec = _table(spec, path or "faults")
        _unknown_keys(spec, ("default", "peers", "links"), path)
        base = {"reorder_delay": Uniform(0.0, 2.0 * interval)}
        default = _parse_layer(spec.get("default", {}), _key(path, "default"), interval)
        per_peer: dict[str, dict] = {}
        peers_path = _key(path, "peers")
        for name, table in _table(spec.get("peers", {}), peers_path).items():
            where = _key(peers_path, str(name))
            if name not in names:
                raise ValueError(f"key '{where}': unknown peer {name!r} "
                                 f"(peers: {', '.join(names)})")
            per_peer[name] = _parse_layer(table, where, interval)
        per_link: dict[tuple[str, str], dict] = {}
        links_path = _key(path, "links")
        links = spec.get("links", [])
        if not isinstance(links, list | tuple):
            raise ValueError(f"key '{links_path}' must be a list of tables, got {_short(links)}")
        for i, table in enumerate(links):
            where = _key(links_path, i)
            table = _table(table, where)
            ends = []
            for end in ("from", "to"):
                if end not in table:
                    raise ValueError(f"missing required key '{_key(where, end)}'")
                if table[end] not in names:
                    raise ValueError(f"key '{_key(where, end)}': unknown peer "
                                     f"{_short(table[end])} (peers: {', '.join(names)})")
                ends.append(table[end])
            pair = (ends[0], ends[1])
            if pair[0] == pair[1]:
                raise ValueError(f"key '{where}': a link needs two different peers, got "
                                 f"{pair[0]!r} -> {pair[1]!r}")
            if pair in per_link:
                raise ValueError(f"key '{where}': link {pair[0]} -> {pair[1]} is given twice")
            per_link[pair] = _parse_layer(table, where, interval, skip=("from", "to"))

        def resolve(layers: list[dict], where: str) -> LinkFaults:
            merged: dict[str, Any] = {}
            parts: list[tuple[float, float]] = []
            for layer in layers:
                merged.update(layer)
                parts.extend(layer.get("partitions", ()))
            merged["partitions"] = tuple(sorted(set(parts)))
            try:
                return LinkFaults(**merged)
            except ValueError as e:
                raise ValueError(f"{where}: {e}") from None

        plan_default = resolve([base, default], f"key '{_key(path, 'default')}'")
        resolved: dict[tuple[str, str], LinkFaults] = {}
        for s in names:
            for r in names:
                if s == r:
                    continue
                layers = [base, default, per_peer.get(s, {}), per_peer.get(r, {}),
                          per_link.get((s, r), {})]
                faults = resolve(layers, f"link {s} -> {r}")
                if faults != plan_default:
                    resolved[(s, r)] = faults
        return cls(default=plan_default, links=resolved)


# --------------------------------------------------------------------------------------------
# The injector: seeded decisions and their log
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class FaultRecord:
    """One decision about one message on one link."""

    t: float
    """Run-clock send time (s)."""
    sender: str
    """Sending peer."""
    receiver: str
    """Receiving peer."""
    msg_id: str
    """The message, as the caller names it (e.g. ``"s1:k12:r0"``)."""
    action: str
    """One of :data:`ACTIONS`."""
    delays: tuple[float, ...]
    """Delay of each delivered copy (s); empty when dropped."""
    reordered: bool = False
    """Whether the copies carry the reorder extra delay (also when duplicated)."""


def default_msg_id(msg: Any) -> str:
    """``"<sender>:k<k>:r<round>"`` for an :class:`~protocol.messages.Estimate`-like message."""
    sender, k = getattr(msg, "sender", None), getattr(msg, "k", None)
    if sender is None or k is None:
        return str(msg)
    return f"{sender}:k{k}:r{getattr(msg, 'round', 0)}"


def link_seed(seed: int, sender: str, receiver: str) -> np.random.SeedSequence:
    """The seed sequence of one directed link: a function of the run seed and the two names."""
    return np.random.SeedSequence([seed, zlib.crc32(sender.encode("utf-8")),
                                   zlib.crc32(receiver.encode("utf-8"))])


class FaultInjector:
    """Decides, draws and logs what happens to each message on each link of a :class:`FaultPlan`.

    Not thread-safe: call it from the thread that sends (the twin's loop, the runtime's main
    thread). Decisions on a link depend only on the seed, the link's names and faults, and the
    sequence of ``(t, msg)`` the link has seen.
    """

    def __init__(self, plan: FaultPlan, seed: int,
                 msg_id: Callable[[Any], Hashable] = default_msg_id) -> None:
        if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
            raise ValueError(f"seed must be an integer >= 0, got {seed!r}")
        self.plan = plan
        self.seed = int(seed)
        self.msg_id = msg_id
        self.log: list[FaultRecord] = []
        self._counts: Counter = Counter()
        self._rngs: dict[tuple[str, str], np.random.Generator] = {}

    def _rng(self, sender: str, receiver: str) -> np.random.Generator:
        rng = self._rngs.get((sender, receiver))
        if rng is None:
            rng = np.random.default_rng(link_seed(self.seed, sender, receiver))
            self._rngs[(sender, receiver)] = rng
        return rng

    def decide(self, sender: str, receiver: str, t: float, msg_id: Hashable) -> list[float]:
        """The delivery delays (s) of one message sent at run-clock ``t``: ``[]`` dropped,
        one entry delivered once, two entries duplicated. Logged as a :class:`FaultRecord`."""
        faults = self.plan.for_link(sender, receiver)
        rng = self._rng(sender, receiver)
        # the same draws for every message, whatever happens to it (see the module docstring)
        u_loss, u_dup, u_reorder = rng.random(3)
        base = np.asarray(faults.delay.sample(rng, 2), dtype=float)
        extra = np.asarray(faults.reorder_delay.sample(rng, 2), dtype=float)
        reordered = bool(u_reorder < faults.reorder)
        if faults.partitioned(t):
            action, delays = "drop-partition", []
        elif u_loss < faults.loss:
            action, delays = "drop-loss", []
        else:
            copies = 2 if u_dup < faults.duplicate else 1
            wait = base[:copies] + (extra[:copies] if reordered else 0.0)
            delays = [float(d) for d in wait if not faults.partitioned(t, t + float(d))]
            if not delays:
                action = "drop-partition"
            elif len(delays) == 2:
                action = "duplicate"
            else:
                action = "reorder" if reordered else "deliver"
        self.log.append(FaultRecord(float(t), sender, receiver, str(msg_id), action,
                                    tuple(delays), reordered and bool(delays)))
        self._counts[action] += 1
        return delays

    def deliveries(self, sender: str, receiver: str, t: float, msg: Any) -> list[float]:
        """:meth:`decide` for a message object, named by the injector's ``msg_id`` function."""
        return self.decide(sender, receiver, t, self.msg_id(msg))

    def as_link_delay(self, msg_id_fn: Callable[[Any], Hashable] | None = None,
                      time_fn: Callable[[Any], float] | None = None
                      ) -> Callable[[str, str, Any], float | None]:
        """A ``(sender, receiver, msg) -> delay | None`` callable (the twin's ``LinkDelay``).

        It can deliver one copy only: a duplicated message is delivered once (its first copy;
        the log still says ``"duplicate"``); use :meth:`deliveries` to deliver both.
        ``time_fn`` gives the run-clock send time of a message (default: its ``send_time``,
        which the twin sets to the virtual time).
        """
        name = msg_id_fn or self.msg_id
        when = time_fn or (lambda msg: float(msg.send_time))

        def delay(sender: str, receiver: str, msg: Any) -> float | None:
            out = self.decide(sender, receiver, when(msg), name(msg))
            return out[0] if out else None

        return delay

    def counts(self) -> dict[str, int]:
        """How many decisions took each action (every action present, zeros included)."""
        return {a: self._counts.get(a, 0) for a in ACTIONS}

    def write_log(self, path: str | Path, append: bool = False) -> None:
        """The log as CSV: a header, then one line per decision; ``delays`` joined by ``;``.

        ``append``: add the records to an existing file (header only if it is new) and clear
        the in-memory log, so a long run's memory stays flat (:meth:`counts` is kept apart).
        """
        new = not append or not Path(path).exists()
        with open(path, "a" if append else "w", newline="", encoding="utf-8") as f:
            w = csv.writer(f)
            if new:
                w.writerow(["t", "sender", "receiver", "msg_id", "action", "reordered",
                            "delays"])
            for r in self.log:
                w.writerow([repr(r.t), r.sender, r.receiver, r.msg_id, r.action,
                            int(r.reordered), ";".join(repr(d) for d in r.delays)])
        if append:
            self.log.clear()


class HoldQueue:
    """Messages held back until their delivery time: what a runtime transport wrapper needs.

    ``push(due, item)`` holds ``item`` until the clock reads ``due``; ``pop_due(now)`` returns
    the items due by ``now`` in order of ``due`` (ties in push order). The caller owns the
    clock (e.g. ``time.monotonic()``) and polls, e.g. in the loop that fires fusion deadlines:
    wait at most ``next_due() - now``.
    """

    def __init__(self) -> None:
        self._heap: list[tuple[float, int, Any]] = []
        self._order = itertools.count()

    def __len__(self) -> int:
        return len(self._heap)

    def push(self, due: float, item: Any) -> None:
        """Hold ``item`` until ``due``."""
        heapq.heappush(self._heap, (float(due), next(self._order), item))

    def next_due(self) -> float | None:
        """When the next item is due, or ``None`` if nothing is held."""
        return self._heap[0][0] if self._heap else None

    def pop_due(self, now: float) -> list[Any]:
        """The items due at or before ``now``, earliest first; they are no longer held."""
        out = []
        while self._heap and self._heap[0][0] <= now:
            out.append(heapq.heappop(self._heap)[2])
        return out
