"""Seed 003 as a network scenario: one single-target PDA peer per sensor (docs/seed003.md).

``sim/scenarios/seed003.toml`` is the offline study's file; :func:`network_document` makes the
network scenario of it (``[scenario] study = "seed003"``), so every command runs it: ``sensornet
run seed003`` (world + one PDA peer process per sensor over Zenoh, ``--sim``, ``--record``,
``--fault``, ``--secure``, campaigns). The peers (:mod:`sim.kinds.pda`) are built by
the kind (:func:`sim.kinds.pda.make_parts`) in one of two modes, ``pda.mode``:

* ``meas`` — measurement sharing (the paper's scheme): each peer predicts, publishes the returns
  of its own scan inside a wide pre-gate, and runs the PDA update sensor by sensor in the fixed
  order of the file (s1, then s2) on its own filter once every peer's returns are in, or at the
  fusion deadline with those that are (a late or lost s2 scan: s1 only; counted)
  (:class:`peers.pda_parts.SequentialPdaEstimator`, :class:`~peers.pda_parts.SequentialFuser`);
* ``ci`` — estimate sharing: each peer runs its filter on its own sensor, publishes its
  posterior and fuses the others' by covariance intersection
  (:class:`peers.pda_parts.PdaEstimator`, :class:`~peers.pda_parts.CiFuser`; no feedback).

Every peer starts from the run's one initial estimate (drawn as in
:mod:`sim.studies.seed003.peers`),
so measurement-sharing peers hold the same estimate. ``python -m
sensornet.sim.studies.seed003.network run``
compares
the two modes in one table: each mode a common run (:func:`sim.run.launcher.start_run`) beside its
twin (``--sim``: the twins only); with every message in time the processes compute what the
twin computes (the table's "max diff to twin" column; the tests check it).
"""

from __future__ import annotations

import argparse
import copy
import sys
import time
import tomllib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from sensornet.peers.core import PeerCore
from sensornet.sim.kinds.pda import (  # noqa: F401  (the peers' parts live in the kind; named here as before)
    METHOD,
    MODES,
    PREGATE,
    draws,
    make_parts,
)
from sensornet.sim.run.launcher import read_summaries, start_run, wait_run
from sensornet.sim.run.peers import make_peer
from sensornet.sim.run.twin import run_twin
from sensornet.sim.scenario import Scenario, ScenarioError, apply_overrides, load_document
from sensornet.sim.scenario.seed003 import read_seed003
from sensornet.sim.studies.seed003 import montecarlo as seed003
from sensornet.sim.world import Truth
from sensornet.sim.world.build import fault_injector
from sensornet.tracking.imm import POS

LABELS = {"meas": "measurement sharing", "ci": "estimate sharing (CI)"}
SPEED = 10.0
"""Scans per scan period (100 scans in 10 s)."""
DEADLINE = 0.9
"""Fusion deadline, as a fraction of the scan interval."""


# -- the scenario ------------------------------------------------------------------------------


def load(overrides: Mapping | None = None, path: str | Path | None = None) -> dict:
    """The seed-003 tables (``path``, default ``sim/scenarios/seed003.toml``) with region clutter
    (what a peer network sees), ``overrides`` applied (``"table.key"``; ``faults.*`` keys as in
    the other scenarios: ``faults.default.loss``, ``faults.links[0].delay``)."""
    overrides = dict(overrides or {})
    fault_keys = {k[len("faults."):]: overrides.pop(k) for k in list(overrides)
                  if k.startswith("faults.")}
    cfg = seed003.load(path or seed003.SCENARIO,
                       overrides={"clutter.mode": "region", **overrides})
    if fault_keys:
        if not isinstance(cfg.setdefault("faults", {}), dict):
            raise ValueError("seed003: 'faults' must be a table")
        apply_overrides(cfg["faults"], fault_keys, "seed003 [faults]")
    return cfg


