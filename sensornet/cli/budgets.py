"""Budgets: a scenario over one refuses to start, naming the limit and the flag that lifts it."""

from __future__ import annotations

import argparse
import math

from sensornet.cli.common import (
    DEFAULT_MAX_PEERS,
    DEFAULT_MAX_POINTS,
    DEFAULT_MAX_TARGETS,
    UserError,
    default_memory_gb,
)
from sensornet.protocol.codec import DEFAULT_LIMITS

# --------------------------------------------------------------------------------------------
# Budgets: a scenario over one refuses to start, naming the limit and the flag that lifts it
# --------------------------------------------------------------------------------------------

PROCESS_MB = 200.0
"""Resident memory of one peer or world process with Rerun recording (measured 95-185 MB)."""


def points_per_scan(scn) -> dict[str, float]:
    """Expected measurements per scan of each sensor: clutter rate + targets alive at most."""
    targets = targets_at_once(scn)
    return {s.name: s.clutter_rate + targets * s.detection_probability for s in scn.sensors}


def targets_at_once(scn) -> int:
    """The most true targets alive at one scan."""
    if scn.truth != "straight" or not scn.targets:
        return max(1, len(scn.targets))
    edges = sorted([(t.birth_scan, 1) for t in scn.targets]
                   + [(t.death_scan + 1, -1) for t in scn.targets])
    alive = most = 0
    for _, step in edges:
        alive += step
        most = max(most, alive)
    return most


def memory_estimate_gb(scn, workers: int = 1, processes: int = 0) -> float:
    """A rough upper bound: per worker, every scan of a run held at once (16 bytes a point)
    plus the filter update's (measurement x component) working set (about 14 float64 a pair);
    plus :data:`PROCESS_MB` per process for a run over processes."""
    points = points_per_scan(scn)
    scans = scn.num_scans * sum(points.values()) * 16
    components = scn.filter.max_components + len(scn.birth.paper) + targets_at_once(scn)
    update = components * max(points.values(), default=0) * 14 * 8
    per_worker = 0.15e9 + scans + update
    return (max(1, workers) * per_worker + processes * PROCESS_MB * 1e6) / 1e9


def check_budget(scn, args: argparse.Namespace, workers: int = 1, processes: int = 0,
                 wire: bool = False) -> None:
    """Refuse a scenario over a budget (or, over processes, over what a message carries)."""
    max_points = getattr(args, "max_points", DEFAULT_MAX_POINTS)
    max_targets = getattr(args, "max_targets", DEFAULT_MAX_TARGETS)
    for name, n in points_per_scan(scn).items():
        if n > max_points:
            raise UserError(f"sensor {name} expects {n:,.0f} points per scan, over the budget "
                            f"of {max_points} (--max-points N lifts it)")
    targets = targets_at_once(scn)
    if targets > max_targets:
        raise UserError(f"{targets} true targets at once, over the budget of {max_targets} "
                        f"(--max-targets N lifts it)")
    if wire:
        for name, n in points_per_scan(scn).items():
            high = n + 6 * math.sqrt(n)
            if high > DEFAULT_LIMITS.max_measurements:
                raise UserError(f"sensor {name} expects {n:,.0f} points per scan: more than one "
                                f"scan message carries ({DEFAULT_LIMITS.max_measurements}); "
                                f"run it offline with 'sensornet experiment'")
        if targets >= DEFAULT_LIMITS.max_components:
            raise UserError(f"{targets} true targets at once: more than one truth message "
                            f"carries ({DEFAULT_LIMITS.max_components - 1}); run it offline "
                            f"with 'sensornet experiment'")
    if processes:  # the world's and the peers' (one each, or hosts of several)
        max_peers = getattr(args, "max_peers", DEFAULT_MAX_PEERS)
        if processes - 1 > max_peers:
            raise UserError(f"{len(scn.sensors)} sensors would start {processes - 1} peer "
                            f"processes on this machine, over the budget of {max_peers} "
                            f"(--max-peers N lifts it; --per-process N packs peers in hosts)")
    max_gb = getattr(args, "max_memory_gb", None) or default_memory_gb()
    need = memory_estimate_gb(scn, workers, processes)
    if need > max_gb:
        raise UserError(f"estimated memory {need:.1f} GB is over the budget of {max_gb:g} GB "
                        f"(--max-memory-gb X lifts it)")
