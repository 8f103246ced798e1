"""Seed 003 over Zenoh: single-target PDA peers, one per sensor, as real processes, and their twin.

``sensornet run seed003`` (= ``python -m sim.seed003_net run``) plays one run of
``sim/scenarios/seed003.toml`` (region clutter: every peer sees the world's clutter) twice, once
per mode, each time as a world process and one peer process per sensor over Zenoh on
127.0.0.1, through the common peer core (:class:`peers.core.PeerCore`, the Zenoh runtime, link
faults, Rerun), and prints one table:

* ``meas`` — measurement sharing (the paper's scheme): each peer predicts, publishes the returns
  of its own scan inside a wide pre-gate, and runs the PDA update sensor by sensor in the fixed
  order of the file (s1, then s2) on its own filter once every peer's returns are in, or at the
  fusion deadline with those that are (a late or lost s2 scan: s1 only; counted)
  (:class:`peers.pda_parts.SequentialPdaEstimator`, :class:`~peers.pda_parts.SequentialFuser`);
* ``ci`` — estimate sharing: each peer runs its filter on its own sensor, publishes its
  posterior and fuses the others' by covariance intersection
  (:class:`peers.pda_parts.PdaEstimator`, :class:`~peers.pda_parts.CiFuser`; no feedback).

Every peer starts from the run's one initial estimate (drawn as in :mod:`sim.seed003_peers`),
so measurement-sharing peers hold the same estimate, and with every message in time the
processes compute what :func:`twin` computes (the table's last column; the tests check it).
Link faults: a ``[faults]`` table (``--faults FILE``, the scenario files' format) applies to
the estimates between peers, in the twin and in the processes alike.
"""

from __future__ import annotations

import argparse
import copy
import json
import subprocess
import sys
import time
import tomllib
import uuid
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from peers.consensus import Consensus, ConsensusOptions
from peers.core import CoreConfig, PeerCore
from peers.pda_parts import CiFuser, PdaEstimator, SequentialFuser, SequentialPdaEstimator
from peers.scoring import Scorer
from peers.session import PEER_WAIT
from protocol.keys import check_name, check_run_id
from sim import seed003
from tracking.imm import POS

MODES = ("meas", "ci")
LABELS = {"meas": "measurement sharing", "ci": "estimate sharing (CI)"}
SPEED = 10.0
"""Scans per scan period (100 scans in 10 s)."""
DEADLINE = 0.9
"""Fusion deadline, as a fraction of the scan interval."""
METHOD = "fuzzy IMM"
"""The peers' filter (the paper's; with the detector silent it is the IMM-PDAF)."""
PREGATE = 4.0
"""Measurement sharing publishes the returns inside ``PREGATE`` x the gate threshold of the
predicted estimate: a later sensor's gate (on the estimate after the earlier sensors' update)
lies inside it unless that update moved the estimate by more than a gate's size."""


# -- the scenario as the world and the twin see it --------------------------------------------


@dataclass(frozen=True)
class NetSensor:
    name: str
    kind: str = "linear"
    position: tuple[float, float] = (0.0, 0.0)
    """Drawn only (position sensors: where they stand is not part of the model)."""


@dataclass(frozen=True)
class NetSettings:
    speed: float
    deadline: float
    filter: str = "pda"


@dataclass(frozen=True, eq=False)
class NetScenario:
    """``seed003.toml`` with the fields :func:`sim.world_process.run_world`,
    :func:`sim.twin.run_twin` and :func:`sim.build.fault_injector` read."""

    cfg: dict
    network: NetSettings
    faults: object = None
    name: str = "seed003"
    truth: str = "seed003"
    targets: tuple = (1,)

    @property
    def seed(self) -> int:
        return int(self.cfg["scenario"]["seed"])

    @property
    def num_scans(self) -> int:
        return int(self.cfg["scenario"]["num_scans"])

    @property
    def scan_period(self) -> float:
        return float(self.cfg["scenario"]["scan_period"])

    @property
    def sensor_names(self) -> list[str]:
        return [s["name"] for s in self.cfg["sensors"]]

    @property
    def sensors(self) -> tuple[NetSensor, ...]:
        return tuple(NetSensor(n, position=(2000.0 * i, 0.0))
                     for i, n in enumerate(self.sensor_names))

    @property
    def region(self):
        X = seed003.truth(self.cfg)
        hw = float(self.cfg["clutter"]["halfwidth"])
        (x0, y0), (x1, y1) = X[:, list(POS)].min(0) - hw, X[:, list(POS)].max(0) + hw
        return (x0, x1), (y0, y1)


