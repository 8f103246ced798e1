"""The one ``--set`` grammar: ``KEY=VALUE`` items, dotted keys into the raw TOML."""

from __future__ import annotations

import copy
import re
import tomllib
from collections.abc import Iterable, Mapping
from typing import Any

from sensornet.sim.scenario.model import ScenarioError


def parse_overrides(items: Iterable[str]) -> dict[str, Any]:
    """``["filter.gate=9.21", "fusion.rule=aa"]`` → ``{"filter.gate": 9.21, ...}`` (for CLIs).

    The value is read as a TOML value (``20``, ``1e-4``, ``true``, ``[1, 2]``, ``"s2"``); text that
    is not valid TOML is taken as a bare string, so ``fusion.rule=aa`` works unquoted.
    """
    out: dict[str, Any] = {}
    for item in items:
        key, sep, raw = item.partition("=")
        key, raw = key.strip(), raw.strip()
        if not sep or not key:
            raise ScenarioError(f"override {item!r}: expected KEY=VALUE, e.g. filter.gate=9.21")
        try:
            out[key] = tomllib.loads(f"v = {raw}")["v"]
        except tomllib.TOMLDecodeError:
            out[key] = raw
    return out


# --------------------------------------------------------------------------------------------
# Overrides
# --------------------------------------------------------------------------------------------

_TOKEN = re.compile(r"\[([^\]]*)\]|([^.\[\]]+)")


def _flatten(overrides: Mapping[str, Any], prefix: str = "") -> Iterable[tuple[str, Any]]:
    for key, value in overrides.items():
        path = f"{prefix}.{key}" if prefix else str(key)
        if isinstance(value, Mapping):
            yield from _flatten(value, path)
        else:
            yield path, value


def apply_overrides(data: dict, overrides: Mapping[str, Any], label: str) -> set[str]:
    """Write ``overrides`` into the raw TOML ``data``; return the normalised paths written."""
    written: set[str] = set()
    for key, value in _flatten(overrides):
        tokens = [m.group(1) if m.group(1) is not None else m.group(2)
                  for m in _TOKEN.finditer(key)]
        if not tokens or "".join(_TOKEN.sub("", key).split(".")):
            raise ScenarioError(f"{label} (overrides): malformed key {key!r}")
        for path in _set_path(data, tokens, copy.deepcopy(value), "", key, label):
            written.add(path)
    return written


def _set_path(node: Any, tokens: list[str], value: Any, path: str, key: str,
              label: str) -> list[str]:
    head, rest = tokens[0], tokens[1:]
    if isinstance(node, list):
        if head == "*":
            picks = list(range(len(node)))
        elif head.lstrip("-").isdigit():
            picks = [int(head)]
        else:
            picks = [i for i, e in enumerate(node) if isinstance(e, dict) and e.get("name") == head]
        if not picks or not all(0 <= i < len(node) for i in picks):
            raise ScenarioError(
                f"{label} (overrides): key {key!r}: no entry {head!r} in '{path}' "
                f"(it has {len(node)} entries)"
            )
        if not rest:
            for i in picks:
                node[i] = value
            return [f"{path}[{i}]" for i in picks]
        return [p for i in picks
                for p in _set_path(node[i], rest, value, f"{path}[{i}]", key, label)]
    if not isinstance(node, dict):
        raise ScenarioError(f"{label} (overrides): key {key!r}: '{path}' is not a table")
    here = f"{path}.{head}" if path else head
    if not rest:
        node[head] = value
        return [here]
    child = node.setdefault(head, {})
    return _set_path(child, rest, value, here, key, label)


