"""One declaration per scenario option: :func:`option` puts a field's default, doc, unit,
choices and bounds in the dataclass field itself (Stone Soup's ``base.Property`` idea), and the
parser (:mod:`sim.scenario.parse`), the accepted keys, the defaults and docs/scenario.md
(:mod:`sim.scenario.docs`) are read from it.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from typing import Any

Choices = tuple[str, ...] | Callable[[], Iterable[str]]
"""A key's values: a tuple, or a registry's ``names`` function (asked at load, so kinds a
plug-in registers later count)."""


@dataclass(frozen=True)
class Bound:
    """Where a number may lie: ``low``/``high`` (``None``: unbounded), each open or closed."""

    low: float | None = None
    high: float | None = None
    low_open: bool = False
    high_open: bool = False

    def problem(self, value: float) -> str | None:
        """Why ``value`` is out of bounds (``"must be > 0, got 0"``), or None when it is in."""
        got = f"{value}" if isinstance(value, int) else f"{value:g}"
        if self == PROBABILITY and not 0.0 <= value <= 1.0:
            return f"must be a probability in [0, 1], got {got}"
        if self.low is not None and (value <= self.low if self.low_open else value < self.low):
            return f"must be {'>' if self.low_open else '>='} {self.low:g}, got {got}"
        if self.high is not None and (value >= self.high if self.high_open
                                      else value > self.high):
            return f"must be {'<' if self.high_open else '<='} {self.high:g}, got {got}"
        return None

    def __str__(self) -> str:
        if self.low is not None and self.high is not None:
            return (f"{'(' if self.low_open else '['}{self.low:g}, {self.high:g}"
                    f"{')' if self.high_open else ']'}")
        if self.low is not None:
            return f"{'>' if self.low_open else '>='} {self.low:g}"
        if self.high is not None:
            return f"{'<' if self.high_open else '<='} {self.high:g}"
        return ""


POSITIVE = Bound(0, low_open=True)
"""``> 0``."""
NONNEGATIVE = Bound(0)
"""``>= 0``."""
PROBABILITY = Bound(0, 1)
"""``[0, 1]``."""


def at_least(low: float) -> Bound:
    """``>= low``."""
    return Bound(low)


@dataclass(frozen=True)
class Meta:
    """What :func:`option` declares about a field, besides its type and default."""

    doc: str
    """One or two sentences: what the option does (Markdown, for docs/scenario.md)."""
    unit: str | None = None
    """``"m"``, ``"s"``, ``"scans"``, ... (None: none)."""
    choices: Choices | None = None
    """The values a text option takes."""
    check: Bound | None = None
    """Bounds of a number."""
    key: str | None = None
    """The key in its table when it differs from the field's name (``"truth.weight"``)."""
    was: str | None = None
    """The key's old name, still read with a deprecation warning (``"omega"``)."""
    custom: str | None = None
    """Read by its section's own code in :mod:`sim.scenario.parse` (a table, a list, a
    cross-check); the text says what the value is when the key is absent, for the docs."""

    def values(self) -> tuple[str, ...]:
        """The choices now (a registry's names included)."""
        c = self.choices
        return tuple(c() if callable(c) else c or ())


def option(default: Any = dataclasses.MISSING, *, doc: str, unit: str | None = None,
           choices: Choices | None = None, check: Bound | None = None, key: str | None = None,
           was: str | None = None, custom: str | None = None) -> Any:
    """A scenario option: a dataclass field with its default and its :class:`Meta`.

    ``default``: what a file without the key loads (omitted: the key is required). ``doc``:
    what it does; ``unit``; ``choices``: a tuple or a registry's ``names``; ``check``: a
    :class:`Bound`; ``key``: its key when not the field's name; ``was``: its old key;
    ``custom``: read by its section's own code, with the absent key's meaning for the docs.
    """
    meta = Meta(doc, unit, choices, check, key, was, custom)
    return dataclasses.field(default=default, metadata={"option": meta})


def meta(f: dataclasses.Field) -> Meta | None:
    """A field's :class:`Meta` (None for a field not declared with :func:`option`)."""
    return f.metadata.get("option")


def options(cls: type) -> Iterator[tuple[dataclasses.Field, Meta]]:
    """The option fields of a dataclass, in declaration order."""
    for f in dataclasses.fields(cls):
        m = meta(f)
        if m is not None:
            yield f, m


def key_of(f: dataclasses.Field) -> str:
    """The field's key in its section (``"truth.weight"``, ``"scenario.seed"``, ``"rule"``)."""
    m = meta(f)
    return m.key if m is not None and m.key else f.name


def keys(cls: type, prefix: str = "") -> list[str]:
    """The keys a table of ``cls`` accepts: option keys under ``prefix`` (``"scenario"``,
    ``""``: the section's own), the first dotted part of deeper ones, and old names."""
    out: list[str] = []
    for f, m in options(cls):
        k = key_of(f)
        if prefix:
            if not k.startswith(prefix + "."):
                continue
            k = k[len(prefix) + 1:]
        out.append(k.split(".")[0])
        if m.was and "." not in k:
            out.append(m.was)
    return list(dict.fromkeys(out))


def required(f: dataclasses.Field) -> bool:
    """The option has no default: a file must give it."""
    return f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING
