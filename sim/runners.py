"""Campaign tasks and where they run: in-process, a local process pool, or a Dask cluster.

A :class:`Task` is one (cell, run) pair: pure and seeded (every random draw comes from the
scenario's seed and the run index), so its row is the same bit for bit wherever it runs. The
task carries the scenario *text* (not a path), so a worker on another machine needs only the
project installed, not the campaign's files. A worker checks that its code version and its
reading of the scenario hash to the values the client computed, and refuses otherwise.

Runners (``runner`` in the campaign file):

* ``experiment``: the offline Monte Carlo of :func:`sim.experiment.run_once` (each sensor's
  local GM-PHD, the fusing sensor's fusion, the centralized filter): per-scan OSPA, estimate
  counts, component counts before and after level-2 pruning (the seed-000 figures);
* ``twin``: the peer network on the discrete-event twin (:func:`sim.twin.run_twin`): fused and
  local OSPA averaged over the peers, out-of-sequence counters, link-fault counts;
* ``real``: the peers as processes over Zenoh (:mod:`sim.launcher`), as ``sensornet run``;
* ``seed001``: seed 001's single-target study (:func:`sim.seed001.run_once`: IMM-EKF and IMM-PF
  peers, each radar alone, GCI fusion and the particle fusion rule); its cells set
  :data:`SEED001_KEYS` (``geometry = "A"``, ``particles = 800``, ``omega = 0.15``, ...), not
  scenario-file keys. Per run: mean squared x position / velocity / acceleration error and
  whether the track was lost, per (filter, estimate): Table 1 from them.
"""

from __future__ import annotations

import fnmatch
import functools
import hashlib
import os
import socket
import tempfile
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

RUNNERS = ("experiment", "twin", "real", "seed001")

SEED001_KEYS = ("geometry", "seed", "particles", "jitter", "omega", "filters", "loss_threshold",
                "loss_after")
"""What a ``seed001`` campaign's ``[set]``/``[grid]`` may change (sim/seed001.py)."""

_NOT_CODE = {"report.py", "progress.py", "campaign.py", "results.py", "fusion_study.py",
             "trust_calibration.py"}
"""Modules of ``sim`` that do not change what a task computes (left out of the code version)."""


def code_version() -> str:
    """A hash of the source that computes a task (``tracking``, ``peers``, ``protocol``,
    ``sim``) and of the numeric libraries' versions: results from other code are not reused.

    ``$SENSORNET_CODE_VERSION``, when set, is used instead (the tests pin it, so that edits
    made to a shared working tree while they run do not change it half-way).
    """
    return os.environ.get("SENSORNET_CODE_VERSION") or _source_hash()


@functools.cache
def _source_hash() -> str:
    import scipy

    root = Path(__file__).resolve().parent.parent
    h = hashlib.sha256(f"numpy {np.__version__} scipy {scipy.__version__}".encode())
    for pkg in ("tracking", "peers", "protocol", "sim"):
        for p in sorted((root / pkg).rglob("*.py")):
            if pkg == "sim" and p.name in _NOT_CODE and p.parent.name == "sim":
                continue
            h.update(p.relative_to(root).as_posix().encode())
            h.update(p.read_bytes())
    return h.hexdigest()[:16]


def scenario_hash(scn: Any) -> str:
    """A hash of a fully resolved scenario (every value after overrides and validation; the
    informational ``source`` left out)."""
    import dataclasses

    return hashlib.sha256(repr(dataclasses.replace(scn, source="")).encode()).hexdigest()[:16]


@dataclass(frozen=True)
class Task:
    """One (cell, run) pair of a campaign."""

    key: str
    cell: int
    cell_label: str
    run: int
    runner: str
    scenario: str
    """A built-in scenario name, or the file name of ``scenario_text``."""
    scenario_text: str | None
    overrides: dict = field(default_factory=dict)
    scenario_hash: str = ""
    code_version: str = ""
    metrics: tuple[str, ...] = ("*",)


_SCENARIO_DIR: dict[str, Path] = {}


def scenario_source(name: str, text: str | None) -> str:
    """A path (or built-in name) this process can load: file text is written once per process
    to a temporary file of the same name, so the scenario reads exactly as on the client."""
    if text is None:
        return name
    digest = hashlib.sha256(text.encode()).hexdigest()[:16]
    if digest not in _SCENARIO_DIR:
        folder = Path(tempfile.mkdtemp(prefix=f"sensornet-campaign-{digest}-"))
        (folder / Path(name).name).write_text(text, encoding="utf-8")
        _SCENARIO_DIR[digest] = folder
    return str(_SCENARIO_DIR[digest] / Path(name).name)