def scenario_of(cfg: Mapping, mode: str, speed: float = SPEED, deadline: float = DEADLINE,
                method: str = METHOD) -> Scenario:
    """The network scenario of the tables ``cfg`` with peers in ``mode`` (checked like a file)."""
    doc = copy.deepcopy(dict(cfg))
    doc["network"] = {**doc.get("network", {}), "speed": float(speed),
                      "deadline": float(deadline)}
    doc["pda"] = {**doc.get("pda", {}), "mode": mode, "method": method}
    return load_document(doc, "seed003.toml", name="seed003")


def run_data(cfg: Mapping, run: int):
    """``(truth, scans)`` of run ``run`` as :func:`sim.world.generate_run` returns them (the
    target's return first in each scan, then the clutter: the order the offline filters use)."""
    X, sens, target, region, _, _ = draws(cfg, run)
    K = len(X) - 1
    truth = Truth(states=[X[k][None] for k in range(1, K + 1)],
                  ids=[np.array([1]) for _ in range(K)])
    scans = [[np.vstack([target[k][i], region[k][i]]) for k in range(K)]
             for i in range(len(sens))]
    return truth, scans


def network_document(doc: dict, label: str = "seed003.toml") -> dict:
    """The seed-003 document as a network scenario (:mod:`sim.scenario`'s format, for
    ``sensornet run seed003`` and every other command): one PDA peer per sensor on a full
    graph (``network.filter = "pda"``), region clutter (every peer sees the world's clutter),
    the study's own draws (truth model ``"seed003"``), the loss bound as the OSPA cut-off, and
    the ``[pda]`` table (``mode``, ``method``, ``pregate``). ``[network]``, ``[faults]``,
    ``[security]`` are taken as they are."""
    passed = ("network", "faults", "security", "pda", "fusion")
    cfg = copy.deepcopy({k: v for k, v in doc.items() if k not in passed})
    read_seed003(cfg, label)  # every key checked as declared (sim/scenario/seed003.py)
    try:
        seed003.check_sensor_names(cfg.get("sensors"), label)
        cfg.setdefault("clutter", {})["mode"] = "region"
        sc = cfg["scenario"]
        sens = seed003.sensors(cfg)
        hw = float(cfg["clutter"]["halfwidth"])
        X = seed003.truth(cfg)
        lo, hi = X[:, list(POS)].min(0) - hw, X[:, list(POS)].max(0) + hw
        sensors = [{"name": s["name"], "kind": "linear", "position": [2000.0 * i, 0.0],
                    "sigma_r": float(s["sigma"]),
                    "detection_probability": float(s["detection_probability"]),
                    "clutter_rate": float(m.clutter_density * (2 * hw) ** 2)}
                   for i, (s, m) in enumerate(zip(cfg["sensors"], sens, strict=True))]
        scenario = {"name": sc.get("name", "seed003"), "seed": int(sc["seed"]),
                    "scan_period": float(sc["scan_period"]), "num_scans": int(sc["num_scans"]),
                    "region": [[float(lo[0]), float(hi[0])], [float(lo[1]), float(hi[1])]],
                    "truth": "seed003"}
        metrics = {"ospa_cutoff": float(cfg["metrics"]["loss_bound"]), "ospa_order": 2.0}
    except (KeyError, TypeError, ValueError) as exc:
        raise ScenarioError(f"{label}: {exc}" if not str(exc).startswith(label)
                            else str(exc)) from None
    network = {"topology": "full", "rounds": 1, "filter": "pda", "speed": SPEED,
               "deadline": DEADLINE, **doc.get("network", {})}
    pda = {"mode": "meas", "method": METHOD, "pregate": PREGATE, **doc.get("pda", {}),
           **pda_section(cfg)}
    return {"scenario": scenario, "sensors": sensors, "metrics": metrics, "network": network,
            "pda": pda, **{k: doc[k] for k in ("faults", "security", "fusion") if k in doc}}


