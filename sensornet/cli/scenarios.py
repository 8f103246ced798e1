"""The scenario a command plays: its file or built-in name with the ``--set`` overrides, and the
warnings its fusion settings earn."""

from __future__ import annotations

import argparse
import sys

from sensornet.sim.scenario import load_scenario, parse_overrides
from sensornet.sim.studies.fusion.advice import fusion_warnings


def load(args: argparse.Namespace, source: str):
    """Scenario ``source`` with the command line's ``--set`` items on top."""
    return load_scenario(source, overrides=parse_overrides(getattr(args, "set", None) or []))


def warn_fusion(scn) -> None:
    """One line per fusion setting the fusion-quality study measured to hurt."""
    for line in fusion_warnings(scn):
        print(f"warning: {line}", file=sys.stderr, flush=True)
