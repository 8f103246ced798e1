"""How ``sensornet run`` packs peers into processes when ``--per-process`` is not given.

A process per peer is the default: it is what makes ``kill -9`` of a peer real. It stops
keeping real time at about 20 peers on 2 cores (``benchmarks/bench_network.py``: 20 peers of
degree 4 kept real time in 1 run of 4, every process paying its own interpreter and Zenoh
session), so above :data:`PACK_ABOVE` peers the run packs them into one peer host per core.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass

PACK_ABOVE = 16
"""Largest network run as one process per peer when ``--per-process`` is not given."""


@dataclass(frozen=True)
class Packing:
    """Peers per process and, when chosen automatically, the line that says why."""

    per_process: int
    line: str = ""


def cores() -> int:
    """CPUs this process may run on (the affinity mask where there is one)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not Linux
        return max(1, os.cpu_count() or 1)


def choose(n_peers: int, asked: int | None, why_not: str = "",
           n_cores: int | None = None) -> Packing:
    """``asked`` (``--per-process N``) wins; else a process per peer up to
    :data:`PACK_ABOVE` peers or when ``why_not`` (what the run needs that hosts cannot do:
    secure mode, a fault of one process), else a host per core (at least 2 hosts, so one busy
    loop thread does not carry the whole network)."""
    if asked is not None:
        return Packing(asked)
    if n_peers <= PACK_ABOVE:
        return Packing(1)
    if why_not:
        return Packing(1, f"packing: {n_peers} peers one per process ({why_not}); above "
                          f"{PACK_ABOVE} they may not keep real time")
    hosts = min(n_peers, max(2, n_cores or cores()))
    per = math.ceil(n_peers / hosts)
    hosts = math.ceil(n_peers / per)
    return Packing(per, f"packing: {n_peers} peers into {hosts} host processes of up to {per} "
                        f"(one per core; a process per peer stops keeping real time above "
                        f"{PACK_ABOVE}); --per-process 1 for a process per peer")