def pda_section(cfg: Mapping) -> dict:
    """The seed-003 tables ``cfg`` as the typed sub-tables of the scenario's ``[pda]``
    (:mod:`sim.scenario.pda`): the target of ``[scenario]``, the sensors' gate probabilities
    (the declared default unless every sensor gives one), ``[clutter]``, ``[filters]``,
    ``[detector]``, ``[fuzzy]`` and the loss rule of ``[metrics]``."""
    sc, metrics = cfg["scenario"], cfg.get("metrics", {})
    gates = [s["gate_probability"] for s in cfg["sensors"] if "gate_probability" in s]
    return {"target": {k: sc[k] for k in ("start", "speed", "turn_scans", "manoeuvre")
                       if k in sc},
            **({"gate_probability": gates} if len(gates) == len(cfg["sensors"]) else {}),
            **{k: cfg[k] for k in ("clutter", "filters", "detector", "fuzzy") if k in cfg},
            **{k: metrics[k] for k in ("loss_bound", "loss_scans") if k in metrics}}


# -- peers --------------------------------------------------------------------------------------


def make_core(cfg: Mapping, name: str, mode: str, run: int = 0, *, network: str = "twin",
              speed: float = SPEED, deadline: float = DEADLINE,
              method: str = METHOD) -> PeerCore:
    """The sans-I/O PDA peer of sensor ``name`` in ``mode`` (``"meas"`` or ``"ci"``): the common
    peer of the network scenario (:func:`sim.run.peers.make_peer`)."""
    scn = scenario_of(cfg, mode, speed, deadline, method)
    if name not in scn.sensor_names:
        raise ValueError(f"seed003: no sensor named {name!r} "
                         f"(sensors: {', '.join(scn.sensor_names)})")
    return make_peer(scn, name, run, network=network)


def twin(cfg: Mapping, mode: str, run: int = 0, *, speed: float = SPEED,
         deadline: float = DEADLINE, method: str = METHOD, faults=None):
    """The run on the discrete-event twin (:func:`sim.run.twin.run_twin`); ``faults``: a
    :class:`peers.faults.FaultInjector` (default: the ``[faults]`` table's, if any)."""
    scn = scenario_of(cfg, mode, speed, deadline, method)
    return run_twin(scn, run, faults=faults or fault_injector(scn, run))


# -- scores and the table ---------------------------------------------------------------------


def track_errors(X: np.ndarray, tracks: Mapping[int, np.ndarray]) -> np.ndarray:
    """Position error per scan ``(K,)`` (NaN where the peer published no track)."""
    err = np.full(len(X) - 1, np.nan)
    for k, s in tracks.items():
        if 1 <= k < len(X) and len(s):
            err[k - 1] = float(np.hypot(*(np.asarray(s)[0, list(POS)] - X[k, list(POS)])))
    return err


@dataclass
class Row:
    mode: str
    peer: str
    scans: int
    tracks: int
    missing_inputs: int
    """Neighbour inputs a fusion went without (late, lost, or the neighbour gone)."""
    rmse: float
    lost: bool
    twin_diff: float | None = None
    messages_sent: int | None = None
    kb_sent: float | None = None
    latency_ms: float | None = None
    fuser: dict = field(default_factory=dict)


