"""The ``[pda]`` section: single-target PDA peers (seed 003, ``network.filter = "pda"``) and
seed 003's own settings as typed sub-tables (``[pda.target]``, ``[pda.clutter]``,
``[pda.filters]``, ``[pda.detector]``, ``[pda.fuzzy]``), each option declared once in its
field (:func:`sim.scenario.options.option`); :func:`sim.scenario.model.pda_tables` gives them to
the seed-003 world and filters in the nested form those read. Re-exported by
:mod:`sim.scenario.model`."""

from __future__ import annotations

from dataclasses import dataclass

from sensornet.sim.scenario.common import PDA_METHODS, PDA_MODES, Matrix
from sensornet.sim.scenario.options import NONNEGATIVE, POSITIVE, Bound, at_least, option
from sensornet.tracking.fuzzy import WEIGHTING_MODES

MANOEUVRES = ("coordinated", "literal")
"""Seed 003's turn: 90 degrees over the turn scans, or the paper's literal legs (a_y = 5 g)."""
CLUTTER_MODES = ("gate", "region")
IMM_MODELS = ("ca", "ct")
"""The IMM's manoeuvre model: CV + CA, or CV + coordinated turns at +/- the turn rate."""
GATE_PROBABILITY = 0.99
"""Each sensor's gate probability ``PG`` when ``pda.gate_probability`` is not given."""
OPEN_PROBABILITY = Bound(0, 1, low_open=True, high_open=True)
"""``(0, 1)``."""


@dataclass(frozen=True)
class PdaTarget:
    """Seed 003's one target: straight, a turn over ``turn_scans``, straight (docs/seed003.md)."""

    start: tuple[float, float] = option((0.0, 5000.0), doc="Position `[x, y]` at scan 0.",
                                        unit="m")
    speed: float = option(500.0, doc="Speed along x at scan 0.", unit="m/s", check=POSITIVE)
    turn_scans: tuple[int, int] = option((51, 70), doc="First and last scan of the manoeuvre.",
                                         unit="scan", custom="`[51, 70]`")
    manoeuvre: str = option("coordinated", doc="`\"coordinated\"`: 90 degrees over the turn "
                                               "scans; `\"literal\"`: the paper's legs (a_y = 5 "
                                               "g).", choices=MANOEUVRES)


@dataclass(frozen=True)
class PdaClutter:
    """Seed 003's clutter: in each filter's gate, or over a square about the target (peers).

    The peers take ``"region"``: every peer sees the world's clutter."""

    mode: str = option("region", doc="`\"gate\"`: Poisson(`in_gate`) returns in each filter's "
                                     "own gate; `\"region\"`: uniform over a square of "
                                     "half-width `halfwidth` about the truth, of the density "
                                     "that puts `in_gate` in the steady-state CV gate.",
                       choices=CLUTTER_MODES)
    in_gate: float = option(2.0, doc="Mean number of clutter returns in a sensor's gate.",
                            check=NONNEGATIVE)
    halfwidth: float = option(2000.0, doc="`\"region\"`: half-width of the clutter square.",
                              unit="m", check=POSITIVE)


@dataclass(frozen=True)
class PdaFilters:
    """Seed 003's filter models (sim.kinds.pda_filters)."""

    model: str = option("ca", doc="Manoeuvre model: `\"ca\"` (CV + CA) or `\"ct\"` (CV + turns "
                                  "at +- `turn_rate_deg`).", choices=IMM_MODELS)
    sigma_cv: float = option(2.0, doc="CV white acceleration.", unit="m/s^2",
                             check=NONNEGATIVE)
    sigma_ca: float = option(30.0, doc="CA acceleration change per scan.", unit="m/s^2",
                             check=NONNEGATIVE)
    turn_rate_deg: float = option(4.5, doc="`\"ct\"`: turn rate of the two turn models.",
                                  unit="deg/s", check=POSITIVE)
    sigma_ct: float = option(5.0, doc="`\"ct\"`: white acceleration of the turn models.",
                             unit="m/s^2", check=NONNEGATIVE)
    transition: Matrix = option(((0.95, 0.05), (0.05, 0.95)),
                                doc="IMM Markov matrix (2 x 2, rows sum to 1; `\"ct\"` splits "
                                    "the second row and column between the turns).",
                                custom="`[[0.95, 0.05], [0.05, 0.95]]`")
    initial_probs: tuple[float, ...] = option((0.9, 0.1), doc="Initial model probabilities (2, "
                                                              "summing to 1).",
                                              custom="`[0.9, 0.1]`")
    init_sigma: tuple[float, ...] = option((100.0, 50.0, 5.0),
                                           doc="Initial error standard deviations: position, "
                                               "velocity, acceleration.",
                                           unit="m, m/s, m/s^2", custom="`[100, 50, 5]`")


