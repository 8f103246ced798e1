"""Fault-parameter sweeps: mean OSPA per setting and out-of-sequence policy over Monte Carlo runs.

Each (value, policy, run) is one run of the scenario with ``param = value`` and
``network.policy = policy``: on the discrete-event twin by default (fast, reproducible), or as
real processes over Zenoh (``real=True``). Writes ``sweep.csv`` (one row per run) and
``sweep.png`` (mean fused OSPA against the value, a line per policy).
"""

from __future__ import annotations

import csv
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from sensornet.sim.report.report_plots import plt_module
from sensornet.sim.run.launcher import read_summaries, start_run, wait_run
from sensornet.sim.run.pool import map_runs
from sensornet.sim.run.twin import run_twin
from sensornet.sim.scenario import load_scenario


@dataclass(frozen=True)
class SweepPoint:
    value: Any
    policy: str
    run: int


def _overrides(base: dict, param: str, value: Any, policy: str) -> dict:
    return {**base, param: value, "network.policy": policy}


def run_point(source: str, base: dict, param: str, point: SweepPoint, real: bool) -> dict:
    """One run; returns its row (fused and local OSPA averaged over the peers, counters)."""
    scn = load_scenario(source, overrides=_overrides(base, param, point.value, point.policy))
    row: dict[str, Any] = {"param": param, "value": point.value, "policy": point.policy,
                           "run": point.run}
    if real:
        sets = [f"{k}={_toml(v)}" for k, v in _overrides(base, param, point.value,
                                                         point.policy).items()]
        with tempfile.TemporaryDirectory(prefix="sensornet-sweep-") as tmp:
            handle = start_run(scn, source, Path(tmp), overrides=sets, run=point.run,
                               rerun=False)
            try:
                wait_run(handle, timeout=scn.num_scans * scn.scan_period / scn.network.speed
                         + 90)
            finally:
                handle.stop_all()
            summaries = read_summaries(Path(tmp), scn.sensor_names)
        row["fused_ospa"] = float(np.mean([s["mean_ospa_fused"] for s in summaries.values()]))
        row["local_ospa"] = float(np.mean([s["mean_ospa_local"] for s in summaries.values()]))
        for key in ("late", "redundant", "too_old", "dropped_late"):
            row[key] = sum(s["nale"][key] for s in summaries.values())
        row.update(cost_columns([s.get("cost") or {} for s in summaries.values()]))
        return row
    result = run_twin(scn, point.run)
    peers = result.peers.values()
    row["fused_ospa"] = float(np.mean([p.mean_ospa("fused") for p in peers]))
    row["local_ospa"] = float(np.mean([p.mean_ospa("local") for p in peers]))
    for key in ("late", "redundant", "too_old", "dropped_late"):
        row[key] = sum(getattr(p.consensus.nale.counts, key) for p in peers)
    row.update(cost_columns([p.cost() for p in peers]))
    if result.faults is not None:
        for action, n in result.faults.counts().items():
            row[f"links_{action}"] = n
    return row


def cost_columns(costs: list[dict]) -> dict[str, float]:
    """Communication cost per peer per scan, averaged over the peers (``PeerCore.cost``)."""
    return {"tuples_per_peer_scan": float(np.mean([c.get("tuples_per_scan", np.nan)
                                                   for c in costs])) if costs else np.nan,
            "bytes_per_peer_scan": float(np.mean([
                c.get("estimate_bytes_to_neighbours_per_scan", np.nan) for c in costs]))
            if costs else np.nan}


def _toml(value: Any) -> str:
    if isinstance(value, str):
        return f'"{value}"'
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k} = {_toml(v)}" for k, v in value.items()) + "}"
    return repr(value)


def sweep(source: str, param: str, values: list, policies: list[str], runs: int,
          base: dict | None = None, real: bool = False, jobs: int = 1,
          progress: bool = True) -> list[dict]:
    """All (value, policy, run) points; rows in a fixed order whatever the worker count."""
    base = dict(base or {})
    for v in values:  # fail fast, with the scenario's one-line error, before any run
        load_scenario(source, overrides=_overrides(base, param, v, policies[0]))
    points = [SweepPoint(v, p, r) for v in values for p in policies for r in range(runs)]
    # Real runs one at a time: each is a whole network of processes on this machine.
    return map_runs(run_point, [(source, base, param, pt, real) for pt in points],
                    1 if real else jobs, f"runs ({param} x policy)", progress)


def summarise(rows: list[dict]) -> list[dict]:
    """Mean and standard error of the fused OSPA per (value, policy), in first-seen order."""
    groups: dict[tuple, list[dict]] = {}
    for r in rows:
        groups.setdefault((repr(r["value"]), r["policy"]), []).append(r)
    out = []
    for (_, policy), rs in groups.items():
        f = np.array([r["fused_ospa"] for r in rs])
        out.append({"value": rs[0]["value"], "policy": policy, "runs": len(rs),
                    "fused_ospa": float(f.mean()),
                    "sem": float(f.std(ddof=1) / np.sqrt(len(f))) if len(f) > 1 else float("nan"),
                    "local_ospa": float(np.mean([r["local_ospa"] for r in rs])),
                    "late": float(np.mean([r["late"] for r in rs])),
                    "too_old": float(np.mean([r["too_old"] for r in rs]))})
    return out


def format_summary(param: str, summary: list[dict]) -> str:
    lines = [f"| {param} | policy | runs | mean fused OSPA (m) | ± s.e. | local OSPA (m) | "
             "late / run | too old / run |", "|---|---|---:|---:|---:|---:|---:|---:|"]
    for s in summary:
        lines.append(f"| {s['value']} | {s['policy']} | {s['runs']} | {s['fused_ospa']:.1f} | "
                     f"{s['sem']:.1f} | {s['local_ospa']:.1f} | {s['late']:.0f} | "
                     f"{s['too_old']:.0f} |")
    return "\n".join(lines)


def write_outputs(rows: list[dict], param: str, folder: Path) -> list[Path]:
    folder.mkdir(parents=True, exist_ok=True)
    keys: list[str] = []
    for r in rows:
        keys += [k for k in r if k not in keys]
    csv_path = folder / "sweep.csv"
    with csv_path.open("w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=keys)
        w.writeheader()
        w.writerows(rows)
    plt = plt_module()

    summary = summarise(rows)
    labels = {repr(s["value"]): str(s["value"]) for s in summary}
    values = list(labels)
    x = np.arange(len(values))
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for policy in dict.fromkeys(s["policy"] for s in summary):
        pts = [s for s in summary if s["policy"] == policy]
        ax.errorbar(x[: len(pts)], [s["fused_ospa"] for s in pts],
                    yerr=[s["sem"] for s in pts], marker="o", capsize=3, label=f"fused, {policy}")
    local = [np.mean([s["local_ospa"] for s in summary if repr(s["value"]) == v]) for v in values]
    ax.plot(x, local, "k--", label="local only")
    ax.set_xticks(x, [labels[v] for v in values])
    ax.set_xlabel(param)
    ax.set_ylabel("mean OSPA (m)")
    ax.grid(alpha=0.3)
    ax.legend()
    runs = summary[0]["runs"] if summary else 0
    ax.set_title(f"mean OSPA per setting and policy ({runs} runs each)")
    fig.tight_layout()
    png = folder / "sweep.png"
    fig.savefig(png, dpi=100)
    plt.close(fig)
    return [csv_path, png]
