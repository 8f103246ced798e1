"""Loading a scenario: a file or a built-in name, overrides, a study's own format."""

from __future__ import annotations

import tomllib
from collections.abc import Mapping
from importlib import resources
from pathlib import Path
from typing import Any

from sensornet.sim.formats import adapt_document
from sensornet.sim.scenario.model import Scenario, ScenarioError
from sensornet.sim.scenario.overrides import apply_overrides
from sensornet.sim.scenario.parse import parse_document
from sensornet.sim.scenario.tables import Context

# --------------------------------------------------------------------------------------------
# Built-in scenarios
# --------------------------------------------------------------------------------------------


def _builtin_dir():
    return resources.files("sensornet.sim").joinpath("scenarios")


def builtin_scenarios() -> list[str]:
    """Names of the scenarios shipped in ``sim/scenarios/`` (``["seed000", ...]``)."""
    return sorted(
        p.name[: -len(".toml")] for p in _builtin_dir().iterdir() if p.name.endswith(".toml")
    )


def scenario_text(name: str) -> str:
    """The text of a built-in scenario file (for ``scenario show`` and for copying)."""
    key = name[: -len(".toml")] if name.endswith(".toml") else name
    if key not in builtin_scenarios():
        raise ScenarioError(
            f"no built-in scenario {name!r} (built-in: {', '.join(builtin_scenarios())})"
        )
    return _builtin_dir().joinpath(f"{key}.toml").read_text(encoding="utf-8")


# --------------------------------------------------------------------------------------------
# Loading
# --------------------------------------------------------------------------------------------


def load_scenario(source: str | Path, overrides: Mapping[str, Any] | None = None) -> Scenario:
    """Read and validate a scenario from a ``.toml`` path or a built-in name (``"seed000"``).

    ``overrides`` changes values before validation, so they are checked like the file. Keys are
    dotted paths (``{"filter.gate": 9.21}``, ``{"sensors[1].clutter_rate": 20}``; a list entry
    is picked by index, by its ``name`` (``"sensors.s2.sigma_r"``) or all at once with ``*``
    (``"sensors.*.clutter_rate"``)) or nested tables (``{"filter": {"gate": 9.21}}``).
    """
    path = Path(source)
    if path.is_file():
        label, origin, stem = (path.name if path.parent == Path() else str(path), str(path),
                               path.stem)
        text = path.read_text(encoding="utf-8")
    else:
        key = str(source)
        key = key[: -len(".toml")] if key.endswith(".toml") else key
        if key not in builtin_scenarios():
            raise ScenarioError(
                f"{source}: no such scenario file or built-in scenario "
                f"(built-in: {', '.join(builtin_scenarios())})"
            )
        label, origin, stem = f"{key}.toml", f"builtin:{key}", key
        text = scenario_text(key)
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"{label}: invalid TOML: {exc}") from None
    return load_document(data, label, overrides, stem, origin)


def load_document(data: dict, label: str, overrides: Mapping[str, Any] | None = None,
                  name: str = "scenario", origin: str = "") -> Scenario:
    """A scenario from an already-read TOML document (``data`` is changed in place by the
    overrides): what :func:`load_scenario` does after reading the file. ``label`` names it in
    error messages, ``name`` is the default ``scenario.name``."""
    offline = data.get("scenario", {}).get("offline") if isinstance(data.get("scenario"),
                                                                    dict) else None
    if offline:  # e.g. seed003.toml: read by its own study, no network peers yet
        raise ScenarioError(f"{label}: an offline study, not a network scenario; run '{offline}'")
    ctx = Context(label)
    if overrides:
        ctx.override_paths = apply_overrides(data, overrides, label)
    study = data.get("scenario", {}).get("study") if isinstance(data.get("scenario"),
                                                                dict) else None
    if study is not None:  # a study's own format: the network scenario is built from it
        try:
            data = adapt_document(study, data, label)
        except KeyError as exc:
            raise ScenarioError(str(exc.args[0])) from None
    return parse_document(data, ctx, default_name=name, origin=origin or label)