def load(overrides: Mapping | None = None, faults_file: str | Path | None = None,
         path: str | Path | None = None) -> dict:
    """The scenario (``path``, default ``sim/scenarios/seed003.toml``) with region clutter (what
    a peer network sees). Link faults: the file's ``[faults]`` table, replaced by the one of
    ``faults_file`` if given, then ``overrides`` under ``faults.`` (the other scenarios'
    spelling: ``faults.default.loss``, ``faults.links[0].delay``); checked by
    :func:`net_scenario`."""
    from sim.scenario import apply_overrides

    overrides = dict(overrides or {})
    fault_keys = {k[len("faults."):]: overrides.pop(k) for k in list(overrides)
                  if k.startswith("faults.")}
    cfg = seed003.load(path or seed003.SCENARIO,
                       overrides={"clutter.mode": "region", **overrides})
    if faults_file is not None:
        table = tomllib.loads(Path(faults_file).read_text(encoding="utf-8"))
        if "faults" not in table:
            raise ValueError(f"{faults_file}: no [faults] table")
        cfg["faults"] = table["faults"]
    if fault_keys:
        if not isinstance(cfg.setdefault("faults", {}), dict):
            raise ValueError("seed003: 'faults' must be a table")
        apply_overrides(cfg["faults"], fault_keys, "seed003 [faults]")
    return cfg


def net_scenario(cfg: dict, speed: float = SPEED, deadline: float = DEADLINE) -> NetScenario:
    plan = None
    if cfg.get("faults"):
        from sim.scenario import parse_faults

        names = [s["name"] for s in cfg["sensors"]]
        interval = float(cfg["scenario"]["scan_period"]) / speed
        plan = parse_faults(cfg["faults"], interval, names, "seed003 [faults]")
    return NetScenario(cfg, NetSettings(float(speed), float(deadline)), plan)


def draws(cfg: Mapping, run: int):
    """Truth ``(K + 1, 6)``, sensors, target returns, region clutter and the initial estimate
    of run ``run`` (the draws of :func:`sim.seed003_peers.run_once`)."""
    rng = np.random.default_rng([int(cfg["scenario"]["seed"]), int(run)])
    X = seed003.truth(cfg)
    sens = seed003.sensors(cfg)
    target = seed003.target_returns(X, sens, rng)
    m0, P0 = seed003.initial_state(cfg, X[0], rng)
    region = seed003.region_clutter(cfg, X, sens, rng)
    return X, sens, target, region, m0, P0


def run_data(cfg: Mapping, run: int):
    """``(truth, scans)`` of run ``run`` as :func:`sim.world.generate_run` returns them (the
    target's return first in each scan, then the clutter: the order the offline filters use)."""
    from sim.world import Truth

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
    from sim.scenario import ScenarioError  # noqa: PLC0415 (the loader imports this module)

    passed = ("network", "faults", "security", "pda", "fusion")
    cfg = copy.deepcopy({k: v for k, v in doc.items() if k not in passed})
    if bad := _unknown_keys(cfg, tomllib.loads(seed003.SCENARIO.read_text(encoding="utf-8"))):
        raise ScenarioError(f"{label}: unknown key {bad!r} (not a seed-003 setting: "
                            f"sim/scenarios/seed003.toml lists them)")
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
           "config": cfg}
    return {"scenario": scenario, "sensors": sensors, "metrics": metrics, "network": network,
            "pda": pda, **{k: doc[k] for k in ("faults", "security", "fusion") if k in doc}}


