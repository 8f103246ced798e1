"""What every scenario section shares: the fixed vocabularies of its keys (sensor kinds, PDA
methods, fault keys, ...), the matrix type, and :class:`ScenarioError` (split from
:mod:`sim.scenario.model`, which re-exports every name)."""

from __future__ import annotations

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
LIE_KINDS = ("empty", "shifted", "inflated", "phantoms", "biased", "stuck")
"""The lies ``fusion.lie`` names (the test hook; what each does: :mod:`sim.run.lies`)."""
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


class ScenarioError(ValueError):
    """A user error in a scenario file or override; the message is one line naming the key."""
