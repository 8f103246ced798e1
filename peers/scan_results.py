"""Per-scan results of one peer: what it estimated, what was true, and what each estimate scored.

One row per (scan, estimate) that the peer owed, ``estimate`` being ``"local"`` or ``"fused"``.
A row whose output never came (``scored`` false) carries no tracks and is scored as a miss:
OSPA at the cut-off and GOSPA with every true target missed, as the summary's means count it.
The schema (:data:`COLUMNS`) is documented in docs/results.md; :func:`write_parquet` writes it.
"""

from __future__ import annotations

import json
from pathlib import Path

import msgpack
import numpy as np
from sensornet.tracking.metrics import gospa_parts, ospa_gospa_parts

COLUMNS_V1 = ("peer", "scan", "estimate", "scored", "ospa", "gospa", "gospa_localisation",
              "gospa_missed", "gospa_false", "n_estimated", "n_true", "latency_ms", "tracks",
              "truth")
"""The columns of tables written before track identities (still read: the new ones empty)."""
ID_COLUMNS = ("track_ids", "track_status", "truth_ids")
"""Track identities: ``[origin, birth_scan, index]`` per row of ``tracks`` (empty when the
peer's kind has no labels), 0/1 tentative/confirmed per row, the true target ids per row of
``truth``."""
COLUMNS = COLUMNS_V1 + ID_COLUMNS
"""The table's columns, in order (docs/results.md says what each holds)."""
LIST_COLUMNS = ("tracks", "truth", *ID_COLUMNS)
"""Columns whose rows are lists of varying length (readers keep them as lists)."""

UNITS = {"peer": "name", "scan": "scan index", "estimate": "local or fused",
         "scored": "bool: the output came", "ospa": "m (lower is better)",
         "gospa": "m (lower is better)", "gospa_localisation": "m^p, p = order",
         "gospa_missed": "targets", "gospa_false": "tracks", "n_estimated": "tracks",
         "n_true": "targets", "latency_ms": "ms (scan to published tracks)",
         "tracks": "state rows (m, m/s)", "truth": "state rows (m, m/s)",
         "track_ids": "[origin, birth_scan, index]", "track_status": "0 tentative, 1 confirmed",
         "truth_ids": "target id"}
"""Each column's unit or meaning, written in the Parquet file's metadata (docs/results.md)."""
GOSPA_ALPHA = 2.0
"""The GOSPA alpha of every row (tracking.metrics.gospa_parts: alpha = 2)."""

Ids = tuple[np.ndarray | None, np.ndarray | None, np.ndarray | None] | None
"""``(track ids (n, 3), status (n,), truth ids (m,))`` of one row, any of them None."""

MAX_ROWS = 500_000
"""Rows kept per peer (a 10 scans/s run of about 7 hours); later rows are counted, not kept."""