def seed001_setup(overrides: dict):
    """``(Seed001Scenario, ExperimentConfig)`` of a ``seed001`` cell; ``ValueError`` naming the
    key for anything else."""
    from dataclasses import replace

    from sim.seed001 import FILTERS, GEOMETRIES, ExperimentConfig, Seed001Scenario

    unknown = sorted(set(overrides) - set(SEED001_KEYS))
    if unknown:
        raise ValueError(f"seed001 runner: unknown key(s) {unknown} (known: "
                         f"{', '.join(SEED001_KEYS)})")
    o = dict(overrides)
    geometry = o.get("geometry", "A")
    if geometry not in GEOMETRIES:
        raise ValueError(f"seed001 runner: geometry must be one of {sorted(GEOMETRIES)}, "
                         f"got {geometry!r}")
    scn = Seed001Scenario(geometry=geometry, seed=int(o.get("seed", 1)))
    cfg = ExperimentConfig()
    if "particles" in o or "jitter" in o:
        cfg = replace(cfg, particle=replace(
            cfg.particle, n_particles=int(o.get("particles", cfg.particle.n_particles)),
            jitter=float(o.get("jitter", cfg.particle.jitter))))
    if "omega" in o:
        cfg = replace(cfg, gci_omega=o["omega"])
    if "filters" in o:
        filters = tuple(o["filters"]) if isinstance(o["filters"], list) else (o["filters"],)
        if not filters or any(f not in FILTERS for f in filters):
            raise ValueError(f"seed001 runner: filters must be a list of {FILTERS}, "
                             f"got {o['filters']!r}")
        cfg = replace(cfg, filters=filters)
    for k in ("loss_threshold", "loss_after"):
        if k in o:
            cfg = replace(cfg, **{k: type(getattr(cfg, k))(o[k])})
    return scn, cfg


def seed001_hash(setup) -> str:
    return hashlib.sha256(repr(setup).encode()).hexdigest()[:16]


_SCENARIOS: dict[tuple[str, str | None, str], Any] = {}


def load_task_scenario(task: Task):
    """The task's resolved scenario, parsed once per process and cell (scenarios are frozen
    dataclasses: the runs of a cell share one)."""
    import json

    from sim.scenario import load_scenario

    key = (task.scenario, task.scenario_text, json.dumps(task.overrides, sort_keys=True,
                                                         default=repr))
    if key not in _SCENARIOS:
        _SCENARIOS[key] = load_scenario(scenario_source(task.scenario, task.scenario_text),
                                        overrides=task.overrides)
    return _SCENARIOS[key]


_RUNNER_MODULES = {"experiment": ("sim.experiment",), "twin": ("sim.twin",),
                   "real": ("sim.launcher", "sim.sweep"), "seed001": ("sim.seed001",)}


def warm(tasks: list[Task]) -> None:
    """Import what the tasks' runners need and parse each cell's scenario once, here: a
    process pool forked after this call starts with all of it (its workers neither import
    nor parse per task or per worker)."""
    import importlib

    for name in {m for t in tasks for m in _RUNNER_MODULES.get(t.runner, ())}:
        importlib.import_module(name)
    seen = set()
    for t in tasks:
        if t.runner != "seed001" and (t.cell, t.scenario) not in seen:
            seen.add((t.cell, t.scenario))
            load_task_scenario(t)


def _worker_init(tasks: list[Task]) -> None:
    """Pool worker start: one BLAS thread (two workers with a BLAS pool each would
    oversubscribe the cores the pool already fills), and the imports when the pool does not
    fork (spawn/forkserver start methods)."""
    try:
        from threadpoolctl import threadpool_limits

        threadpool_limits(1)
    except ImportError:
        pass
    warm(tasks)


