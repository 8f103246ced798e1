"""``sensornet report CAMPAIGN_DIR``: a markdown report with PNG figures from a campaign's results.

Per-cell tables give every scalar metric's mean over the runs with a 95 % confidence interval
(Student t, ``mean ± t(0.975, n-1) s / sqrt(n)``), its lower end clipped at 0 for a metric no
run found negative (OSPA, a cardinality error, counts: :func:`bounds`). The overview leads with
the fused and local OSPA and GOSPA and, where the runner gives them, the track-level numbers
(OSPA(2), identity switches per 1,000 target-scans, label agreement). Figures, as the
campaign's ``[[figures]]`` ask (default: OSPA over time per cell):

* ``sweep``: a metric (``y``, default the fused OSPA) against one grid key (``x``), a line per
  value of ``lines`` (or per combination of the other grid keys), 95 % error bars; optional
  ``baseline`` (another metric drawn dashed beside each line, e.g. ``local_ospa``: each peer
  alone), ``paper = {value = ..., label = "..."}`` (the paper's number, a red line, where the
  paper gives one; ``note`` otherwise, e.g. that it gives none), ``xlabel`` and ``ylabel``;
* ``ospa-time``: every cell's mean fused OSPA per scan in one plot;
* a study's kind (e.g. ``seed000``, ``seed001``): per cell, what the study's ``report`` hook
  draws (:mod:`sim.studies`: seed 000's Figs. 4-8, seed 001's Table 1).
"""

from __future__ import annotations

import csv
import math
from pathlib import Path
from typing import Any

import numpy as np
from sensornet.sim import studies
from sensornet.sim.campaign import _fmt, read_manifest, results_table
from sensornet.sim.campaign.results import META_COLUMNS, need_pyarrow
from sensornet.sim.report.report_html import markdown_html
from sensornet.sim.report.report_plots import axis_label, band, plt_module, series
from sensornet.sim.scenario import ScenarioError, load_scenario

CAMPAIGN_FIGURES = ("sweep", "ospa-time")
"""Figure kinds drawn over the whole campaign; any other kind is a study's per-cell report."""


def interval(values: np.ndarray) -> tuple[float, float, int]:
    """``(mean, half-width of the 95 % interval, n)`` over finite values."""
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    n = len(v)
    if n == 0:
        return math.nan, math.nan, 0
    if n == 1:
        return float(v[0]), math.nan, 1
    # heavy dependency: scipy.stats (only intervals over two runs or more need it)
    from scipy.stats import t

    return float(v.mean()), float(t.ppf(0.975, n - 1) * v.std(ddof=1) / math.sqrt(n)), n


def bounds(mean: float, half: float, nonnegative: bool) -> tuple[float, float, bool]:
    """``(low, high, clipped)`` of the interval ``mean ± half``; for a quantity that cannot be
    negative (``nonnegative``: no run of the campaign gave a negative value) the low end is
    clipped at 0, ``clipped`` saying it was (the t interval's symmetry does not hold near 0;
    clipping keeps its coverage and drops only impossible values)."""
    low, high = mean - half, mean + half
    if nonnegative and low < 0:
        return 0.0, high, True
    return low, high, False


def _nonnegative(values) -> bool:
    v = np.array([np.nan if x is None else x for x in values], dtype=float)
    v = v[np.isfinite(v)]
    return bool(len(v)) and bool((v >= 0).all())


def _num(x: float) -> str:
    if not math.isfinite(x):
        return "–"
    return f"{x:.1f}" if abs(x) >= 100 else f"{x:.3g}"


def _columns(table) -> tuple[list[str], list[str]]:
    """(scalar metric columns, per-scan series columns)."""
    pa, _ = need_pyarrow()
    scalars, series = [], []
    for f in table.schema:
        if f.name in META_COLUMNS:
            continue
        (series if pa.types.is_list(f.type) else scalars).append(f.name)
    return scalars, series


def _by_cell(table, manifest) -> dict[int, dict[str, Any]]:
    cells = table.column("cell").to_pylist()
    cols = {c: table.column(c).to_pylist() for c in table.column_names}
    out: dict[int, dict[str, Any]] = {}
    for cell in manifest["cells"]:
        idx = [i for i, c in enumerate(cells) if c == cell["index"]]
        out[cell["index"]] = {c: [cols[c][i] for i in idx] for c in cols}
    return out


