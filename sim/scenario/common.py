"""What every scenario section shares: the fixed vocabularies of its keys (sensor kinds, PDA
methods, fault keys, ...), the matrix type, and :class:`ScenarioError` (split from
:mod:`sim.scenario.model`, which re-exports every name)."""

from __future__ import annotations

import math
from collections.abc import Iterable

from sensornet.sim.choices import OMEGA_RULES
from sensornet.sim.kinds import names as kind_names
from sensornet.sim.truths import names as truth_names

STATE_DIM = 4
"""State ``[px, vx, py, vy]``."""
TRUTH_MODELS = truth_names()
"""The shipped truth models (:mod:`sim.truths`; the loader asks the registry)."""
MOTION_MODELS = ("cv",)
SENSOR_KINDS = ("linear", "range-bearing")
NETWORK_OMEGA_RULES = OMEGA_RULES
"""The old name of :data:`OMEGA_RULES` (one set of weights for the network and the fusing
sensor)."""
PEER_FILTERS = kind_names()
"""The peer kinds known at import (:mod:`sim.kinds`; the loader asks the registry, which also
knows plug-ins registered later)."""
FLOOD_ESTIMATORS = ("idpc", "ftc", "ic")
"""What a flooding peer makes of its pooled scans (seed 004): density-peaks clustering, the
FTC baseline, or the iterated-corrector GM-PHD (``clustering.estimator``)."""
LIE_KINDS = ("empty", "shifted", "inflated", "phantoms", "biased", "stuck", "drift")
"""The lies ``fusion.lie`` names (the test hook; what each does: :mod:`sim.run.lies`);
``drift`` takes its rate as ``"drift:RATE"`` (m/scan; :func:`parse_lie`)."""
PARTITIONS = ("distance", "grid-spectral")
K_RULES = ("eigengap", "core-regions")
DISTANCE_UNITS = ("sigma", "unit-box")
ASSUMED_SCANS = ("held", "all")
PDA_MODES = ("meas", "ci")
PDA_METHODS = ("PDAF", "IMM-PDAF", "fuzzy PDA", "fuzzy IMM")
TOPOLOGIES = ("full", "ring", "star", "line", "custom")
FAULT_KEYS = ("delay", "loss", "duplicate", "reorder", "reorder_delay", "partitions")
"""The keys of a ``[faults.default]``, ``[faults.peers.<name>]`` or ``faults.links`` entry."""
DELAY_KINDS = {"constant": ("value",), "uniform": ("low", "high"), "exponential": ("mean",),
               "scans": ("low", "high"), "short": (), "one-step": (), "multi-step": ("max_steps",)}
"""Delay kinds and the parameters each needs."""
Matrix = tuple[tuple[float, ...], ...]


def _diag(values: Iterable[float]) -> Matrix:
    """A diagonal matrix as nested tuples."""
    v = [float(x) for x in values]
    return tuple(tuple(x if i == j else 0.0 for j in range(len(v))) for i, x in enumerate(v))


def listing(options: Iterable[str]) -> str:
    """The choices of a key, quoted, for error messages."""
    return ", ".join(repr(o) for o in options)


def parse_lie(kind: str) -> tuple[str, float | None]:
    """``"KIND"`` of :data:`LIE_KINDS`, or ``"drift:RATE"`` (a positive, finite number of
    metres per scan), as ``(KIND, RATE or None)``; a ValueError in one line otherwise."""
    name, sep, arg = str(kind).partition(":")
    if name not in LIE_KINDS:
        raise ValueError(f"unknown lie {name!r}; expected one of {listing(LIE_KINDS)}")
    if not sep:
        return name, None
    if name != "drift":
        raise ValueError(f"lie {name!r} takes no value, got {kind!r}")
    try:
        rate = float(arg)
    except ValueError:
        rate = math.nan
    if not (math.isfinite(rate) and rate > 0.0):
        raise ValueError(f"the drift lie's rate must be a positive number of metres per scan "
                         f"(\"drift:2\"), got {arg!r}")
    return name, rate


class ScenarioError(ValueError):
    """A user error in a scenario file or override; the message is one line naming the key."""