def run_task(task: Task) -> dict[str, Any]:
    """Compute one task: its row (metadata, then the runner's metrics)."""
    if task.code_version and task.code_version != code_version():
        raise RuntimeError(f"worker {socket.gethostname()}: code version {code_version()} "
                           f"differs from the client's {task.code_version}: install the same "
                           "sensornet version on every worker")
    if task.runner == "seed001":
        setup = seed001_setup(task.overrides)
        scn, here = setup, seed001_hash(setup)
    else:
        scn = load_task_scenario(task)
        here = scenario_hash(scn)
    if task.scenario_hash and here != task.scenario_hash:
        raise RuntimeError(f"worker {socket.gethostname()}: the scenario of cell "
                           f"{task.cell_label!r} resolves differently here than on the client")
    t0, c0 = time.perf_counter(), time.process_time()
    if task.runner == "experiment":
        metrics = _experiment_row(scn, task.run)
    elif task.runner == "twin":
        metrics = _twin_row(scn, task.run)
    elif task.runner == "real":
        metrics = _real_row(scn, task)
    elif task.runner == "seed001":
        metrics = _seed001_row(*scn, task.run)
    else:
        raise ValueError(f"unknown runner {task.runner!r} (expected one of {RUNNERS})")
    row: dict[str, Any] = {
        "key": task.key, "cell": task.cell, "cell_label": task.cell_label, "run": task.run,
        "runner": task.runner, "code_version": code_version(),
        "seconds": time.perf_counter() - t0, "cpu_seconds": time.process_time() - c0,
        "worker": f"{socket.gethostname()}:{os.getpid()}"}
    for k, v in metrics.items():
        if any(fnmatch.fnmatchcase(k, p) for p in task.metrics):
            row[k] = v
    return row


def method_key(method: str) -> str:
    """``"local s1"`` -> ``local_s1``, ``"fused s2 (gci)"`` -> ``fused``, ``centralized``."""
    if method.startswith("fused"):
        return "fused"
    return method.replace(" ", "_")


def _experiment_row(scn, run: int) -> dict[str, Any]:
    from sim.experiment import method_names, run_once

    res = run_once(scn, run)
    K = scn.num_scans
    out: dict[str, Any] = {}
    for m in method_names(scn):
        k = method_key(m)
        out[f"mean_ospa.{k}"] = float(res.ospa[m].mean())
        out[f"mean_card_error.{k}"] = float(res.card_error[m].mean())
        out[f"ms_per_scan.{k}"] = res.seconds[m] / K * 1e3
    for m in method_names(scn):
        k = method_key(m)
        out[f"ospa_k.{k}"] = res.ospa[m]
        out[f"n_est_k.{k}"] = res.n_estimates[m]
    out["n_true_k"] = res.n_true
    for c, v in res.components.items():
        out[f"comp_k.{c}"] = v
    return out


def seed001_method(filt: str, rule: str) -> str:
    """``("IMM-EKF", "GCI fusion")`` -> ``IMM-EKF.GCI_fusion``."""
    return f"{filt}.{rule.replace(' ', '_')}"


def _seed001_row(scn, cfg, run: int) -> dict[str, Any]:
    from sim.seed001 import run_once

    res = run_once(scn, cfg, run)
    out: dict[str, Any] = {}
    for (filt, rule), e in res.errors.items():
        m = seed001_method(filt, rule)
        sq = np.mean(np.square(e), axis=0)  # x position, velocity, acceleration
        out[f"msx_pos.{m}"], out[f"msx_vel.{m}"], out[f"msx_acc.{m}"] = (float(x) for x in sq)
        pe = res.pos_error[(filt, rule)]
        out[f"lost.{m}"] = float(pe[cfg.loss_after:].max() > cfg.loss_threshold)
        out[f"mean_pos_error.{m}"] = float(pe.mean())
    for filt, sec in res.seconds.items():
        out[f"ms_per_scan.{filt}"] = sec / scn.num_scans * 1e3
    return out


def _twin_row(scn, run: int) -> dict[str, Any]:
    from sim.sweep import cost_columns
    from sim.twin import run_twin

    result = run_twin(scn, run)
    peers = result.peers
    out: dict[str, Any] = {
        "fused_ospa": float(np.mean([p.mean_ospa("fused") for p in peers.values()])),
        "local_ospa": float(np.mean([p.mean_ospa("local") for p in peers.values()])),
        "fused_card_error": float(np.mean([p.scorer.mean_cardinality_error("fused")
                                           for p in peers.values()])),
        "local_card_error": float(np.mean([p.scorer.mean_cardinality_error("local")
                                           for p in peers.values()]))}
    for key in ("late", "redundant", "too_old", "dropped_late"):
        out[key] = sum(getattr(p.consensus.nale.counts, key) for p in peers.values())
    out.update(cost_columns([p.cost() for p in peers.values()]))
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


