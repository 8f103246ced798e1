"""A campaign folder read back: its manifest, its rows in (cell, run) order, its status."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from sensornet.sim.campaign.campaign_model import Campaign, CampaignError, Cell
from sensornet.sim.campaign.campaign_run import lock_alive, read_lock
from sensornet.sim.campaign.results import ResultStore, is_timing, need_pyarrow

# --------------------------------------------------------------------------------------------
# Status and progress
# --------------------------------------------------------------------------------------------


@dataclass
class Status:
    done: int
    total: int
    per_cell: list[tuple[Cell, int]]
    stale: int
    """Stored rows that belong to no task of this campaign (other code, other cells)."""
    running: dict[str, Any] | None = None
    """The lock of the process running the campaign now (pid, host), if one does."""
    died: dict[str, Any] | None = None
    """The lock a process left when it died without finishing (``kill -9``, a crash)."""

    @property
    def cells_done(self) -> int:
        return sum(1 for c, n in self.per_cell if n == len(c.keys))


def status(c: Campaign, folder: Path) -> Status:
    stored = ResultStore(folder / "results").done_keys()
    per = [(cell, sum(1 for k in cell.keys if k in stored)) for cell in c.cells]
    wanted = {k for cell in c.cells for k in cell.keys}
    lock = read_lock(folder)
    alive = lock is not None and lock_alive(lock)
    return Status(sum(n for _, n in per), len(wanted), per, len(stored - wanted),
                  running=lock if alive else None,
                  died=lock if lock is not None and not alive else None)


def recorded_runs(folder: Path) -> int | None:
    """Runs per cell of the plan the folder records (its ``manifest.json``), if any."""
    try:
        runs = json.loads((Path(folder) / "manifest.json").read_text()).get("runs")
    except (OSError, ValueError):
        return None
    return runs if isinstance(runs, int) and runs >= 1 else None


def format_status(c: Campaign, folder: Path, st: Status) -> str:
    lines = [f"campaign {c.name}: runner {c.runner}, {len(c.cells)} cells x {c.runs} runs, "
             f"code {c.code_version}",
             f"{st.done}/{st.total} runs done, {st.cells_done}/{len(c.cells)} cells complete"
             f" ({folder})"]
    left = st.total - st.done
    if st.running is not None:
        lines.append(f"running: pid {st.running.get('pid')} on {st.running.get('host')}")
    elif left and st.died is not None:
        lines.append(f"stopped: the process that ran it (pid {st.died.get('pid')} on "
                     f"{st.died.get('host')}) is gone, {left} runs to go; run the campaign "
                     "again to finish")
    elif left and st.done:
        lines.append(f"incomplete: no process is running it, {left} runs to go; run the "
                     "campaign again to finish")
    elif left:
        lines.append("not started")
    width = max(len(cell.label) for cell in c.cells)
    partial = "running" if st.running is not None else "incomplete"
    for cell, n in st.per_cell:
        mark = "done" if n == len(cell.keys) else (partial if n else "")
        lines.append(f"  cell {cell.index:>3}  {cell.label:<{width}}  {n:>5}/{len(cell.keys)}"
                     f"  {mark}".rstrip())
    if st.stale:
        lines.append(f"{st.stale} stored runs belong to other code versions or cells "
                     "(kept, not used)")
    return "\n".join(lines)


# --------------------------------------------------------------------------------------------
# Reading results
# --------------------------------------------------------------------------------------------


def read_manifest(folder: Path) -> dict[str, Any]:
    path = Path(folder) / "manifest.json"
    if not Path(folder).exists():
        raise CampaignError(f"{folder}: no such folder (a campaign folder is what 'sensornet "
                            "campaign FILE' writes, runs/campaign-<name> by default)")
    if not Path(folder).is_dir():
        raise CampaignError(f"{folder}: not a folder (give the campaign's folder, e.g. "
                            "runs/campaign-<name>)")
    if not path.is_file():
        raise CampaignError(f"{folder}: no manifest.json (not a campaign folder; run "
                            "'sensornet campaign FILE' first)")
    return json.loads(path.read_text())


def results_table(folder: Path, manifest: dict[str, Any] | None = None,
                  complete_only: bool = False):
    """The campaign's rows in (cell, run) order, from the manifest's keys (rows not yet
    computed are absent). Columns ``cell``/``cell_label`` are the manifest's."""
    pa, _ = need_pyarrow()
    manifest = manifest or read_manifest(folder)
    order = [(cell["index"], cell["label"], k) for cell in manifest["cells"]
             for k in cell["keys"]]
    table = ResultStore(Path(folder) / "results").read({k for _, _, k in order})
    where = {k: i for i, k in enumerate(table.column("key").to_pylist())}
    picked = [(ci, lab, where[k]) for ci, lab, k in order if k in where]
    if complete_only and len(picked) < len(order):
        raise CampaignError(f"{folder}: {len(order) - len(picked)} of {len(order)} runs "
                            "not computed yet")
    table = table.take(pa.array([i for _, _, i in picked], pa.int64()))
    if table.num_rows:
        for name, values, typ in (("cell", [ci for ci, _, _ in picked], pa.int64()),
                                  ("cell_label", [lab for _, lab, _ in picked], pa.string())):
            table = table.set_column(table.schema.get_field_index(name), name,
                                     pa.array(values, typ))
    return table


def canonical_rows(table) -> list[tuple]:
    """The table's computed values as exact text (``repr`` of every float), without timing
    columns, keys and code versions: equal lists mean bit-identical results."""
    cols = sorted(c for c in table.column_names
                  if not is_timing(c) and c not in ("key", "code_version"))
    data = {c: table.column(c).to_pylist() for c in cols}
    return [tuple((c, repr(data[c][i])) for c in cols) for i in range(table.num_rows)]