class ScanResults:
    """Collects a peer's per-scan rows; ``position_index`` picks the position from a state."""

    def __init__(self, cutoff: float, order: float, position_index: tuple[int, int]) -> None:
        self.c, self.p = float(cutoff), float(order)
        self.pos = list(position_index)
        self._columns = np.asarray(self.pos, dtype=np.intp)  # xy's take: no list converted
        self.rows: list[tuple] = []
        self.dropped = 0
        self._gospa_sum: dict[str, float] = {}
        self._gospa_n: dict[str, int] = {}

    def scored(self, k: int, which: str, states: np.ndarray, truth: np.ndarray,
               ids: Ids = None) -> float:
        """Add an estimate that arrived; its OSPA (the value the summary's mean takes).
        ``ids``: ``(track ids (n, 3), status (n,), truth ids (m,))``, any of them None."""
        est, true = self.xy(states), self.xy(truth)
        value, parts = ospa_gospa_parts(est, true, self.c, self.p)
        self._add(k, which, True, value, est, true, states, truth, parts, ids)
        return value

    def scored_as(self, k: int, which: str, states: np.ndarray, truth: np.ndarray,
                  est: np.ndarray, true: np.ndarray, value: float,
                  parts: tuple[float, float, int, int], ids: Ids = None) -> None:
        """:meth:`scored` with the score computed elsewhere (a host's batch, from the same
        positions ``est = xy(states)``, ``true = xy(truth)``)."""
        self._add(k, which, True, value, est, true, states, truth, parts, ids)

    def missed(self, k: int, which: str, truth: np.ndarray | None,
               truth_ids: np.ndarray | None = None) -> None:
        """Add an output that never came: OSPA at the cut-off, every true target missed."""
        truth = np.zeros((0, 0)) if truth is None else truth
        self._add(k, which, False, self.c, np.zeros((0, 2)), self.xy(truth), None, truth,
                  ids=(None, None, truth_ids))

    def xy(self, states: np.ndarray) -> np.ndarray:
        """``(n, 2)`` positions of state rows ``(n, d)`` (empty-safe)."""
        return states.take(self._columns, axis=1) if len(states) else np.zeros((0, 2))

    def _add(self, k: int, which: str, scored: bool, value: float, est: np.ndarray,
             true: np.ndarray, states: np.ndarray | None, truth: np.ndarray,
             parts: tuple[float, float, int, int] | None = None, ids: Ids = None) -> None:
        g, loc, missed, false = parts or gospa_parts(est, true, self.c, self.p)
        # the summary's GOSPA mean counts every estimate, kept as a row or not
        self._gospa_sum[which] = self._gospa_sum.get(which, 0.0) + g
        self._gospa_n[which] = self._gospa_n.get(which, 0) + 1
        if len(self.rows) >= MAX_ROWS:
            self.dropped += 1
            return
        tracks = [] if states is None else np.asarray(states, float).tolist()
        tid, status, truth_ids = ids or (None, None, None)
        self.rows.append((int(k), which, scored, float(value), g, loc, missed, false,
                          len(est), len(true), tracks, np.asarray(truth, float).tolist(),
                          [] if tid is None else np.asarray(tid, np.int64).tolist(),
                          [] if status is None else np.asarray(status, np.int64).tolist(),
                          [] if truth_ids is None else np.asarray(truth_ids, np.int64).tolist()))

    def mean(self, which: str) -> float:
        """Mean GOSPA of this peer's ``which`` estimates, misses included (as the summary's
        OSPA means count them), over every estimate, also those past :data:`MAX_ROWS` that
        the table no longer keeps; NaN with none."""
        n = self._gospa_n.get(which, 0)
        return self._gospa_sum[which] / n if n else float("nan")

    def meta(self) -> dict:
        """What a reader needs besides the rows: where the position sits in a state row, and
        the OSPA/GOSPA cut-off and order the rows were scored with."""
        return {"position_index": list(self.pos), "cutoff": self.c, "order": self.p}

    def table(self, peer: str, latency_ms: dict[int, float] | None = None) -> dict[str, list]:
        """The rows as columns (:data:`COLUMNS`), sorted by scan then estimate; a fused row's
        latency from ``latency_ms`` (scan -> published tracks), NaN where none was measured."""
        lat = latency_ms or {}
        rows = sorted(self.rows, key=lambda r: (r[0], r[1]))
        cols: dict[str, list] = {name: [] for name in COLUMNS}
        for r in rows:
            cols["peer"].append(peer)
            for name, v in zip(COLUMNS[1:11], r[:10], strict=True):
                cols[name].append(v)
            cols["latency_ms"].append(float(lat.get(r[0], np.nan)) if r[1] == "fused"
                                      else np.nan)
            cols["tracks"].append(r[10])
            cols["truth"].append(r[11])
            for name, v in zip(ID_COLUMNS, r[12:15], strict=True):
                cols[name].append(v)
        return cols


def write_part(results: ScanResults, peer: str, path: Path,
               latency_ms: dict[int, float] | None = None) -> Path:
    """Write one peer's rows and meta as msgpack (cheap at a peer's exit; :func:`merge_parts`
    turns a run's parts into one Parquet table), atomically."""
    path = Path(path)
    tmp = path.with_suffix(".tmp")
    part = {"columns": results.table(peer, latency_ms), "meta": results.meta()}
    tmp.write_bytes(msgpack.packb(part, use_bin_type=True))
    tmp.replace(path)
    return path


