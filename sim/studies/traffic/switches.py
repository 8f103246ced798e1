"""Where a tracker's identity switches on real traffic happen (issue 34): one line per switch.

A switch (CLEAR MOT matching at the OSPA cut-off, :func:`tracking.track_metrics.clear_match`)
is an aircraft whose matched track differs from the one it last had. Per switch: the tick,
the aircraft (icao24), the old and new track labels ``(origin, scan, index)``, how old the
new label is (ticks since it was first seen on this peer), what became of the old track
(``swap``: it now holds another aircraft; ``dropped``: it is gone; ``coasting``: present but
matched to nothing), the nearest other aircraft (m), the aircraft's speed, turn rate and
the radars whose coverage it is in, and which aircraft last held the new label and how many
ticks before (``held_by``: ``self``, another's icao24, or ``-``).
Cause classes (the first that applies), so a fix can be aimed at the largest:

* ``settle``: the old and the new label were made at the same scan and the new one is at most
  a tick old (two peers' labels of one new track meeting: the network rule keeps one);
* ``handover``: the new label last held another aircraft (``held_by``): a label moved from
  one aircraft to another;
* ``crossing``: another aircraft within 3 km (their tracks' labels can trade);
* ``relabel``: the old track is gone and the new label is older than the switch (a label
  that existed elsewhere took the aircraft: the network rule replacing the id);
* ``reborn``: the old track is gone and the new label is new (a lost and re-born track);
* ``other``.

``python -m sensornet.sim.studies.traffic.switches [SCENARIO] --file F --start S --minutes M
[--kind lmb] [--estimate fused] [--peer NAME] [--set KEY=VALUE ...]``
"""

from __future__ import annotations

import argparse
import sys
from collections import Counter

import numpy as np
from sensornet.sim.run.twin import run_twin
from sensornet.sim.scenario import Scenario, ScenarioError
from sensornet.sim.studies.labelled.study import peer_tables, truth_table
from sensornet.sim.studies.traffic.study import add_window_arguments, window_scenario
from sensornet.sim.world import Truth, generate_run
from sensornet.tracking.track_metrics import TrackTable, clear_match

NEAR = 3000.0
"""An aircraft closer than this (m) to the switching one makes the switch a crossing."""


def switch_events(scn: Scenario, run: int, which: str, peer: str | None = None
                  ) -> tuple[list[dict], dict]:
    """The switches of ``peer``'s ``which`` (``"local"``/``"fused"``) tracks (first peer if
    None) on the scenario's twin, as :func:`trace` gives them."""
    peer = peer or scn.sensor_names[0]
    return peer_switches(scn, run, which, [peer])[peer]


def peer_switches(scn: Scenario, run: int, which: str, peers: list[str]
                  ) -> dict[str, tuple[list[dict], dict]]:
    """:func:`trace` of each of ``peers``' ``which`` tracks, from one twin of the scenario
    (the peers' tables share one label code, so a label is one id at every peer)."""
    truth, _ = generate_run(scn, run)
    twin = run_twin(scn, run)
    code: dict = {}
    est = peer_tables(twin, peers, which, code)
    sites = {s.name: (np.asarray(s.position[:2], float), float(s.max_range or np.inf))
             for s in scn.sensors}
    back = {v: k for k, v in code.items()}
    return {p: trace(truth, est[p], back, sites, scn.metrics.ospa_cutoff, scn.scan_period)
            for p in peers}


