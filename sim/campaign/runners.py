"""Campaign tasks and where they run: in-process, a local process pool, or a Dask cluster.

A :class:`Task` is one (cell, run) pair: pure and seeded (every random draw comes from the
scenario's seed and the run index), so its row is the same bit for bit wherever it runs. The
task carries the scenario *text* (not a path), so a worker on another machine needs only the
project installed, not the campaign's files. A worker checks that its code version and its
reading of the scenario hash to the values the client computed, and refuses otherwise.

A task's ``runner`` is a study's name (:mod:`sim.studies`: those with a ``row`` hook, e.g.
``experiment``, ``twin``, ``real``, ``seed001``): the study makes the cell's setup and computes
the run's columns; this module never names one.
"""

from __future__ import annotations

import dataclasses
import fnmatch
import functools
import hashlib
import importlib
import json
import logging
import os
import socket
import tempfile
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import scipy
from sensornet.sim import studies
from sensornet.sim.run.pool import iter_pool
from sensornet.sim.scenario import load_scenario

try:  # optional dependency: threadpoolctl (without it a pool worker keeps BLAS's threads)
    from threadpoolctl import threadpool_limits
except ImportError:
    threadpool_limits = None

_NOT_CODE = {"campaign/report.py", "report/report_html.py", "report/report_plots.py",
             "run/progress.py", "campaign/__init__.py", "campaign/campaign_model.py",
             "campaign/campaign_run.py", "campaign/campaign_results.py", "campaign/results.py",
             "studies/fusion/quality.py", "studies/lying/trust_calibration.py"}
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
    root = Path(__file__).resolve().parents[2]
    h = hashlib.sha256(f"numpy {np.__version__} scipy {scipy.__version__}".encode())
    for pkg in ("tracking", "peers", "protocol", "sim"):
        for p in sorted((root / pkg).rglob("*.py")):
            if pkg == "sim" and p.relative_to(root / "sim").as_posix() in _NOT_CODE:
                continue
            h.update(p.relative_to(root).as_posix().encode())
            h.update(p.read_bytes())
    return h.hexdigest()[:16]


def scenario_hash(scn: Any) -> str:
    """A hash of a fully resolved scenario (every value after overrides and validation; the
    informational ``source`` left out)."""
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


_SCENARIOS: dict[tuple[str, str | None, str], Any] = {}


def load_task_scenario(task: Task):
    """The task's resolved setup (a scenario, or what its study's ``cell_setup`` makes),
    made once per process and cell (setups are frozen: the runs of a cell share one)."""
    key = (task.runner, task.scenario, task.scenario_text,
           json.dumps(task.overrides, sort_keys=True, default=repr))
    if key not in _SCENARIOS:
        make = studies.get(task.runner).cell_setup
        source = scenario_source(task.scenario, task.scenario_text)
        _SCENARIOS[key] = (make(source, task.overrides) if make is not None else
                           load_scenario(source, overrides=task.overrides))
    return _SCENARIOS[key]


def setup_hash(runner: str, setup: Any) -> str:
    """The hash a cell's setup is checked by on every worker (the study's, or the scenario's)."""
    own = studies.get(runner).setup_hash
    return own(setup) if own is not None else scenario_hash(setup)


def warm(tasks: list[Task]) -> None:
    """Import what the tasks' studies need and make each cell's setup once, here: a process
    pool forked after this call starts with all of it (its workers neither import nor parse
    per task or per worker)."""
    for name in {m for t in tasks for m in studies.get(t.runner).modules}:
        importlib.import_module(name)
    seen = set()
    for t in tasks:
        if (t.cell, t.scenario) not in seen:
            seen.add((t.cell, t.scenario))
            load_task_scenario(t)


def _worker_init(tasks: list[Task]) -> None:
    """Pool worker start: one BLAS thread (two workers with a BLAS pool each would
    oversubscribe the cores the pool already fills), and the imports when the pool does not
    fork (spawn/forkserver start methods)."""
    if threadpool_limits is not None:
        threadpool_limits(1)
    warm(tasks)


def run_task(task: Task) -> dict[str, Any]:
    """Compute one task: its row (metadata, then the runner's metrics)."""
    if task.code_version and task.code_version != code_version():
        raise RuntimeError(f"worker {socket.gethostname()}: code version {code_version()} "
                           f"differs from the client's {task.code_version}: install the same "
                           "sensornet version on every worker")
    study = studies.get(task.runner)
    if study.row is None:
        raise ValueError(f"study {task.runner!r} is not a campaign runner")
    setup = load_task_scenario(task)
    if task.scenario_hash and setup_hash(task.runner, setup) != task.scenario_hash:
        raise RuntimeError(f"worker {socket.gethostname()}: the scenario of cell "
                           f"{task.cell_label!r} resolves differently here than on the client")
    t0, c0 = time.perf_counter(), time.process_time()
    metrics = study.row(setup, task)
    row: dict[str, Any] = {
        "key": task.key, "cell": task.cell, "cell_label": task.cell_label, "run": task.run,
        "runner": task.runner, "code_version": code_version(),
        "seconds": time.perf_counter() - t0, "cpu_seconds": time.process_time() - c0,
        "worker": f"{socket.gethostname()}:{os.getpid()}"}
    for k, v in metrics.items():
        if any(fnmatch.fnmatchcase(k, p) for p in task.metrics):
            row[k] = v
    return row


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
    code_version()  # computed once here, inherited by the workers
    # One task per cell is enough to warm a worker (imports, scenarios): sent once, not per task.
    firsts = list({t.cell: t for t in reversed(tasks)}.values())
    warm(firsts)
    rows = iter_pool(run_task, [(t,) for t in tasks], jobs, _worker_init, (firsts,))
    try:
        for _, row in rows:
            yield row
    finally:
        rows.close()


class DaskUnavailable(ImportError):
    pass


def _need_dask():
    try:  # heavy optional dependency: dask (only --dask/--scheduler campaigns need it)
        import dask
        import distributed  # heavy optional dependency: distributed (Dask's cluster)
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