# -- peers --------------------------------------------------------------------------------------


def _unknown_keys(doc: Mapping, ref: Mapping, prefix: str = "") -> str | None:
    """The first dotted key of ``doc`` that the shipped file ``ref`` does not have (tables
    recursively, ``[[sensors]]`` entries against the first shipped one), or None."""
    for key, value in doc.items():
        here = f"{prefix}{key}"
        if key not in ref:
            return here
        want = ref[key]
        if isinstance(value, dict) and isinstance(want, dict):
            if bad := _unknown_keys(value, want, here + "."):
                return bad
        elif (isinstance(value, list) and isinstance(want, list) and want
              and isinstance(want[0], dict)):
            for i, entry in enumerate(value):
                if isinstance(entry, dict) and (bad := _unknown_keys(entry, want[0],
                                                                     f"{here}[{i}].")):
                    return bad
    return None


def make_parts(cfg: Mapping, name: str, mode: str, run: int = 0, *, method: str = METHOD,
               pregate: float = PREGATE):
    """The estimator and fuser of the PDA peer of sensor ``name`` in ``mode``, from the run's
    one initial estimate (every peer starts from it)."""
    names = [s["name"] for s in cfg["sensors"]]
    if name not in names:
        raise ValueError(f"seed003: no sensor named {name!r} (sensors: {', '.join(names)})")
    _, sens, _, _, m0, P0 = draws(cfg, run)
    by_name = dict(zip(names, sens, strict=True))
    filt = seed003.make_filter(cfg, method, m0, P0)
    if mode == "meas":
        est = SequentialPdaEstimator(filt, by_name, names, name, POS, pregate)
        return est, SequentialFuser(est)
    if mode == "ci":
        return PdaEstimator(filt, by_name[name], POS, feedback=False), CiFuser()
    raise ValueError(f"seed003: unknown peer mode {mode!r}; expected one of {MODES}")


def make_core(cfg: dict, name: str, mode: str, run: int = 0, *, network: str = "twin",
              speed: float = SPEED, deadline: float = DEADLINE, method: str = METHOD,
              pregate: float = PREGATE) -> PeerCore:
    """The sans-I/O PDA peer of sensor ``name`` in ``mode`` (``"meas"`` or ``"ci"``)."""
    est, fuser = make_parts(cfg, name, mode, run, method=method, pregate=pregate)
    names = [s["name"] for s in cfg["sensors"]]
    X = seed003.truth(cfg)
    others = tuple(n for n in names if n != name)
    opts = ConsensusOptions(name=name, neighbours=others,
                            degrees=tuple((n, len(others)) for n in (name, *others)),
                            rounds=1, max_age=0, policy="drop-late", feedback=False)

    def truth(k: int) -> np.ndarray | None:
        return X[k][None] if 1 <= k < len(X) else None

    scorer = Scorer(float(cfg["metrics"]["loss_bound"]), 2.0, POS, truth)
    core_cfg = CoreConfig(name=name, sensor=name, network=network,
                          interval=float(cfg["scenario"]["scan_period"]) / speed,
                          deadline=deadline)
    return PeerCore(core_cfg, Consensus(opts, est, fuser), scorer)


def twin(cfg: dict, mode: str, run: int = 0, *, speed: float = SPEED,
         deadline: float = DEADLINE, method: str = METHOD, faults=None):
    """The run on the discrete-event twin (:func:`sim.twin.run_twin`); ``faults``: a
    :class:`peers.faults.FaultInjector` (default: the ``[faults]`` table's, if any)."""
    from sim.build import fault_injector
    from sim.twin import run_twin

    scn = net_scenario(cfg, speed, deadline)
    peers = {n: make_core(cfg, n, mode, run, speed=speed, deadline=deadline, method=method)
             for n in scn.sensor_names}
    return run_twin(scn, run, peers=peers, faults=faults or fault_injector(scn, run),
                    data=run_data(cfg, run))


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


