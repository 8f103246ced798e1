"""Resumable campaign results: one Parquet row per finished (cell, run), keyed by a hash.

A row's ``key`` hashes the run's fully resolved scenario, its runner, its run index and the code
version (:func:`sim.campaign.task_key`), so a result is reused only for exactly the computation
that produced it. Every finished task is written at once to its own small file
(``results/<key>.parquet``, written to a temporary name and renamed, so a killed campaign never
leaves half a file); :meth:`ResultStore.compact` folds those into one ``part-*.parquet`` file when
a campaign stops (finished, interrupted or failed). Reading deduplicates by key.

Needs ``pyarrow`` (``pip install 'sensornet[campaign]'``).
"""

from __future__ import annotations

import fnmatch
import os
import uuid
from collections.abc import Iterable
from pathlib import Path
from typing import Any

META_COLUMNS = ("key", "cell", "cell_label", "run", "runner", "code_version", "seconds",
                "cpu_seconds", "worker")
"""Columns every row has; the others are the runner's metrics."""

TIMING_COLUMNS = ("seconds", "cpu_seconds", "worker", "ms_per_scan.*", "ms_latency_*",
                  "cell", "cell_label")
"""Columns that depend on the machine, the clock or the campaign file's cell order rather than
on the computation (left out when results are compared bit for bit)."""


def need_pyarrow():
    """``pyarrow`` and ``pyarrow.parquet``, or a one-line :class:`ImportError` saying what to
    install."""
    try:  # heavy optional dependency: pyarrow (the one place the campaign code loads it)
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        raise ImportError("campaign results need pyarrow: pip install 'sensornet[campaign]' "
                          "(or pip install pyarrow)") from None
    return pa, pq


def is_timing(column: str) -> bool:
    return any(fnmatch.fnmatchcase(column, p) for p in TIMING_COLUMNS)


def _normalise(row: dict[str, Any]) -> dict[str, Any]:
    """Metric scalars as float64 and series as lists of float64, so every file's schema
    unifies with every other's (an integer count in one file, a float in another would not)."""
    out: dict[str, Any] = {}
    for k, v in row.items():
        if k in ("cell", "run"):
            out[k] = int(v)
        elif k in META_COLUMNS:
            out[k] = v
        elif isinstance(v, list | tuple):
            out[k] = [float(x) for x in v]
        elif hasattr(v, "tolist"):  # numpy scalar or array
            v = v.tolist()
            out[k] = [float(x) for x in v] if isinstance(v, list) else float(v)
        else:
            out[k] = float(v)
    return out


class ResultStore:
    """The ``results/`` folder of a campaign."""

    KEEP = 500
    """Rows kept in memory for compaction at most (beyond, they are read back): 500 rows of
    the ``experiment`` runner (its per-scan series) took 31 MB here, twin rows less."""

    def __init__(self, folder: str | Path) -> None:
        self.folder = Path(folder)
        self._written: dict[Path, Any] = {}
        """The rows this store wrote (up to :attr:`KEEP`), kept so compaction need not read
        their files back (about 4 ms a file)."""

    def _files(self) -> list[Path]:
        if not self.folder.is_dir():
            return []
        return sorted(p for p in self.folder.iterdir()
                      if p.suffix == ".parquet" and not p.name.startswith("."))

    def write(self, row: dict[str, Any]) -> Path:
        """Store one finished task durably (atomic rename)."""
        pa, pq = need_pyarrow()
        self.folder.mkdir(parents=True, exist_ok=True)
        path = self.folder / f"{row['key']}.parquet"
        tmp = self.folder / f".{row['key']}.{uuid.uuid4().hex}.tmp"
        table = pa.Table.from_pylist([_normalise(row)])
        try:
            pq.write_table(table, tmp)
            os.replace(tmp, path)
        except BaseException:  # an interrupt mid-write leaves no half-written file behind
            tmp.unlink(missing_ok=True)
            raise
        if len(self._written) < self.KEEP:
            self._written[path] = table
        return path

    def done_keys(self) -> set[str]:
        """Keys of every stored row (reads only the ``key`` column)."""
        _, pq = need_pyarrow()
        keys: set[str] = set()
        for p in self._files():
            if p.name.startswith("part-"):
                keys.update(pq.read_table(p, columns=["key"]).column("key").to_pylist())
            else:
                keys.add(p.stem)
        return keys

    def read(self, keys: Iterable[str] | None = None):
        """All stored rows (or those with ``keys``) as one table, one row per key."""
        pa, pq = need_pyarrow()
        tables = [pq.read_table(p) for p in self._files()]
        if not tables:
            return pa.table({"key": pa.array([], pa.string())})
        table = pa.concat_tables(tables, promote_options="default")
        want = None if keys is None else set(keys)
        seen: set[str] = set()
        idx = []
        for i, k in enumerate(table.column("key").to_pylist()):
            if k not in seen and (want is None or k in want):
                seen.add(k)
                idx.append(i)
        return table.take(pa.array(idx, pa.int64()))

    def compact(self) -> Path | None:
        """Fold the one-row files into one ``part-*.parquet`` (then remove them), and remove
        temporary files a killed writer left (the campaign's lock makes this the only writer)."""
        pa, pq = need_pyarrow()
        if self.folder.is_dir():
            for p in self.folder.glob(".*.tmp"):
                p.unlink(missing_ok=True)
        loose = [p for p in self._files() if not p.name.startswith("part-")]
        if len(loose) < 2:
            return None
        written, self._written = self._written, {}
        table = pa.concat_tables([written[p] if p in written else pq.read_table(p)
                                  for p in loose], promote_options="default")
        path = self.folder / f"part-{uuid.uuid4().hex[:12]}.parquet"
        tmp = self.folder / f".{path.name}.tmp"
        pq.write_table(table, tmp)
        os.replace(tmp, path)
        for p in loose:
            p.unlink(missing_ok=True)
        return path

    def count_files(self) -> int:
        return len(self._files())