def read_part(path: Path) -> tuple[dict[str, list], dict]:
    """``(columns, meta)`` of a part written by :func:`write_part`; ``ValueError`` if it is
    not one."""
    part = msgpack.unpackb(Path(path).read_bytes(), raw=False, strict_map_key=False)
    if (not isinstance(part, dict) or not isinstance(part.get("columns"), dict)
            or tuple(part["columns"]) not in (COLUMNS, COLUMNS_V1)
            or not isinstance(part.get("meta"), dict)):
        raise ValueError("not a per-scan results part")
    return with_id_columns(part["columns"]), part["meta"]


def with_id_columns(cols: dict[str, list]) -> dict[str, list]:
    """A table of :data:`COLUMNS_V1` (written before track identities) with the identity
    columns added, empty lists in every row; a current table as it is."""
    if tuple(cols) == COLUMNS:
        return cols
    n = len(cols["peer"])
    return {**cols, **{name: [[] for _ in range(n)] for name in ID_COLUMNS}}


def merge_parts(parts: list[Path], path: Path) -> Path | None:
    """Concatenate peers' parts (sorted by peer, then scan) into one Parquet table at
    ``path``; None if there are no parts. A part that cannot be read is named and skipped."""
    tables, meta = [], None
    for part in sorted(parts):
        try:
            cols, m = read_part(part)
        except (ValueError, OSError, msgpack.UnpackException) as exc:
            print(f"per-scan results: skipped {part.name}: {exc}")
            continue
        tables.append(cols)
        meta = meta or m
    if not tables:
        return None
    merged = {name: [v for t in tables for v in t[name]] for name in COLUMNS}
    return write_parquet(merged, meta, path)


def write_parquet(columns: dict[str, list], meta: dict, path: Path) -> Path:
    """Write a results table (:data:`COLUMNS`; ``meta`` with GOSPA's alpha and each column's
    unit, :data:`UNITS`, as JSON under the file's ``sensornet`` metadata key) atomically
    (temporary name, then rename)."""
    import pyarrow as pa  # heavy optional dependency: pyarrow (only writing results)
    import pyarrow.parquet as pq

    path = Path(path)
    tmp = path.with_suffix(".tmp")
    info = {**meta, "gospa_alpha": GOSPA_ALPHA, "units": UNITS}
    table = pa.table(columns, schema=schema()).replace_schema_metadata(
        {"sensornet": json.dumps(info)})
    pq.write_table(table, tmp)
    tmp.replace(path)
    return path


def read_table(path: Path) -> tuple[dict[str, list], dict]:
    """``(columns, meta)`` of a ``results.parquet``; ``ValueError`` if it is not one."""
    import pyarrow.parquet as pq  # heavy optional dependency: pyarrow

    table = pq.read_table(path)
    raw = (table.schema.metadata or {}).get(b"sensornet")
    if raw is None or tuple(table.column_names) not in (COLUMNS, COLUMNS_V1):
        raise ValueError(f"{path}: not a sensornet per-scan results table")
    return with_id_columns(table.to_pydict()), _meta(raw)


def _meta(raw: bytes) -> dict:
    """A table's metadata: JSON (since the metric parameters and units were added), or the
    hex of msgpack that earlier tables hold."""
    text = raw.decode()
    if text.startswith("{"):
        return json.loads(text)
    return msgpack.unpackb(bytes.fromhex(text))


def schema():
    """The pyarrow schema of a results table."""
    import pyarrow as pa  # heavy optional dependency: pyarrow

    rows = pa.list_(pa.list_(pa.float64()))
    return pa.schema([("peer", pa.string()), ("scan", pa.int64()), ("estimate", pa.string()),
                      ("scored", pa.bool_()), ("ospa", pa.float64()), ("gospa", pa.float64()),
                      ("gospa_localisation", pa.float64()), ("gospa_missed", pa.int64()),
                      ("gospa_false", pa.int64()), ("n_estimated", pa.int64()),
                      ("n_true", pa.int64()), ("latency_ms", pa.float64()), ("tracks", rows),
                      ("truth", rows), ("track_ids", pa.list_(pa.list_(pa.int64()))),
                      ("track_status", pa.list_(pa.int8())),
                      ("truth_ids", pa.list_(pa.int64()))])
