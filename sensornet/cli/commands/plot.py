"""``plot``: a run's per-scan results drawn (tracks.png, metrics.png)."""

from __future__ import annotations

import argparse
from pathlib import Path

from sensornet.cli.common import UserError
from sensornet.sim.report.run_plots import PlotError, plot_run


def cmd_plot(args: argparse.Namespace) -> int:
    """``sensornet plot RUN``: tracks.png and metrics.png from the run's per-scan results."""
    try:
        paths = plot_run(Path(args.dir), Path(args.out) if args.out else None)
    except (PlotError, ValueError, OSError) as exc:
        raise UserError(str(exc)) from None
    for p in paths:
        print(p)
    return 0