TRACK_COLUMNS = ("fused_ospa2", "local_ospa2", "fused_switches_per_1000", "label_agreement")
"""The runners' track-level columns (:mod:`sim.studies.network.study`), in the overview when
present: OSPA(2) over whole tracks (m), identity switches per 1,000 true target-scans, the share
of target-scans every peer gives the same id."""


def _headline(scalars: list[str]) -> list[str]:
    keys = [c for c in scalars if c.startswith("mean_ospa.")]
    if not keys:
        keys = [c for c in ("fused_ospa", "local_ospa", "fused_gospa", "local_gospa")
                if c in scalars]
    return (keys or scalars[:3]) + [c for c in TRACK_COLUMNS if c in scalars and c not in keys]


def _tick_labels(values: list) -> dict[str, str]:
    """Short labels: for tables (``{kind = "scans", low = 0, high = 2}``) only the entries
    that differ between the values (``high=2``)."""
    if values and all(isinstance(v, dict) for v in values):
        keys = [k for k in dict.fromkeys(k for v in values for k in v)
                if len({repr(v.get(k)) for v in values}) > 1]
        if keys:
            return {repr(v): ", ".join(f"{k}={_fmt(v.get(k))}" for k in keys) for v in values}
    return {repr(v): _fmt(v) for v in values}


def numeric_axis(values: list):
    """Where each x value sits on a numeric axis, or None (a categorical axis): numbers as
    themselves; tables (``{kind = "scans", low = 0, high = 2}``) that differ in one numeric
    entry by that entry (``high``: 0, 1, 2, 4 spaced as numbers, not evenly)."""
    def number(v) -> bool:
        return isinstance(v, int | float) and not isinstance(v, bool)

    if values and all(number(v) for v in values):
        return lambda v: v
    if values and all(isinstance(v, dict) for v in values):
        keys = [k for k in dict.fromkeys(k for v in values for k in v)
                if len({repr(v.get(k)) for v in values}) > 1]
        if len(keys) == 1 and all(number(v.get(keys[0])) for v in values):
            key = keys[0]

            def scale(v):
                return v[key]

            scale.key = key
            return scale
    return None


def sweep_figure(spec: dict, manifest: dict, cells: dict[int, dict], out: Path,
                 n: int) -> tuple[str, Path] | None:
    plt = plt_module()
    x = spec["x"]
    y = spec.get("y") or ("mean_ospa.fused" if any(
        "mean_ospa.fused" in d for d in cells.values()) else "fused_ospa")
    lines_key = spec.get("lines")
    base_key = spec.get("baseline")
    groups: dict[str, list[tuple[Any, float, float]]] = {}
    base: dict[str, list[tuple[Any, float, float]]] = {}
    for cell in manifest["cells"]:
        vals = cell["values"]
        if x not in vals or y not in cells[cell["index"]]:
            continue
        if lines_key:
            g = f"{lines_key}={_fmt(vals.get(lines_key))}"
        else:
            g = ", ".join(f"{k}={_fmt(v)}" for k, v in vals.items() if k != x) or y
        mean, half, _ = interval(np.array(cells[cell["index"]][y], dtype=float))
        groups.setdefault(g, []).append((vals[x], mean, half))
        if base_key and base_key in cells[cell["index"]]:
            bm, bh, _ = interval(np.array(cells[cell["index"]][base_key], dtype=float))
            base.setdefault(g, []).append((vals[x], bm, bh))
    if not groups:
        return None
    xs = list(dict.fromkeys(repr(v) for pts in groups.values() for v, _, _ in pts))
    values = [v for pts in groups.values() for v, _, _ in pts]
    labels = _tick_labels(values)
    scale = numeric_axis(values)
    numeric = scale is not None
    fig, ax = plt.subplots(figsize=(7, 4.5))

    def pos(v):
        return scale(v) if numeric else xs.index(repr(v))

    for g, pts in groups.items():
        px = [pos(v) for v, _, _ in pts]
        bar = ax.errorbar(px, [m for _, m, _ in pts], yerr=[0 if math.isnan(h) else h
                                                             for _, _, h in pts],
                          marker="o", capsize=3, label=g)
        if g in base:
            bx = [pos(v) for v, _, _ in base[g]]
            ax.plot(bx, [m for _, m, _ in base[g]], "--", color=bar[0].get_color(), alpha=0.7,
                    label=f"{base_key}, {g}")
    paper = spec.get("paper")
    if isinstance(paper, dict) and isinstance(paper.get("value"), int | float):
        ax.axhline(paper["value"], color="red", lw=1.5,
                   label=str(paper.get("label", "paper")))
    if not numeric:
        ax.set_xticks(range(len(xs)), [labels[v] for v in xs],
                      rotation=20 if max(len(labels[v]) for v in xs) > 12 else 0)
    ax.set_xlabel(spec.get("xlabel", x if getattr(scale, "key", None) is None
                           else f"{x}: {scale.key}"))
    ax.set_ylabel(spec.get("ylabel", axis_label(y)))
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title(f"{manifest['name']}: {y} against {x} (95 % intervals)", fontsize=10)
    fig.tight_layout()
    path = out / f"sweep-{n}.png"
    fig.savefig(path, dpi=100)
    plt.close(fig)
    caption = f"{y} against {x}, 95 % intervals"
    if base:
        caption += f"; dashed: {base_key}"
    if isinstance(paper, dict) and "value" in paper:
        caption += f"; red: {paper.get('label', 'paper')} ({_num(float(paper['value']))})"
    elif spec.get("note"):
        caption += f" ({spec['note']})"
    return caption, path