def make_row(cfg: dict, mode: str, peer: str, summary: dict,
             tracks: Mapping[int, np.ndarray], twin_tracks: Mapping | None = None) -> Row:
    X = seed003.truth(cfg)
    err = track_errors(X, tracks)
    bound, nscan = float(cfg["metrics"]["loss_bound"]), int(cfg["metrics"]["loss_scans"])
    st = summary["stats"]
    n_neighbours = len(cfg["sensors"]) - 1
    diff = None
    if twin_tracks is not None:
        ks = sorted(set(tracks) | set(twin_tracks))
        both = [k for k in ks if k in tracks and k in twin_tracks]
        diff = (float(max((np.abs(np.asarray(tracks[k]) - twin_tracks[k]).max() for k in both),
                          default=0.0)) if len(both) == len(ks) else float("inf"))
    ok = err[np.isfinite(err)]
    return Row(mode, peer, int(summary["scans"]), int(np.isfinite(err).sum()),
               int(st["fusions"] * n_neighbours - st["fused_inputs"]),
               float(np.sqrt(np.mean(ok ** 2))) if len(ok) else float("nan"),
               seed003.lost(np.nan_to_num(err, nan=np.inf), bound, nscan), diff,
               summary.get("messages_sent"),
               summary["bytes_sent"] / 1e3 if "bytes_sent" in summary else None,
               summary.get("latency_ms_median"), dict(summary.get("fuser") or {}))


def format_rows(rows: Sequence[Row]) -> str:
    def f(v, fmt):
        return "-" if v is None else fmt.format(v)

    out = ["| mode | peer | scans | tracks | missing inputs | pos RMSE m | lost | "
           "max diff to twin m | msgs sent | kB sent | latency median ms |",
           "|---|---|---:|---:|---:|---:|---|---:|---:|---:|---:|"]
    for r in rows:
        out.append(f"| {LABELS[r.mode]} | {r.peer} | {r.scans} | {r.tracks} | "
                   f"{r.missing_inputs} | {r.rmse:.1f} | {'yes' if r.lost else 'no'} | "
                   f"{f(r.twin_diff, '{:.2g}')} | {f(r.messages_sent, '{}')} | "
                   f"{f(r.kb_sent, '{:.1f}')} | {f(r.latency_ms, '{:.2f}')} |")
    return "\n".join(out)


# -- processes ----------------------------------------------------------------------------------


def _fault_counts(faults) -> str:
    """The injected link faults' decisions, those that happened."""
    return ", ".join(f"{a} {n}" for a, n in faults.counts().items() if n) or "none"


def read_tracks(out: Path, name: str) -> dict[int, np.ndarray]:
    path = out / f"tracks-{name}.npz"
    if not path.is_file():
        return {}
    with np.load(path) as z:
        return {int(k[1:]): z[k] for k in z.files}


def run_mode(a: argparse.Namespace, cfg: dict, mode: str, out: Path) -> tuple[list[Row], int]:
    """One mode as a common run (world + one peer process per sensor over Zenoh); its table
    rows (beside the twin) and an exit code."""
    out.mkdir(parents=True, exist_ok=True)
    scn = scenario_of(cfg, mode, a.speed, a.deadline, a.method)
    names = scn.sensor_names
    ref = twin(cfg, mode, a.run, speed=a.speed, deadline=a.deadline, method=a.method)
    if ref.faults is not None:
        print(f"{mode}: link faults, twin's decisions: {_fault_counts(ref.faults)}", flush=True)
    sets = [*a.set, f"pda.mode={mode}", f"pda.method={a.method}",
            f"network.deadline={a.deadline}"]
    handle = start_run(scn, str(a.scenario or "seed003"), out, overrides=sets,
                       viewer=a.viewer, run=a.run, speed=a.speed, rerun=not a.no_rerun,
                       peer_args={n: ["--save-tracks"] for n in names})
    try:
        codes = wait_run(handle, timeout=scn.num_scans * scn.scan_period / a.speed + a.timeout)
    finally:
        handle.stop_all()
    summaries = read_summaries(out, names)
    rows = [make_row(cfg, mode, n, summaries[n], read_tracks(out, n), ref.tracks[n])
            for n in names if n in summaries]
    bad = {n: c for n, c in codes.items() if c != 0}
    missing = [n for n in names if n not in summaries]
    if bad or missing or handle.timed_out:
        print(f"seed003 {mode}: exit codes {codes}, no summary from {missing or 'none'}"
              f"{', timed out' if handle.timed_out else ''} (logs in {out / 'logs'})",
              file=sys.stderr)
        return rows, 1
    return rows, 0


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m sensornet.sim.studies.seed003.network",
                                description="seed 003: the two PDA peer modes compared")
    sub = p.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run", help="both modes as processes (or twins), one table")
    r.add_argument("--run", type=int, default=0, help="Monte Carlo run (its draws)")
    r.add_argument("--speed", type=float, default=SPEED, help="scans per scan period")
    r.add_argument("--deadline", type=float, default=DEADLINE,
                   help="fusion deadline, fraction of the scan interval")
    r.add_argument("--method", default=METHOD, choices=seed003.METHODS)
    r.add_argument("--set", action="append", default=[], metavar="TABLE.KEY=VALUE")
    r.add_argument("--scenario", type=Path,
                   help="scenario file (default sim/scenarios/seed003.toml; its [faults] "
                        "table applies)")
    r.add_argument("--out", type=Path)
    r.add_argument("--viewer")
    r.add_argument("--no-rerun", action="store_true")
    r.add_argument("--modes", default=",".join(MODES))
    r.add_argument("--timeout", type=float, default=60.0,
                   help="seconds allowed beyond the scans' own time")
    r.add_argument("--sim", action="store_true", help="the twin only (no processes)")
    return p


