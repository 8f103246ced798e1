"""Generated peer networks: circulant graphs and seed-000-like scenarios on them.

The networks the scale benchmarks and the fusion-quality study run (``benchmarks/
bench_network.py``, ``sim/studies/fusion/quality.py``): ``n`` linear sensors with seed 000's
targets,
noise and clutter, on a circulant graph (a ring is degree 2).
"""

from __future__ import annotations

import numpy as np
from sensornet.sim.scenario import load_scenario


def circulant(n: int, degree: int) -> np.ndarray:
    """The adjacency ``(n, n)`` of a circulant graph: node i linked to i +- 1 .. i +- degree/2,
    and for an odd degree (n even) to i + n/2."""
    A = np.zeros((n, n), dtype=bool)
    i = np.arange(n)
    for s in range(1, degree // 2 + 1):
        A[i, (i + s) % n] = A[(i + s) % n, i] = True
    if degree % 2 == 1 and n % 2 == 0:
        A[i, (i + n // 2) % n] = True
    np.fill_diagonal(A, False)
    return A


def network_scenario(n: int, degree: int, scans: int = 100, rounds: int = 1,
                     speed: float = 10.0, deadline: float = 0.9,
                     detection_probability: float = 0.99, clutter_rate: float = 10,
                     name: str | None = None) -> str:
    """Scenario text: seed 000's targets and sensor model, ``n`` linear sensors on a circulant
    graph of ``degree``, births at the true birth points, default fusion settings."""
    base = load_scenario("seed000")
    lines = [
        "[scenario]", f'name = "{name or f"scale{n}d{degree}"}"', "seed = 0",
        "scan_period = 1.0", f"num_scans = {scans}",
        "region = [[-1000.0, 1000.0], [-1000.0, 1000.0]]",
        "[motion]", "sigma_w = 2.0", "survival_probability = 0.99",
    ]
    for t in base.targets:
        lines += ["[[targets]]", f"birth_scan = {t.birth_scan}", f"death_scan = {t.death_scan}",
                  f"start = {list(t.start)}", f"end = {list(t.end)}"]
    names = [f"p{i:02d}" for i in range(n)]
    for i, sensor in enumerate(names):
        pos = base.sensors[i % len(base.sensors)].position
        lines += ["[[sensors]]", f'name = "{sensor}"', 'kind = "linear"',
                  f"position = {list(pos)}", "sigma_r = 20.0",
                  f"detection_probability = {detection_probability}",
                  f"clutter_rate = {clutter_rate}"]
    edges = np.argwhere(np.triu(circulant(n, degree)))  # (a, b), a < b, sorted
    edge_text = ", ".join(f'["{names[a]}", "{names[b]}"]' for a, b in edges)
    lines += ['[birth]', 'model = "truth"', "[fusion]", f'fusing_sensor = "{names[0]}"',
              "[network]", 'topology = "custom"', f"edges = [{edge_text}]", f"rounds = {rounds}",
              f"speed = {speed}", f"deadline = {deadline}"]
    return "\n".join(lines) + "\n"