def _cutoff(manifest: dict, cell: dict) -> float | None:
    """The OSPA cut-off a cell was scored with: its own setting, else its scenario's."""
    value = cell.get("values", {}).get("metrics.ospa_cutoff")
    if isinstance(value, int | float):
        return float(value)
    try:
        source = cell.get("scenario") or manifest.get("scenario", "")
        return float(load_scenario(source).metrics.ospa_cutoff)
    except (ScenarioError, OSError, ValueError):  # no longer loads: clipped at 0 only
        return None


def ospa_time_figure(manifest: dict, cells: dict[int, dict], out: Path,
                     n: int) -> tuple[str, Path] | None:
    plt = plt_module()
    fig, ax = plt.subplots(figsize=(8, 4.5))
    drew = False
    for cell in manifest["cells"]:
        data = cells[cell["index"]]
        col = "ospa_k.fused" if "ospa_k.fused" in data else None
        if col is None or not data[col]:
            continue
        s = series(data[col])
        band(ax, np.arange(1, s.shape[1] + 1), s, cell["label"], lo=0.0,
             hi=_cutoff(manifest, cell))
        drew = True
    if not drew:
        plt.close(fig)
        return None
    ax.set_xlabel("scan")
    ax.set_ylabel("fused OSPA (m; band clipped to 0..cut-off)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    ax.set_title(f"{manifest['name']}: fused OSPA over time (95 % bands)", fontsize=10)
    fig.tight_layout()
    path = out / f"ospa-time-{n}.png"
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return "Fused OSPA over time per cell, 95 % bands", path


def overview(table, manifest: dict) -> list[str]:
    """A markdown table: a row per cell, its headline metrics with 95 % intervals."""
    scalars, _ = _columns(table)
    cells = _by_cell(table, manifest)
    head = _headline(scalars)
    lines = ["| cell | runs | " + " | ".join(f"{h} (95 % CI)" for h in head) + " |",
             "|---|---:|" + "---:|" * len(head)]
    for cell in manifest["cells"]:
        d = cells[cell["index"]]
        parts = []
        for h in head:  # mean ± the t half-width: the precision (the cell tables clip at 0)
            mean, half, _ = interval(np.array([np.nan if v is None else v
                                               for v in d.get(h, [])], dtype=float))
            parts.append(f"{_num(mean)} ± {_num(half)}")
        lines.append(f"| {cell['label']} | {len(d['key'])} | " + " | ".join(parts) + " |")
    return lines


def write_report(folder: str | Path, out: str | Path | None = None,
                 html: bool = False) -> list[Path]:
    """Write ``report.md`` and its PNGs (default: ``<folder>/report/``); return the files.
    ``html``: also ``report.html``, the same report in one self-contained file (tables, and
    every PNG embedded)."""
    folder = Path(folder)
    manifest = read_manifest(folder)
    out = Path(out) if out else folder / "report"
    out.mkdir(parents=True, exist_ok=True)
    table = results_table(folder, manifest)
    total = sum(len(c["keys"]) for c in manifest["cells"])
    lines = [f"# Campaign {manifest['name']}", "",
             f"Runner `{manifest['runner']}`, scenario `{manifest['scenario']}`, "
             f"{len(manifest['cells'])} cells × {manifest['runs']} runs "
             f"(runs {manifest['first_run']}–{manifest['first_run'] + manifest['runs'] - 1}); "
             f"{table.num_rows}/{total} runs computed; code version "
             f"`{manifest['code_version']}`.", "",
             "Means over the runs with 95 % confidence intervals "
             "(Student t: mean ± t(0.975, n−1)·s/√n); in the cells' tables, for a metric "
             "no run found negative (OSPA, cardinality error, counts) the interval's low end "
             "is clipped at 0, and says so.", ""]
    written: list[Path] = []
    if table.num_rows == 0:
        lines.append("No results yet.")
        path = out / "report.md"
        path.write_text("\n".join(lines) + "\n")
        return [path, *_html(path, manifest, html)]
    scalars, _ = _columns(table)
    cells = _by_cell(table, manifest)
    nonneg = {s: _nonnegative(table.column(s).to_pylist()) for s in scalars}
    lines += ["## Overview", "", *overview(table, manifest), ""]
    figures = manifest.get("figures") or [{"kind": "ospa-time"}]
    campaign_figs: list[tuple[str, Path]] = []
    cell_reports = [studies.for_report(kind) for kind in
                    dict.fromkeys(f["kind"] for f in figures) if kind not in CAMPAIGN_FIGURES]
    for n, spec in enumerate(figures):
        got = None
        if spec["kind"] == "sweep":
            got = sweep_figure(spec, manifest, cells, out, n)
        elif spec["kind"] == "ospa-time":
            got = ospa_time_figure(manifest, cells, out, n)
        if got:
            campaign_figs.append(got)
    if campaign_figs:
        lines += ["## Figures", ""]
        for caption, path in campaign_figs:
            lines += [f"![{caption}]({path.name})", "", f"*{caption}*", ""]
            written.append(path)
    lines += ["## Cells", ""]
    for cell in manifest["cells"]:
        d = cells[cell["index"]]
        lines += [f"### Cell {cell['index']}: {cell['label']}", "",
                  f"{len(d['key'])} runs; overrides: "
                  + (", ".join(f"`{k}={v}`" for k, v in cell["set"].items()) or "none"), "",
                  "| metric | mean | 95 % CI | runs |", "|---|---:|---:|---:|"]
        for s in scalars:
            mean, half, k = interval(np.array([np.nan if v is None else v for v in d[s]],
                                              dtype=float))
            if k == 0:
                continue
            low, high, clipped = bounds(mean, half, nonneg[s])
            ci = (f"[{_num(low)}, {_num(high)}]" + (" (clipped at 0)" if clipped else "")
                  if math.isfinite(half) else "–")
            lines.append(f"| {s} | {_num(mean)} | {ci} | {k} |")
        lines.append("")
        for study in cell_reports:
            more, files = study.report(cell, d, out)
            lines += more
            written += files
    csv_path = out / "per_run.csv"
    with csv_path.open("w", newline="") as fh:
        w = csv.writer(fh)
        cols = ["cell", "cell_label", "run", *scalars]
        w.writerow(cols)
        data = [table.column(c).to_pylist() for c in cols]
        w.writerows(zip(*data, strict=True))
    lines += ["Every run's scalar metrics: [per_run.csv](per_run.csv).", ""]
    path = out / "report.md"
    path.write_text("\n".join(lines) + "\n")
    return [path, *_html(path, manifest, html), csv_path, *written]


def _html(md_path: Path, manifest: dict, wanted: bool) -> list[Path]:
    if not wanted:
        return []
    page = markdown_html(md_path.read_text(), md_path.parent, f"Campaign {manifest['name']}")
    path = md_path.with_suffix(".html")
    path.write_text(page, encoding="utf-8")
    return [path]