def _overrides(items: Sequence[str]) -> dict:
    out = {}
    for item in items:
        if "=" not in item:
            raise ValueError(f"--set {item!r}: expected TABLE.KEY=VALUE")
        k, v = item.split("=", 1)
        try:
            out[k] = tomllib.loads(f"v = {v}")["v"]
        except tomllib.TOMLDecodeError:
            out[k] = v
    return out


def main(argv: Sequence[str] | None = None) -> int:
    a = _parser().parse_args(argv)
    try:
        cfg = load(_overrides(a.set), a.scenario)
        for mode in MODES:
            scenario_of(cfg, mode, a.speed, a.deadline, a.method)  # checked before any run
    except (ValueError, OSError, ScenarioError) as exc:
        print(f"sensornet: error: seed003: {exc}", file=sys.stderr)
        return 2
    modes = [m.strip() for m in a.modes.split(",") if m.strip()]
    if unknown := [m for m in modes if m not in MODES]:
        print(f"sensornet: error: seed003: unknown modes {unknown} (expected {MODES})",
              file=sys.stderr)
        return 2
    t0 = time.monotonic()
    rows: list[Row] = []
    code = 0
    if a.sim:
        for mode in modes:
            res = twin(cfg, mode, a.run, speed=a.speed, deadline=a.deadline, method=a.method)
            rows += [make_row(cfg, mode, n, res.summary(n), res.tracks[n]) for n in res.peers]
            if res.faults is not None:
                print(f"{mode}: injected link faults: {_fault_counts(res.faults)}")
        print(f"seed003 twin, run {a.run} ({a.method}, {time.monotonic() - t0:.1f} s):")
    else:
        out = a.out or Path("runs") / f"seed003-{time.strftime('%Y%m%d-%H%M%S')}"
        n = len(cfg["sensors"])
        print(f"seed003: world + {n} PDA peers as processes over Zenoh on 127.0.0.1, run "
              f"{a.run}, {cfg['scenario']['num_scans']} scans at {a.speed:g}x, modes "
              f"{', '.join(modes)}; output in {out}", flush=True)
        for mode in modes:
            r, c = run_mode(a, cfg, mode, out / mode)
            rows += r
            code = max(code, c)
        print(f"seed003 processes, run {a.run} ({a.method}, {time.monotonic() - t0:.0f} s):")
    print(format_rows(rows))
    print(f"(lost: error > {cfg['metrics']['loss_bound']:g} m for "
          f"{cfg['metrics']['loss_scans']} scans; missing inputs: neighbour returns/estimates "
          f"a fusion went without, e.g. a late s2 scan: s1 only)")
    return code


if __name__ == "__main__":
    raise SystemExit(main())
