"""Checked reading of TOML tables: every mistake a one-line :class:`ScenarioError` naming
the file and the dotted key."""

from __future__ import annotations

import dataclasses
import difflib
import math
import warnings
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np
from sensornet.sim.scenario.model import MAX_COORDINATE, Matrix, ScenarioError, listing

# --------------------------------------------------------------------------------------------
# Validation
# --------------------------------------------------------------------------------------------

REQUIRED = object()


def brief(value: Any) -> str:
    """A value for an error message, TOML-spelled where it differs, at most 60 characters."""
    text = ("true" if value else "false") if isinstance(value, bool) else repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


@dataclass
class Context:
    """Where errors point: the file label, and which keys came from overrides."""

    label: str
    override_paths: set[str] = dataclasses.field(default_factory=set)

    def fail(self, path: str, problem: str) -> ScenarioError:
        overridden = any(
            path == p or path.startswith((p + ".", p + "[")) or p.startswith((path + ".",
                                                                              path + "["))
            for p in self.override_paths
        )
        where = f"{self.label} (overrides)" if overridden else self.label
        return ScenarioError(f"{where}: {problem}")


class Table:
    """One TOML table being read: typed getters; keys outside ``known`` are errors."""

    def __init__(self, data: Any, path: str, ctx: Context, known: Iterable[str]):
        self.path, self.ctx = path, ctx
        if not isinstance(data, dict):
            raise ctx.fail(path, f"'{path}' must be a table, got {brief(data)}")
        self.data = data
        known = list(known)
        for key in data:
            if key not in known:
                close = difflib.get_close_matches(key, known, n=1, cutoff=0.6)
                hint = f" (did you mean '{self.key(close[0])}'?)" if close else ""
                raise ctx.fail(self.key(key), f"unknown key '{self.key(key)}'{hint}")

    def key(self, name: str) -> str:
        return f"{self.path}.{name}" if self.path else name

    def fail(self, name: str, problem: str) -> ScenarioError:
        return self.ctx.fail(self.key(name), f"key '{self.key(name)}' {problem}")

    def raw(self, name: str, default: Any = REQUIRED) -> Any:
        if name in self.data:
            return self.data[name]
        if default is REQUIRED:
            raise self.ctx.fail(self.key(name), f"missing required key '{self.key(name)}'")
        return default

    def has(self, name: str) -> bool:
        return name in self.data

    def renamed(self, old: str, new: str) -> str:
        """The key to read for an option renamed ``old`` -> ``new``: ``new``, or ``old`` (with a
        one-line :class:`FutureWarning`) when only the old name is given."""
        if not self.has(old):
            return new
        if self.has(new):
            raise self.fail(old, f"is the old name of '{self.key(new)}', which is given too; "
                                 f"drop '{self.key(old)}'")
        # shown as one line "FILE:0: FutureWarning: ..." (no source line to quote)
        warnings.warn_explicit(f"key '{self.key(old)}' is now '{self.key(new)}' (the old name "
                               f"will stop working)", FutureWarning, self.ctx.label, 0)
        return old

    # typed getters ---------------------------------------------------------------------------
    def integer(self, name: str, default: Any = REQUIRED, minimum: int | None = None,
                maximum: int | None = None) -> int:
        v = self.raw(name, default)
        if isinstance(v, bool) or not isinstance(v, int):
            raise self.fail(name, f"must be an integer, got {brief(v)}")
        if minimum is not None and v < minimum:
            raise self.fail(name, f"must be >= {minimum}, got {v}")
        if maximum is not None and v > maximum:
            raise self.fail(name, f"must be <= {maximum}, got {brief(v)}")
        return v

    def number(self, name: str, default: Any = REQUIRED, minimum: float | None = None,
              positive: bool = False, probability: bool = False) -> float:
        v = self.raw(name, default)
        v = self._number(name, v)
        if probability and not 0.0 <= v <= 1.0:
            raise self.fail(name, f"must be a probability in [0, 1], got {v:g}")
        if positive and v <= 0:
            raise self.fail(name, f"must be > 0, got {v:g}")
        if minimum is not None and v < minimum:
            raise self.fail(name, f"must be >= {minimum:g} (no negative values), got {v:g}")
        return v

    def _number(self, name: str, v: Any, what: str = "a number") -> float:
        if isinstance(v, bool) or not isinstance(v, int | float):
            raise self.fail(name, f"must be {what}, got {brief(v)}")
        if not math.isfinite(v):
            raise self.fail(name, f"must be finite, got {v}")
        return float(v)

    def flag(self, name: str, default: Any = REQUIRED) -> bool:
        v = self.raw(name, default)
        if not isinstance(v, bool):
            raise self.fail(name, f"must be true or false, got {brief(v)}")
        return v

    def text(self, name: str, default: Any = REQUIRED) -> str:
        v = self.raw(name, default)
        if not isinstance(v, str) or not v:
            raise self.fail(name, f"must be a non-empty string, got {brief(v)}")
        return v

    def choice(self, name: str, options: Iterable[str], default: Any = REQUIRED) -> str:
        options = tuple(options)
        v = self.raw(name, default)
        if v not in options:
            close = difflib.get_close_matches(str(v), options, n=1, cutoff=0.6)
            hint = f"; did you mean {close[0]!r}?" if close else ""
            raise self.fail(name, f"is {brief(v)}, expected one of {listing(options)}{hint}")
        return v

    def vector(self, name: str, length: int, default: Any = REQUIRED) -> tuple[float, ...]:
        v = self.raw(name, default)
        if not isinstance(v, list | tuple) or len(v) != length:
            raise self.fail(name, f"must be a list of {length} numbers, got {brief(v)}")
        return tuple(self._number(name, x, f"a list of {length} numbers") for x in v)

    def position(self, name: str) -> tuple[float, float]:
        """``[x, y]`` in metres, each within :data:`MAX_COORDINATE`."""
        x, y = self.vector(name, 2)
        if max(abs(x), abs(y)) > MAX_COORDINATE:
            raise self.fail(name, f"is [{x:g}, {y:g}] m, beyond +-{MAX_COORDINATE:g} m")
        return x, y

    def tables(self, name: str, default: Any = REQUIRED) -> list[Any]:
        v = self.raw(name, default)
        if not isinstance(v, list):
            raise self.fail(name, f"must be an array of tables ([[{self.key(name)}]]), "
                                  f"got {brief(v)}")
        return v

    def covariance(self, dim: int, default: Matrix | None = None) -> Matrix:
        """``cov_diag = [d...]`` or ``cov = [[...]]`` (not both): symmetric positive definite."""
        if self.has("cov_diag") and self.has("cov"):
            raise self.fail("cov", "and 'cov_diag' are both given; use one")
        if self.has("cov"):
            rows = self.raw("cov")
            if not isinstance(rows, list) or len(rows) != dim or not all(
                isinstance(r, list) and len(r) == dim for r in rows
            ):
                raise self.fail("cov", f"must be a {dim} x {dim} list of lists, got {brief(rows)}")
            P = np.array([[self._number("cov", x, "a matrix of numbers") for x in r]
                          for r in rows])
            if not np.allclose(P, P.T, rtol=1e-9, atol=1e-12):
                raise self.fail("cov", "must be symmetric")
            name = "cov"
        elif self.has("cov_diag") or default is None:
            diag = self.vector("cov_diag", dim)
            P = np.diag(diag)
            name = "cov_diag"
        else:
            return default
        eig = np.linalg.eigvalsh(P)
        if eig.min() <= 1e-12 * max(1.0, float(np.abs(eig).max())):
            raise self.fail(name, f"must be positive definite (smallest eigenvalue {eig.min():g})")
        return tuple(tuple(float(x) for x in row) for row in P)