@dataclass(frozen=True)
class PdaDetector:
    """The fuzzy filters' manoeuvre detector (tracking.fuzzy)."""

    window: int = option(5, doc="`L`: scans in the detector's window.", unit="scan",
                         check=at_least(1))
    false_alarm: float = option(0.01, doc="Neyman-Pearson false-alarm rate per scan.",
                                check=OPEN_PROBABILITY)


@dataclass(frozen=True)
class PdaFuzzy:
    """The fuzzy association degree ``mu(g, D)`` of seed 003's fuzzy filters (tracking.fuzzy).

    Gaussian membership functions of a return's NIS ``g`` and the detector's ``D``, and the
    rules joining them."""

    mode: str = option("switched", doc="`\"switched\"`: `mu beta` only while the detector fires; "
                                       "`\"always\"`.", choices=WEIGHTING_MODES)
    rules: tuple[tuple[str, str, str], ...] = option(
        (("small", "low", "high"), ("medium", "low", "medium"), ("large", "low", "low"),
         ("small", "high", "medium"), ("medium", "high", "high"), ("large", "high", "high")),
        doc="`[nis term, D term, output term]` per rule.", custom="seed 003's six rules")
    nis: tuple[tuple[str, float, float], ...] = option(
        (("small", 0.0, 2.0), ("medium", 5.0, 2.0), ("large", 10.0, 3.0)),
        doc="NIS terms: `[pda.fuzzy.inputs.nis]` `NAME = [centre, width]`.", key="inputs.nis",
        custom="small `[0, 2]`, medium `[5, 2]`, large `[10, 3]`")
    dl: tuple[tuple[str, float, float], ...] = option(
        (("low", 1.0, 0.7), ("high", 4.0, 1.5)),
        doc="`D` terms: `[pda.fuzzy.inputs.dl]` `NAME = [centre, width]`.", key="inputs.dl",
        custom="low `[1, 0.7]`, high `[4, 1.5]`")
    outputs: tuple[tuple[str, float], ...] = option(
        (("low", 0.1), ("medium", 0.5), ("high", 0.9)),
        doc="Output terms: `[pda.fuzzy.outputs]` `NAME = centre`.",
        custom="low 0.1, medium 0.5, high 0.9")

    def config(self) -> dict:
        """The nested form :meth:`tracking.fuzzy.FuzzySystem.from_config` reads."""
        return {"mode": self.mode, "rules": [list(r) for r in self.rules],
                "inputs": {"nis": {n: [c, w] for n, c, w in self.nis},
                           "dl": {n: [c, w] for n, c, w in self.dl}},
                "outputs": dict(self.outputs)}


@dataclass(frozen=True)
class PdaSpec:
    """Single-target PDA peers (seed 003, ``network.filter = "pda"``; ``[pda]`` table)."""

    mode: str = option("meas", doc="`\"meas\"`: measurement sharing with the sequential update "
                                   "(the paper's scheme); `\"ci\"`: estimate sharing fused by "
                                   "covariance intersection.", choices=PDA_MODES)
    method: str = option("fuzzy IMM", doc="The filter: `\"PDAF\"`, `\"IMM-PDAF\"`, `\"fuzzy "
                                          "PDA\"` or `\"fuzzy IMM\"`.", choices=PDA_METHODS)
    pregate: float = option(4.0, doc="Measurement sharing publishes the returns inside "
                                     "`pregate` x the gate threshold.", check=POSITIVE)
    gate_probability: tuple[float, ...] = option(
        (), doc="`PG` per sensor, in `[[sensors]]` order (below 1: a finite gate).",
        custom=f"{GATE_PROBABILITY} for every sensor")
    loss_bound: float = option(1000.0, doc="A track is lost when its position error exceeds "
                                           "this for `loss_scans` consecutive scans.", unit="m",
                               check=POSITIVE)
    loss_scans: int = option(5, doc="See `loss_bound`.", unit="scan", check=at_least(1))
    target: PdaTarget = option(PdaTarget(), doc="The target (`[pda.target]`).",
                               custom="the defaults of `[pda.target]`")
    clutter: PdaClutter = option(PdaClutter(), doc="Clutter (`[pda.clutter]`).",
                                 custom="the defaults of `[pda.clutter]`")
    filters: PdaFilters = option(PdaFilters(), doc="Filter models (`[pda.filters]`).",
                                 custom="the defaults of `[pda.filters]`")
    detector: PdaDetector = option(PdaDetector(), doc="Manoeuvre detector (`[pda.detector]`).",
                                   custom="the defaults of `[pda.detector]`")
    fuzzy: PdaFuzzy = option(PdaFuzzy(), doc="Fuzzy association (`[pda.fuzzy]`).",
                             custom="the defaults of `[pda.fuzzy]`")
