"""Running a campaign: skip what is stored, run the rest on a pool or Dask, one progress line, a
lock file while a process runs it."""

from __future__ import annotations

import json
import math
import os
import socket
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TextIO

from sensornet.sim.campaign.campaign_model import Campaign, CampaignError
from sensornet.sim.campaign.results import ResultStore, need_pyarrow
from sensornet.sim.campaign.runners import run_dask, run_pool
from sensornet.sim.run.progress import Progress


class CampaignProgress(Progress):
    """``[####   ] 37/100 runs, cells 1/2, 3.1 runs/s, eta 20s``."""

    def __init__(self, total: int, cell_sizes: dict[int, int], cell_done: dict[int, int],
                 stream: TextIO | None = None, enabled: bool = True) -> None:
        self.cell_sizes, self.cell_done = cell_sizes, dict(cell_done)
        super().__init__(total, "runs", stream=stream, enabled=enabled)

    def finished(self, cell: int) -> None:
        self.cell_done[cell] = self.cell_done.get(cell, 0) + 1
        self.advance()

    def _line(self) -> str:
        frac = self.done / self.total
        elapsed = time.monotonic() - self.start
        rate = self.done / elapsed if elapsed > 0 else 0.0
        eta = (self.total - self.done) / rate if rate > 0 else math.nan
        cells = sum(1 for c, n in self.cell_sizes.items() if self.cell_done.get(c, 0) >= n)
        return (f"[{'#' * int(30 * frac):<30}] {self.done}/{self.total} runs, cells "
                f"{cells}/{len(self.cell_sizes)}, {rate:.2f} runs/s, eta "
                f"{'?' if math.isnan(eta) else f'{eta:.0f}s'}, "
                f"{elapsed:.0f}s elapsed")


# --------------------------------------------------------------------------------------------
# Running
# --------------------------------------------------------------------------------------------


LOCK = "running.json"
"""In a campaign folder while a process runs it: ``{"pid", "host", "start"}``."""


def _start_stamp(pid: int) -> str | None:
    """When process ``pid`` started (Linux ``/proc``: a pid reused by another process has
    another stamp), or None where that cannot be read."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[19]
    except (OSError, IndexError):
        return None


def read_lock(folder: Path) -> dict[str, Any] | None:
    try:
        lock = json.loads((Path(folder) / LOCK).read_text())
    except (OSError, ValueError):
        return None
    return lock if isinstance(lock, dict) else None


def lock_alive(lock: dict[str, Any]) -> bool:
    """Whether the process that wrote ``lock`` still runs (one on another host: assumed)."""
    if lock.get("host") != socket.gethostname():
        return True  # cannot be checked from here
    pid = lock.get("pid")
    if not isinstance(pid, int) or pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        pass
    stamp = _start_stamp(pid)
    return stamp is None or lock.get("start") in (None, stamp)


def _claim(folder: Path) -> Path:
    """Write the folder's lock (refused while another live process holds it)."""
    held = read_lock(folder)
    if held is not None and held.get("pid") != os.getpid() and lock_alive(held):
        raise CampaignError(f"{folder}: the campaign is running already (pid {held.get('pid')} "
                            f"on {held.get('host')}); wait for it, or stop it first")
    path = folder / LOCK
    path.write_text(json.dumps({"pid": os.getpid(), "host": socket.gethostname(),
                                "start": _start_stamp(os.getpid())}) + "\n")
    return path


@dataclass
class RunSummary:
    ran: int
    skipped: int
    stopped: bool
    seconds: float
    cpu_seconds: float = 0.0
    """CPU time the finished tasks used (all workers): ``cpu_seconds / seconds`` is how many
    cores the campaign actually had."""


def run_campaign(c: Campaign, folder: Path, jobs: int = 1, dask: str | None = None,
                 progress: bool = True, stop_after: int | None = None,
                 on_row: Callable[[dict], None] | None = None,
                 stream: TextIO | None = None) -> RunSummary:
    """Run every task of ``c`` whose key is not stored in ``folder``.

    ``dask``: ``None`` (a local process pool of ``jobs``), ``"local"`` (a Dask
    ``LocalCluster`` of ``jobs`` workers) or a scheduler address. ``stop_after``: stop (as an
    interrupt would) once that many tasks have finished in this call.
    """
    need_pyarrow()
    folder.mkdir(parents=True, exist_ok=True)
    lock = _claim(folder)
    try:
        return _run(c, folder, jobs, dask, progress, stop_after, on_row, stream)
    finally:
        lock.unlink(missing_ok=True)


def _run(c: Campaign, folder: Path, jobs: int, dask: str | None, progress: bool,
         stop_after: int | None, on_row: Callable[[dict], None] | None,
         stream: TextIO | None) -> RunSummary:
    (folder / "manifest.json").write_text(json.dumps(c.manifest(), indent=1) + "\n")
    store = ResultStore(folder / "results")
    stored = store.done_keys()
    tasks = [t for t in c.tasks() if t.key not in stored]
    skipped = len(c.tasks()) - len(tasks)
    sizes = {cell.index: len(cell.keys) for cell in c.cells}
    done0 = {cell.index: sum(1 for k in cell.keys if k in stored) for cell in c.cells}
    t0 = time.monotonic()
    ran, cpu = 0, 0.0
    stopped = False
    rows: Iterator[dict]
    if not tasks:
        rows = iter(())
    elif dask is None:
        rows = run_pool(tasks, jobs)
    else:
        rows = run_dask(tasks, scheduler=None if dask == "local" else dask, jobs=jobs)
    try:
        with CampaignProgress(len(tasks), sizes, done0, stream=stream,
                              enabled=progress and bool(tasks)) as bar:
            for row in rows:
                store.write(row)
                ran += 1
                cpu += float(row.get("cpu_seconds", 0.0))
                bar.finished(row["cell"])
                if on_row is not None:
                    on_row(row)
                if stop_after is not None and ran >= stop_after and ran < len(tasks):
                    stopped = True
                    break
    finally:
        close = getattr(rows, "close", None)
        if close is not None:
            close()
        store.compact()
    return RunSummary(ran, skipped, stopped, time.monotonic() - t0, cpu)
