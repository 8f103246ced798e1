"""The ``[manoeuvre]`` section: the one manoeuvring target of truth ``"seed001"`` (seed 001's
ground target, docs/seed001.md), as legs at constant speed, each straight or a constant-rate
turn, and the spread of the filters' initial estimate about its first state. Each option is
declared once in its field (:func:`sim.scenario.options.option`); the offline study's
``Seed001Scenario`` takes its defaults from here. Re-exported by :mod:`sim.scenario.model`."""

from __future__ import annotations

from dataclasses import dataclass

from sensornet.sim.scenario.options import POSITIVE, option


@dataclass(frozen=True)
class ManoeuvreSpec:
    """Seed 001's manoeuvring target: constant-speed legs, straight or turning (truth "seed001")."""

    start: tuple[float, float] = option((6000.0, 8400.0), doc="Position `[x, y]` at time 0.",
                                        unit="m")
    speed: float = option(23.0, doc="Speed, constant over every leg.", unit="m/s",
                          check=POSITIVE)
    heading_deg: float = option(-29.36, doc="Initial heading, counter-clockwise from east "
                                            "(-29.36: 29.36 degrees south of east).", unit="deg")
    segments: tuple[tuple[float, float], ...] = option(
        ((180.0, 0.0), (80.0, 1.15), (110.0, 0.0), (140.0, -0.43), (140.0, 0.0)),
        doc="The legs, `[[duration, turn rate], ...]`: duration in s (a whole number of scans), "
            "turn rate in deg/s (positive: left, 0: straight); the run may be shorter than "
            "their total, not longer.", unit="s, deg/s",
        custom="seed 001's five legs, 650 s: `[[180, 0], [80, 1.15], [110, 0], [140, -0.43], "
               "[140, 0]]`")
    init_sigma: tuple[float, ...] = option(
        (20.0, 2.0, 0.05), doc="Spread of the initial estimate per axis: position, velocity, "
                               "acceleration.", unit="m, m/s, m/s^2",
        custom="`[20, 2, 0.05]`")