def _common(a: argparse.Namespace) -> list[str]:
    out = ["--run", str(a.run), "--speed", str(a.speed), "--deadline", str(a.deadline),
           "--method", a.method, *[x for s in a.set for x in ("--set", s)]]
    if a.faults:
        out += ["--faults", str(a.faults)]
    if a.scenario:
        out += ["--scenario", str(a.scenario)]
    return out


def start(a: argparse.Namespace, cfg: dict, mode: str, out: Path):
    """World and peers of one mode as processes (a :class:`sim.launcher.RunHandle`)."""
    from peers.session import endpoint, free_port
    from sim.launcher import RunHandle

    names = [s["name"] for s in cfg["sensors"]]
    network = f"seed003-{mode}-{uuid.uuid4().hex[:8]}"
    run_id = f"{network}-{uuid.uuid4().hex[:6]}"
    eps = {"world": endpoint(free_port()), **{n: endpoint(free_port()) for n in names}}
    me = [sys.executable, "-m", "sim.seed003_net"]
    shared = ["--network", network, "--out", str(out), "--run-id", run_id, *_common(a)]
    if a.viewer:
        shared += ["--viewer", a.viewer]
    if a.no_rerun:
        shared += ["--no-rerun"]
    cmds = {"world": [*me, "world", *shared, "--listen", eps["world"],
                      "--peers", ",".join(names)]}
    for i, n in enumerate(names):
        links = [eps["world"], *(eps[m] for m in names[:i])]
        cmds[n] = [*me, "peer", n, "--mode", mode, *shared, "--listen", eps[n],
                   "--color", str(i), *[x for c in links for x in ("--connect", c)]]
    (out / "logs").mkdir(parents=True, exist_ok=True)
    (out / "commands.json").write_text(json.dumps(cmds, indent=1))
    handle = RunHandle(out=out, endpoints=eps, network=network, commands=cmds)
    try:
        for n, cmd in cmds.items():
            handle.logs[n] = out / "logs" / f"{n}.log"
            with handle.logs[n].open("w") as fh:
                handle.procs[n] = subprocess.Popen(cmd, stdout=fh, stderr=subprocess.STDOUT,
                                                   stdin=subprocess.DEVNULL)
    except BaseException:
        handle.stop_all(grace=1.0)
        raise
    return handle


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
    """One mode as processes; its table rows (beside the twin) and an exit code."""
    from sim.launcher import merge_recordings, read_summaries, wait_run

    out.mkdir(parents=True, exist_ok=True)
    names = [s["name"] for s in cfg["sensors"]]
    ref = twin(cfg, mode, a.run, speed=a.speed, deadline=a.deadline, method=a.method)
    if ref.faults is not None:
        print(f"{mode}: link faults, twin's decisions: {_fault_counts(ref.faults)}", flush=True)
    handle = start(a, cfg, mode, out)
    expected = int(cfg["scenario"]["num_scans"]) * float(cfg["scenario"]["scan_period"]) / a.speed
    codes = wait_run(handle, timeout=expected + a.timeout)
    summaries = read_summaries(out, names)
    rows = [make_row(cfg, mode, n, summaries[n], read_tracks(out, n), ref.tracks[n])
            for n in names if n in summaries]
    rec = None if a.no_rerun else merge_recordings(out)
    if rec is not None:
        print(f"{mode}: recording {rec}  (view it with: rerun {rec})", flush=True)
    bad = {n: c for n, c in codes.items() if c != 0}
    missing = [n for n in names if n not in summaries]
    if bad or missing or handle.timed_out:
        print(f"seed003 {mode}: exit codes {codes}, no summary from {missing or 'none'}"
              f"{', timed out' if handle.timed_out else ''} (logs in {out / 'logs'})",
              file=sys.stderr)
        return rows, 1
    return rows, 0


