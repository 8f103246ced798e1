"""What the registries of peer kinds (:mod:`sim.kinds`) and studies (:mod:`sim.studies`)
share: entries named ``"module:attribute"``, imported on first use, and a plug-in's entries
from an environment variable (inherited by every process a run or campaign starts).

Standard library only: both registries import it, and the command line's parser imports the
studies' registry.
"""

from __future__ import annotations

import importlib
import os
from typing import Any


def from_env(var: str) -> dict[str, str]:
    """``$VAR`` = comma-separated ``"name=module:attribute"`` entries -> ``{name: target}``;
    :class:`ValueError` naming the variable for an entry of another shape."""
    out = {}
    for item in filter(None, (x.strip() for x in os.environ.get(var, "").split(","))):
        name, sep, target = item.partition("=")
        if not sep or ":" not in target:
            raise ValueError(f"{var}: {item!r} is not 'name=module:attribute'")
        out[name.strip()] = target.strip()
    return out


def load(target: str) -> Any:
    """The object ``"module:attribute"`` names (its module imported now)."""
    module, _, attr = target.partition(":")
    return getattr(importlib.import_module(module), attr)
