"""Identity switches of the kinds whose ids come from point tracking (peers.point_ids).

Per kind, on its default scenario's twin runs: identity switches per 1,000 true target-scans
(CLEAR MOT matching against the truth ids, gate = the scenario's OSPA cut-off:
:func:`tracking.track_metrics.clear_match`), of every peer's fused and local tracks, all and
confirmed only; mean over the peers and runs, and the worst peer of any run::

    python -m sensornet.sim.studies.point_ids --runs 3          # every kind
    python -m sensornet.sim.studies.point_ids --kinds et-gmphd --runs 1
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence

import numpy as np
from sensornet.sim.run.twin import TwinResult, run_twin
from sensornet.sim.scenario import load_scenario
from sensornet.sim.studies.labelled.study import peer_tables as labelled_tables
from sensornet.tracking.track_metrics import TrackTable, clear_match, clear_mot

CROSSING = [[-500.0, 20.0, 0.0, 0.0], [500.0, -20.0, 0.0, 0.0], [0.0, 0.0, 950.0, -30.0]]
"""Seed 004's truth with two targets head-on along y = 0, through each other at scan 26."""

CASES: dict[str, tuple[str, dict]] = {
    "imm-pf": ("seed001", {}),
    "imm-ekf": ("seed001", {"network.filter": "imm-ekf"}),
    "pda-meas": ("seed003", {"pda.mode": "meas"}),
    "pda-ci": ("seed003", {"pda.mode": "ci"}),
    "et-gmphd": ("seed002", {}),
    "flooding": ("seed004", {}),
    "et-gmphd-pd0.9": ("seed002", {"sensors.*.detection_probability": 0.9}),
    "flooding-loss0.3": ("seed004", {"faults.default.loss": 0.3}),
    "flooding-crossing": ("seed004", {"truth.starts": CROSSING}),
}
"""Case -> (scenario, overrides): each kind on its scenario as shipped, then harder
cases (ET-GM-PHD at Pd 0.9; flooding with 30 % of the flooded messages lost; flooding with
two targets crossing head-on)."""


def peer_tables(twin: TwinResult, peer: str, which: str,
                confirmed: bool = False) -> tuple[TrackTable, TrackTable, set]:
    """The truth's and one peer's ``which`` (``"local"``/``"fused"``) tracks as track tables
    from its results table (ids coded to ints; positions by the estimator's
    ``position_index``), and the set of ids seen. Raises if a row lacks one id and one
    status per track or one id per true target."""
    pos = tuple(twin.peers[peer].consensus.estimator.position_index)
    code: dict = {}
    est = labelled_tables(twin, [peer], which, code, confirmed, pos)[peer]
    t = twin.peers[peer].scorer.results.table(peer)
    TS, TI, TX = [], [], []
    for k, e, tru, tids in zip(t["scan"], t["estimate"], t["truth"], t["truth_ids"],
                               strict=True):
        if e != which:
            continue
        if len(tids) != len(tru):
            raise ValueError(f"{peer} {which} scan {k}: {len(tru)} targets, {len(tids)} ids")
        TS += [k] * len(tru)
        TI += list(tids)
        TX += [np.asarray(x)[list(pos)] for x in tru]
    truth = TrackTable(np.array(TS, np.int64), np.array(TI, np.int64),
                       np.array(TX, float).reshape(-1, 2))
    return truth, est, set(code)


def switches(twin: TwinResult, peer: str, which: str, gate: float,
             confirmed: bool = False) -> dict:
    """CLEAR MOT (:func:`tracking.track_metrics.clear_mot`) of a peer's tracks."""
    truth, est, _ = peer_tables(twin, peer, which, confirmed)
    return clear_mot(clear_match(truth, est, gate))


def measure(kind: str, runs: Sequence[int]) -> dict:
    """One row: per (which, confirmed) the switches per 1,000 target-scans, mean over peers
    and runs and the worst peer-run; target-scans per peer-run."""
    name, overrides = CASES[kind]
    scn = load_scenario(name, overrides)
    gate = scn.metrics.ospa_cutoff
    per: dict = {}
    scans = []
    for run in runs:
        twin = run_twin(scn, run)
        for p in scn.sensor_names:
            for which in ("fused", "local"):
                for conf in (False, True):
                    m = switches(twin, p, which, gate, conf)
                    per.setdefault((which, conf), []).append(
                        1000.0 * m["switches"] / max(m["truth_scans"], 1))
            scans.append(m["truth_scans"])
    out = {"kind": kind, "scenario": name, "peers": len(scn.sensor_names), "runs": len(runs),
           "target_scans": int(np.mean(scans))}
    for (which, conf), v in per.items():
        key = which + (" confirmed" if conf else "")
        out[key] = (float(np.mean(v)), float(np.max(v)))
    return out


def table(rows: list[dict]) -> str:
    """The rows as a markdown table."""
    head = ("| kind | scenario | peers | runs | target-scans / peer-run | fused (mean, worst) "
            "| fused confirmed | local | local confirmed |\n|---|---|---:|---:|---:|---:|---:"
            "|---:|---:|")
    body = [f"| {r['kind']} | {r['scenario']} | {r['peers']} | {r['runs']} | "
            f"{r['target_scans']} | " + " | ".join(
                "{:.1f}, {:.1f}".format(*r[k]) for k in ("fused", "fused confirmed", "local",
                                                         "local confirmed")) + " |"
            for r in rows]
    return "\n".join([head, *body])


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=1, help="twin runs 0..runs-1 per kind")
    ap.add_argument("--kinds", nargs="*", default=list(CASES), choices=list(CASES))
    a = ap.parse_args(argv)
    print(table([measure(k, range(a.runs)) for k in a.kinds]))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
