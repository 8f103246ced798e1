"""How ``sensornet run`` packs peers into processes when ``--per-process`` is not given.

A process per peer is the default: it is what makes ``kill -9`` of a peer real. It stops
keeping real time at about 20 peers on 2 cores (``benchmarks/bench_network.py``: 20 peers of
degree 4 kept real time in 1 run of 4, every process paying its own interpreter and Zenoh
session), so above :data:`PACK_ABOVE` peers the run packs them into peer hosts: as few as keep
each host's loop thread at most :data:`HOST_SHARE` busy, from what a peer of its kind costs
(:data:`PEER_COST_MS`; a host runs its peers one after another, so its busy share is its
latency), at most one per core; a host per core (at least 2) for a kind not measured.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass

import numpy as np
from scipy.sparse.csgraph import laplacian

PACK_ABOVE = 16
"""Largest network run as one process per peer when ``--per-process`` is not given."""


HOST_SHARE = 0.75
"""Cores a host's loop thread may be kept busy by its peers' work: a host runs its peers one
after another, so the last of its peers' tracks of a scan come about this share of a scan
interval after the scan; the rest is headroom for jitter. Set to 0.75 (was 0.5) after the
runs of 2026-12-03 evening in benchmarks/README.md: one host of 50 GM-PHD peers of degree 4
kept real time in 3 of 3 runs at 0.51-0.67 cores (p99 83-92 ms); those runs are the
evidence for the value, not an independent check of it."""

PEER_COST_MS = {"gmphd": 2.4, "lmb": 3.6, "flooding": 5.0}
"""CPU ms per peer per scan of a hosted peer, by kind (``network.filter``), rounded up from
the benchmarks: GM-PHD consensus peers of degree 4, two rounds, 1.93-2.38 ms and LMB peers
2.91-3.55 ms in hosts of 50 and 25 (``benchmarks/bench_fifty.py``, 4 Dec at load 3-5; the
GM-PHD's 0.94-1.46 ms of 3 Dec predates its labels); seed-004 flooding peers 3.7-4.8 ms in
hosts of 10. Kinds not here are packed a host per core."""


def peer_load(n_peers: int, kind: str, scans_per_s: float) -> float | None:
    """Cores the peers' work needs (``n`` peers of ``kind`` at ``scans_per_s``), or None for
    a kind whose cost was not measured."""
    cost = PEER_COST_MS.get(kind)
    return None if cost is None else n_peers * cost * scans_per_s / 1e3


def scenario_load(scn) -> float | None:
    """:func:`peer_load` of a scenario's peers at its scan rate (``scan_period / speed``)."""
    interval = scn.scan_period / scn.network.speed
    return peer_load(len(scn.sensors), scn.network.filter, 1.0 / interval)


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
           n_cores: int | None = None, load: float | None = None) -> Packing:
    """``asked`` (``--per-process N``) wins; else a process per peer up to
    :data:`PACK_ABOVE` peers or when ``why_not`` (what the run needs that hosts cannot do:
    secure mode, a fault of one process); else, given ``load`` (:func:`peer_load`: cores the
    peers' work needs), the fewest hosts that keep each under :data:`HOST_SHARE` of a core, at
    most one per core; without it a host per core (at least 2 hosts, so one busy loop thread
    does not carry a network of unknown cost)."""
    if asked is not None:
        return Packing(asked)
    if n_peers <= PACK_ABOVE:
        return Packing(1)
    if why_not:
        return Packing(1, f"packing: {n_peers} peers one per process ({why_not}); above "
                          f"{PACK_ABOVE} they may not keep real time")
    n_cores = n_cores or cores()
    if load is None:
        hosts = min(n_peers, max(2, n_cores))
        why = "one per core"
    else:
        hosts = min(n_peers, n_cores, max(1, math.ceil(load / HOST_SHARE - 1e-9)))
        why = (f"about {load:.2f} cores of peer work, at most {HOST_SHARE:g} a host and one "
               f"host per core")
    per = math.ceil(n_peers / hosts)
    hosts = math.ceil(n_peers / per)
    what = (f"1 host process of {per}" if hosts == 1
            else f"{hosts} host processes of up to {per}")
    return Packing(per, f"packing: {n_peers} peers into {what} ({why}; a process per peer "
                        f"stops keeping real time above {PACK_ABOVE}); --per-process 1 for a "
                        f"process per peer")


def cut_edges(A: np.ndarray, groups: list[list[int]]) -> int:
    """Edges of the symmetric adjacency ``A (n, n)`` between different groups."""
    label = np.empty(len(A), dtype=np.intp)
    for g, members in enumerate(groups):
        label[members] = g
    i, j = np.nonzero(np.triu(np.asarray(A, dtype=bool), 1))
    return int(np.count_nonzero(label[i] != label[j]))


def partition(A: np.ndarray, per_process: int) -> list[list[int]]:
    """Peers into groups of at most ``per_process`` with few edges between groups: recursive
    spectral bisection (each part split at the Fiedler vector of its own graph Laplacian,
    ``scipy.sparse.csgraph.laplacian``; Fiedler 1973, Pothen, Simon & Liou 1990), part sizes
    balanced to whole hosts. Every estimate along a cut edge crosses Zenoh between processes;
    inside a host it is handed over directly."""
    A = np.asarray(A, dtype=float)
    out: list[list[int]] = []

    def split(nodes: np.ndarray) -> None:
        k = math.ceil(len(nodes) / per_process)
        if k <= 1:
            out.append(sorted(nodes.tolist()))
            return
        left = round(len(nodes) * (k // 2) / k)
        sub = A[np.ix_(nodes, nodes)]
        _, vecs = np.linalg.eigh(laplacian(sub))
        order = np.argsort(vecs[:, 1], kind="stable")  # the Fiedler vector's order
        split(nodes[np.sort(order[:left])])
        split(nodes[np.sort(order[left:])])

    split(np.arange(len(A)))
    return out


def contiguous(n: int, per_process: int) -> list[list[int]]:
    """Peers in the scenario's order, ``per_process`` at a time."""
    return [list(range(i, min(i + per_process, n))) for i in range(0, n, per_process)]


def groups_for(A: np.ndarray | None, n: int, per_process: int) -> list[list[int]]:
    """The scenario's order unless a spectral partition of the graph cuts fewer edges (a
    ring's contiguous arcs are already optimal and stay as they were)."""
    plain = contiguous(n, per_process)
    if A is None or per_process <= 1 or per_process >= n:
        return plain
    spectral = partition(A, per_process)
    return spectral if cut_edges(A, spectral) < cut_edges(A, plain) else plain