def trace(truth: Truth, est: TrackTable, label: dict, sites: dict, gate: float,
          period: float) -> tuple[list[dict], dict]:
    """Each identity switch of ``est`` against ``truth`` (CLEAR MOT at ``gate``) as a dict:
    ``tick``, ``aircraft`` (hex id), ``old``/``new`` labels (``label``: table id -> label),
    ``new_age`` (ticks since the new id was first in ``est``), ``fate`` of the old track,
    ``near_m``, ``speed``, ``turn`` (deg/s), ``centre_km``, ``cover`` (radars in ``sites``:
    name -> (position (2,), max range) whose range holds it) and ``cause`` (module
    docstring); and the totals."""
    T = truth_table(truth)
    grid = np.arange(1, truth.num_scans + 1)
    cm = clear_match(T, est, gate, grid)
    first_seen = {int(i): int(est.scan[est.id == i].min()) for i in np.unique(est.id)}
    events = []
    last = np.full(len(cm.truth_ids), -1)
    held = np.full((len(cm.est_ids), 2), -1)  # per track: the last aircraft (index), its tick
    for t, k in enumerate(grid):
        X, ids = truth.states[t], np.asarray(truth.ids[t])
        for j in np.flatnonzero(cm.switch[t]):
            a = int(cm.truth_ids[j])
            old, new = last[j], cm.match[t, j]
            old_id, new_id = int(cm.est_ids[old]), int(cm.est_ids[new])
            fate = ("swap" if (cm.match[t] == old).any() else "coasting"
                    if cm.est_present[t, old] else "dropped")
            x = X[ids == a][0]
            d = np.hypot(X[ids != a, 0] - x[0], X[ids != a, 2] - x[2])
            near = float(d.min()) if len(d) else np.inf
            turn = np.nan
            if 0 < t < len(grid) - 1:
                h0 = truth.states[t - 1][np.asarray(truth.ids[t - 1]) == a]
                h1 = truth.states[t + 1][np.asarray(truth.ids[t + 1]) == a]
                if len(h0) and len(h1):
                    dh = np.arctan2(h1[0, 3], h1[0, 1]) - np.arctan2(h0[0, 3], h0[0, 1])
                    turn = abs((np.degrees(dh) + 180) % 360 - 180) / (2 * period)
            cover = sum(np.hypot(x[0] - p[0], x[2] - p[1]) <= r for p, r in sites.values())
            age = int(k) - first_seen[new_id]
            h, when = held[new]
            was = ("-" if h < 0 else "self" if h == j else f"{int(cm.truth_ids[h]):06x}")
            lo, ln = label.get(old_id), label.get(new_id)
            cause = ("settle" if lo is not None and ln is not None and lo[1] == ln[1]
                     and age <= 1 else
                     "handover" if h >= 0 and h != j else
                     "crossing" if near < NEAR else
                     "relabel" if fate == "dropped" and age > 0 else
                     "reborn" if fate == "dropped" else "other")
            events.append({"tick": int(k), "aircraft": f"{a:06x}",
                           "old": label.get(old_id, old_id), "new": label.get(new_id, new_id),
                           "new_age": age, "fate": fate, "near_m": near,
                           "speed": float(np.hypot(x[1], x[3])), "turn": turn,
                           "centre_km": float(np.hypot(x[0], x[2]) / 1e3), "cover": int(cover),
                           "held_by": was, "held_ago": int(k - grid[when]) if h >= 0 else -1,
                           "cause": cause})
        m = cm.match[t] >= 0
        last[m] = cm.match[t, m]
        held[cm.match[t, m]] = np.column_stack((np.flatnonzero(m), np.full(int(m.sum()), t)))
    present = np.array([[a in ids for a in cm.truth_ids] for ids in truth.ids])  # (T, m)
    hours = present.sum(axis=0) * period / 3600.0
    totals = {"switches": len(events), "aircraft": len(cm.truth_ids),
              "tracks": len(cm.est_ids), "ticks": len(grid), "hours": float(hours.sum()),
              "hours_by": {f"{int(a):06x}": float(h)
                           for a, h in zip(cm.truth_ids, hours, strict=True)}}
    return events, totals


def per_aircraft_rates(events: list[dict], totals: dict) -> np.ndarray:
    """Switches per hour present of every aircraft in ``totals["hours_by"]`` (``(m,)``, the
    aircraft in that order; an aircraft present for no tick is left out)."""
    n = Counter(e["aircraft"] for e in events)
    return np.array([n[a] / h for a, h in totals["hours_by"].items() if h > 0])


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m sensornet.sim.studies.traffic.switches",
                                 description=__doc__.split("\n\n")[0])
    add_window_arguments(ap)
    ap.add_argument("--kind", default="lmb")
    ap.add_argument("--estimate", default="fused", choices=("local", "fused"))
    ap.add_argument("--peer", help="a sensor's name, or 'all' (default: the first sensor)")
    ap.add_argument("--run", type=int, default=0)
    a = ap.parse_args(argv)
    try:
        _, scn = window_scenario(a, {"network.filter": a.kind, **(
            {"fusion.rule": "none"} if a.estimate == "local" else {})})
        names = list(scn.sensor_names)
        peers = names if a.peer == "all" else [a.peer or names[0]]
        if peers[0] not in names:
            raise ValueError(f"no sensor named {peers[0]!r} among {', '.join(names)}")
    except (ScenarioError, ValueError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    out = peer_switches(scn, a.run, a.estimate, peers)
    every: list[dict] = []
    for peer, (events, totals) in out.items():
        rate = per_aircraft_rates(events, totals)
        print(f"== {peer}: {totals['switches']} switches, {totals['aircraft']} aircraft, "
              f"{totals['tracks']} track ids, {totals['ticks']} ticks, "
              f"{totals['switches'] / max(totals['hours'], 1e-9):.2f} per aircraft-hour "
              f"(per aircraft: median {np.median(rate):.2f}, p90 "
              f"{np.percentile(rate, 90):.2f}, max {rate.max():.2f}; none "
              f"{np.mean(rate == 0):.0%})")
        print("tick aircraft old -> new (new age) fate near_m speed turn centre_km cover "
              "held_by(ticks ago) cause")
        for e in events:
            print(f"{e['tick']} {e['aircraft']} {e['old']} -> {e['new']} ({e['new_age']}) "
                  f"{e['fate']} {e['near_m']:.0f} {e['speed']:.0f} {e['turn']:.1f} "
                  f"{e['centre_km']:.1f} {e['cover']} {e['held_by']}({e['held_ago']}) "
                  f"{e['cause']}")
        every += [{**e, "peer": peer} for e in events]
    print("by cause:", dict(Counter(e["cause"] for e in every)))
    print("by aircraft:", dict(Counter(e["aircraft"] for e in every).most_common(10)))
    if len(out) > 1:
        hours = sum(t["hours"] for _, t in out.values())
        print(f"all peers: {len(every)} switches, {len(every) / max(hours, 1e-9):.2f} per "
              f"aircraft-hour")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
