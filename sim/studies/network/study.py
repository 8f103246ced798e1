"""The peer network as studies: on the discrete-event twin (``twin``) or as processes over
Zenoh (``real``, as ``sensornet run``). Their rows are a campaign's columns: fused and local
OSPA averaged over the peers, the track-level numbers (sim.run.track_summary: OSPA(2),
identity switches, label agreement), out-of-sequence counters, communication cost, link faults.
"""

from __future__ import annotations

import tempfile
from pathlib import Path
from typing import Any

import numpy as np
from sensornet.sim.campaign.runners import scenario_source
from sensornet.sim.campaign.sweep import _toml, cost_columns
from sensornet.sim.run.launcher import read_summaries, start_run, wait_run
from sensornet.sim.run.run_summary import read_tables
from sensornet.sim.run.track_summary import track_columns, track_summary
from sensornet.sim.run.twin import run_twin
from sensornet.sim.scenario import Scenario, load_scenario
from sensornet.sim.studies.base import Cell, Outcome, Request, Study


def load(req: Request) -> list[Scenario]:
    return [load_scenario(req.source, overrides=dict(req.overrides))]


def twin_row(scn: Scenario, cell: Cell) -> dict[str, Any]:
    """One twin run's columns."""
    result = run_twin(scn, cell.run)
    peers = result.peers
    out: dict[str, Any] = {
        "fused_ospa": float(np.mean([p.mean_ospa("fused") for p in peers.values()])),
        "local_ospa": float(np.mean([p.mean_ospa("local") for p in peers.values()])),
        "fused_gospa": float(np.mean([p.scorer.results.mean("fused") for p in peers.values()])),
        "local_gospa": float(np.mean([p.scorer.results.mean("local") for p in peers.values()])),
        "fused_card_error": float(np.mean([p.scorer.mean_cardinality_error("fused")
                                           for p in peers.values()])),
        "local_card_error": float(np.mean([p.scorer.mean_cardinality_error("local")
                                           for p in peers.values()]))}
    for key in ("late", "redundant", "too_old", "dropped_late"):
        out[key] = sum(getattr(p.consensus.nale.counts, key) for p in peers.values())
    out.update(cost_columns([p.cost() for p in peers.values()]))
    meta = next(iter(peers.values())).scorer.results.meta()
    out.update(track_columns(track_summary(
        {n: p.scorer.results.table(n) for n, p in peers.items()}, meta["position_index"],
        meta["cutoff"], meta["order"])))
    if result.faults is not None:
        for action, n in sorted(result.faults.counts().items()):
            out[f"links_{action}"] = n
    for name in peers:
        out[f"fused_ospa.{name}"] = float(peers[name].mean_ospa("fused"))
    K = scn.num_scans
    for which in ("fused", "local"):
        per = [result.ospa.get(n, {}).get(which, {}) for n in peers]
        out[f"ospa_k.{which}"] = [
            float(np.mean([p[k] for p in per if k in p])) if any(k in p for p in per)
            else float("nan") for k in range(1, K + 1)]
    return out


def real_row(scn: Scenario, cell: Cell) -> dict[str, Any]:
    """One run over processes: the launcher's world and peers, their summaries' columns."""
    source = scenario_source(cell.scenario, cell.scenario_text)
    sets = [f"{k}={_toml(v)}" for k, v in cell.overrides.items()]
    with tempfile.TemporaryDirectory(prefix="sensornet-campaign-") as tmp:
        handle = start_run(scn, source, Path(tmp), overrides=sets, run=cell.run, rerun=False)
        try:
            wait_run(handle, timeout=scn.num_scans * scn.scan_period / scn.network.speed + 90)
        finally:
            handle.stop_all()
        summaries = read_summaries(Path(tmp), scn.sensor_names)
        tables, meta = read_tables(Path(tmp))
    tracks = (track_columns(track_summary(tables, meta["position_index"], meta["cutoff"],
                                          meta.get("order", 2.0))) if meta else {})
    out: dict[str, Any] = {
        "fused_ospa": float(np.mean([s["mean_ospa_fused"] for s in summaries.values()])),
        "local_ospa": float(np.mean([s["mean_ospa_local"] for s in summaries.values()])),
        "fused_gospa": float(np.mean([s["mean_gospa_fused"] for s in summaries.values()])),
        "local_gospa": float(np.mean([s["mean_gospa_local"] for s in summaries.values()]))}
    for key in ("late", "redundant", "too_old", "dropped_late"):
        out[key] = sum(s["nale"][key] for s in summaries.values())
    out.update(cost_columns([s.get("cost") or {} for s in summaries.values()]))
    out.update(tracks)
    for name, s in summaries.items():
        out[f"fused_ospa.{name}"] = float(s["mean_ospa_fused"])
        if s.get("latency_ms_median") is not None:
            out[f"ms_latency_median.{name}"] = float(s["latency_ms_median"])
    return out


def twin_once(scn: Scenario, run: int) -> dict[str, Any]:
    return twin_row(scn, Cell(run, scn.source, None, {}))


def real_once(scn: Scenario, run: int) -> dict[str, Any]:
    return real_row(scn, Cell(run, scn.source, None, {}))


def summarise(scn: Scenario, rows: list[dict[str, Any]]) -> dict[str, float]:
    """The mean over the runs of every scalar column."""
    keys = [k for k, v in rows[0].items() if isinstance(v, (int, float))]
    return {k: float(np.mean([r[k] for r in rows])) for k in keys}


def table(o: Outcome) -> str:
    return "\n".join([f"{o.setup.name}, {len(o.runs)} runs", "| metric | mean |", "|---|---:|",
                      *(f"| {k} | {v:.4g} |" for k, v in o.summary.items())])


TWIN = Study(
    name="twin", about="the peers on the discrete-event twin (fused and local OSPA, costs)",
    load=load, run_once=twin_once, summarise=summarise, table=table, scenario=True,
    row=twin_row, modules=("sensornet.sim.run.twin",))

REAL = Study(
    name="real", about="the peers as processes over Zenoh, one run at a time",
    load=load, run_once=real_once, summarise=summarise, table=table, scenario=True,
    parallel=False, row=real_row, modules=("sensornet.sim.run.launcher",
                                           "sensornet.sim.campaign.sweep"))