def _checked(check, *what: str):
    """An argparse ``type=`` from a name check: its one-line message on a bad value."""
    def parse(text: str) -> str:
        try:
            return check(text, *what)
        except ValueError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None
    return parse


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m sim.seed003_net",
                                description=__doc__.split("\n")[0])
    sub = p.add_subparsers(dest="cmd", required=True)

    def common(sp: argparse.ArgumentParser) -> None:
        sp.add_argument("--run", type=int, default=0, help="Monte Carlo run (its draws)")
        sp.add_argument("--speed", type=float, default=SPEED, help="scans per scan period")
        sp.add_argument("--deadline", type=float, default=DEADLINE,
                        help="fusion deadline, fraction of the scan interval")
        sp.add_argument("--method", default=METHOD, choices=seed003.METHODS)
        sp.add_argument("--set", action="append", default=[], metavar="TABLE.KEY=VALUE")
        sp.add_argument("--faults", type=Path, help="TOML file with a [faults] table")
        sp.add_argument("--scenario", type=Path,
                        help="scenario file (default sim/scenarios/seed003.toml)")
        sp.add_argument("--out", type=Path)
        sp.add_argument("--viewer")
        sp.add_argument("--no-rerun", action="store_true")

    r = sub.add_parser("run", help="both modes as processes, one table")
    common(r)
    r.add_argument("--modes", default=",".join(MODES))
    r.add_argument("--timeout", type=float, default=60.0,
                   help="seconds allowed beyond the scans' own time")
    r.add_argument("--sim", action="store_true", help="the twin only (no processes)")
    for cmd in ("world", "peer"):
        sp = sub.add_parser(cmd)
        common(sp)
        sp.add_argument("--network", required=True, type=_checked(check_name, "network name"))
        sp.add_argument("--run-id", type=_checked(check_run_id))
        sp.add_argument("--listen", action="append", default=[])
        sp.add_argument("--connect", action="append", default=[])
        if cmd == "world":
            sp.add_argument("--peers", default="")
        else:
            sp.add_argument("name")
            sp.add_argument("--mode", choices=MODES, required=True)
            sp.add_argument("--color", type=int, default=0)
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
        cfg = load(_overrides(a.set), a.faults, a.scenario)
        scn = net_scenario(cfg, a.speed, a.deadline)
    except (ValueError, OSError) as exc:
        print(f"sensornet: error: seed003: {exc}", file=sys.stderr)
        return 2
    if a.cmd == "world":
        from sim.world_process import run_world

        sent = run_world(scn, a.network, run=a.run, listen=a.listen, connect=a.connect,
                         wait_for=[p for p in a.peers.split(",") if p], wait_timeout=PEER_WAIT,
                         out_dir=a.out, run_id=a.run_id, viewer=a.viewer, speed=a.speed,
                         rerun=not a.no_rerun, say=lambda line: print(line, flush=True),
                         data=run_data(cfg, a.run))
        print(f"world: published {sent['scans_published']} scans", flush=True)
        return 0
    if a.cmd == "peer":
        from peers.runtime import PeerRuntime, RuntimeOptions
        from sim.build import fault_injector

        core = make_core(cfg, a.name, a.mode, a.run, network=a.network, speed=a.speed,
                         deadline=a.deadline, method=a.method)
        runtime = PeerRuntime(core, RuntimeOptions(
            listen=tuple(a.listen), connect=tuple(a.connect), out_dir=a.out,
            run_id=a.run_id, viewer=a.viewer, color_index=a.color, rerun=not a.no_rerun,
            save_tracks=True, scan_period=scn.scan_period, faults=fault_injector(scn, a.run)))
        code = runtime.run()
        s = runtime.summary()
        print(f"peer {a.name} ({a.mode}): stopped ({s['stop_reason']}); {s['scans']} scans, "
              f"fuser {s['fuser']}", flush=True)
        return code
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
        print(f"seed003: world + {len(scn.sensor_names)} PDA peers as processes over Zenoh on "
              f"127.0.0.1, run {a.run}, {scn.num_scans} scans at {a.speed:g}x, modes "
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