def _real_row(scn, task: Task) -> dict[str, Any]:
    from sim.launcher import read_summaries, start_run, wait_run
    from sim.sweep import _toml, cost_columns

    source = scenario_source(task.scenario, task.scenario_text)
    sets = [f"{k}={_toml(v)}" for k, v in task.overrides.items()]
    with tempfile.TemporaryDirectory(prefix="sensornet-campaign-") as tmp:
        handle = start_run(scn, source, Path(tmp), overrides=sets, run=task.run, rerun=False)
        try:
            wait_run(handle, timeout=scn.num_scans * scn.scan_period / scn.network.speed + 90)
        finally:
            handle.stop_all()
        summaries = read_summaries(Path(tmp), scn.sensor_names)
    out: dict[str, Any] = {
        "fused_ospa": float(np.mean([s["mean_ospa_fused"] for s in summaries.values()])),
        "local_ospa": float(np.mean([s["mean_ospa_local"] for s in summaries.values()]))}
    for key in ("late", "redundant", "too_old", "dropped_late"):
        out[key] = sum(s["nale"][key] for s in summaries.values())
    out.update(cost_columns([s.get("cost") or {} for s in summaries.values()]))
    for name, s in summaries.items():
        out[f"fused_ospa.{name}"] = float(s["mean_ospa_fused"])
        if s.get("latency_ms_median") is not None:
            out[f"ms_latency_median.{name}"] = float(s["latency_ms_median"])
    return out


# --------------------------------------------------------------------------------------------
# Executors: each yields rows as tasks finish; closing the iterator cancels what is pending
# --------------------------------------------------------------------------------------------


def run_serial(tasks: list[Task]) -> Iterator[dict]:
    for t in tasks:
        yield run_task(t)


def run_pool(tasks: list[Task], jobs: int) -> Iterator[dict]:
    """A local process pool of ``jobs`` workers (in this process when ``jobs`` is 1)."""
    if jobs <= 1 or len(tasks) <= 1:
        yield from run_serial(tasks)
        return
    from concurrent.futures import ProcessPoolExecutor, as_completed

    code_version()  # computed once here, inherited by the workers
    # One task per cell is enough to warm a worker (imports, scenarios): sent once, not per task.
    firsts = list({t.cell: t for t in reversed(tasks)}.values())
    warm(firsts)
    pool = ProcessPoolExecutor(max_workers=min(jobs, len(tasks)), initializer=_worker_init,
                               initargs=(firsts,))
    try:
        futures = [pool.submit(run_task, t) for t in tasks]
        for fut in as_completed(futures):
            yield fut.result()
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


class DaskUnavailable(ImportError):
    pass


def _need_dask():
    try:
        import dask
        import distributed
    except ImportError:
        raise DaskUnavailable("--dask/--scheduler need Dask: pip install 'sensornet[campaign]' "
                              "(or pip install 'dask[distributed]')") from None
    # Dask's workers set MALLOC_TRIM_THRESHOLD_=65536, which made NumPy tasks ~6x slower here
    # (../shared/spec/STACK_NOTES.md); command-line workers need the same in a $DASK_CONFIG file.
    dask.config.set({"distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None})
    return dask, distributed


def run_dask(tasks: list[Task], scheduler: str | None = None, jobs: int = 2,
             on_start=None) -> Iterator[dict]:
    """Tasks on a Dask cluster: ``scheduler`` (``tcp://HOST:8786``) or, when ``None``, a
    ``LocalCluster`` of ``jobs`` single-threaded worker processes."""
    import logging

    _, distributed = _need_dask()
    cluster = None
    if scheduler is None:
        cluster = distributed.LocalCluster(n_workers=jobs, threads_per_worker=1,
                                           processes=True, dashboard_address=None,
                                           silence_logs=logging.ERROR)
        client = distributed.Client(cluster)
    else:
        try:
            client = distributed.Client(scheduler, timeout="10s")
        except OSError as exc:
            raise ConnectionError(f"no Dask scheduler at {scheduler}: {exc}") from None
    if on_start is not None:
        on_start(client)
    futures = []
    try:
        futures = [client.submit(run_task, t, key=f"sensornet-{t.key}", pure=False)
                   for t in tasks]
        for fut in distributed.as_completed(futures):
            yield fut.result()
    finally:
        pending = [f for f in futures if not f.done()]
        if pending:
            client.cancel(pending)
        client.close()
        if cluster is not None:
            cluster.close()
