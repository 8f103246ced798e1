"""The x-y plots' noise for a new recording: ``plot_sigma`` by the rule of docs/real-traffic.md,
measured on a training window of the scenario's own traffic (issue 34).

A radar's x-y plot is off the aircraft at its tick by the radar's own error (range ``sigma_r``
along, ``r sigma_theta`` across the line of sight) plus the time alignment: the aircraft flew
on for up to one tick since the beam crossed it (``sim.traffic.recorded``). The scenarios take
one fixed per-axis noise per radar,

    plot_sigma = sqrt((r_med sigma_theta)^2 + a_rms^2),

``r_med`` the median ground range of the radar's aircraft plots and ``a_rms`` the rms alignment
error over every radar's aircraft plots (:func:`sim.traffic.recorded.alignment_errors`). Both
depend on the traffic, not only on the sites: Paris's approaches (about 130 m/s) gave
``a_rms`` 161 m at 2 s ticks, Swiss cruise traffic (about 230 m/s) 271 m. Measure it on a
window before the one you evaluate on:

    python -m sensornet.sim.traffic.calibrate switzerland-8 --set traffic.start=... \\
        --set scenario.num_scans=...

prints each radar's numbers and the ``--set sensors.NAME.plot_sigma=V`` arguments.
"""

from __future__ import annotations

import argparse
import math
import sys
from dataclasses import dataclass

import numpy as np
from sensornet.sim.scenario import Scenario, ScenarioError, load_scenario, parse_overrides
from sensornet.sim.traffic.recorded import alignment_errors, recorded_world, tick_plots


@dataclass(frozen=True)
class PlotSigma:
    """One radar's numbers of the ``plot_sigma`` rule (metres)."""

    name: str
    plots: int
    """Aircraft plots the median is over (clutter left out)."""
    median_range_m: float
    cross_range_m: float
    """``median_range_m x sigma_theta`` (radians)."""
    alignment_rms_m: float
    """The rms alignment error over every radar's aircraft plots (one number for all)."""
    plot_sigma_m: float


def plot_sigmas(scn: Scenario, run: int = 0) -> list[PlotSigma]:
    """The rule's ``plot_sigma`` for every sensor of ``scn`` (a ``truth = "recorded"``
    scenario), from radar-noise run ``run`` over the scenario's window (module docstring)."""
    if scn.truth != "recorded":
        raise ScenarioError(f"{scn.name}: plot_sigma is measured on recorded traffic "
                            f"(scenario.truth = 'recorded'), not {scn.truth!r}")
    world = recorded_world(scn)
    err = alignment_errors(scn, run)
    err = err[np.isfinite(err)]
    if len(err) == 0:
        raise ScenarioError(f"{scn.name}: no aircraft plot in the window: nothing to measure")
    a_rms = float(np.sqrt(np.mean(err ** 2)))
    out = []
    for spec, radar, p in zip(scn.sensors, world.radars, tick_plots(scn, run), strict=True):
        real = p.truth != ""
        r = np.linalg.norm(p.z_xy[real] - radar.site(world.frame)[:2], axis=1)
        r_med = float(np.median(r)) if len(r) else math.nan
        cross = r_med * math.radians(spec.sigma_theta_deg or 0.0)
        out.append(PlotSigma(name=spec.name, plots=int(real.sum()), median_range_m=r_med,
                             cross_range_m=cross, alignment_rms_m=a_rms,
                             plot_sigma_m=math.hypot(cross, a_rms)))
    return out


def table(rows: list[PlotSigma]) -> str:
    """A markdown table of :func:`plot_sigmas`' rows."""
    lines = ["| radar | aircraft plots | median range (km) | cross-range sd (m) | "
             "alignment rms (m) | plot_sigma (m) |", "|---|---:|---:|---:|---:|---:|"]
    lines += [f"| {r.name} | {r.plots} | {r.median_range_m / 1000:.1f} | {r.cross_range_m:.0f} "
              f"| {r.alignment_rms_m:.0f} | {r.plot_sigma_m:.0f} |" for r in rows]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m sensornet.sim.traffic.calibrate",
        description="plot_sigma by the rule of docs/real-traffic.md, measured on the scenario's "
                    "window (use a training window before the one you evaluate)")
    ap.add_argument("scenario", help="a shipped scenario name or a scenario file")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help="scenario override (e.g. traffic.start=..., scenario.num_scans=...)")
    ap.add_argument("--run", type=int, default=0, help="the radars' noise seed")
    args = ap.parse_args(argv)
    try:
        scn = load_scenario(args.scenario, parse_overrides(args.set))
        rows = plot_sigmas(scn, args.run)
    except ValueError as e:  # ScenarioError included: one line, the user's to fix
        print(f"calibrate: error: {e}", file=sys.stderr)
        return 2
    print(table(rows))
    print(" ".join(f"--set sensors.{r.name}.plot_sigma={r.plot_sigma_m:.0f}" for r in rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
