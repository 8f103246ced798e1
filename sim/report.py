"""``sensornet report CAMPAIGN_DIR``: a markdown report with PNG figures from a campaign's results.

Per-cell tables give every scalar metric's mean over the runs with a 95 % confidence interval
(Student t, ``mean ± t(0.975, n-1) s / sqrt(n)``). Figures, as the campaign's ``[[figures]]``
ask (default: OSPA over time per cell):

* ``seed000``: per cell, seed 000's Figs. 4-8: the mean number of estimates against the truth
  (cardinality), its RMSE over the runs, OSPA over time for each sensor alone, the fused
  estimate and the centralized filter (95 % band), and the component counts of the fusing
  sensor before and after level-2 pruning and after fusion;
* ``sweep``: a metric (``y``, default the fused OSPA) against one grid key (``x``), a line per
  value of ``lines`` (or per combination of the other grid keys), 95 % error bars; optional
  ``baseline`` (another metric drawn dashed beside each line, e.g. ``local_ospa``: each peer
  alone), ``paper = {value = ..., label = "..."}`` (the paper's number, a red line, where the
  paper gives one; ``note`` otherwise, e.g. that it gives none), ``xlabel`` and ``ylabel``;
* ``ospa-time``: every cell's mean fused OSPA per scan in one plot;
* ``seed001``: per cell of a ``seed001`` campaign, Table 1 (x-axis RMSE over the runs not lost,
  lost tracks) beside the paper's numbers, and a bar chart of the position RMSE.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from sim.campaign import _fmt, read_manifest, results_table
from sim.results import META_COLUMNS


def interval(values: np.ndarray) -> tuple[float, float, int]:
    """``(mean, half-width of the 95 % interval, n)`` over finite values."""
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    n = len(v)
    if n == 0:
        return math.nan, math.nan, 0
    if n == 1:
        return float(v[0]), math.nan, 1
    from scipy.stats import t

    return float(v.mean()), float(t.ppf(0.975, n - 1) * v.std(ddof=1) / math.sqrt(n)), n


def _num(x: float) -> str:
    if not math.isfinite(x):
        return "–"
    return f"{x:.1f}" if abs(x) >= 100 else f"{x:.3g}"


def _columns(table) -> tuple[list[str], list[str]]:
    """(scalar metric columns, per-scan series columns)."""
    import pyarrow as pa

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


def _series(rows: list, K: int | None = None) -> np.ndarray:
    """Runs x scans from a list of per-run lists (None rows dropped)."""
    rows = [r for r in rows if r is not None]
    if not rows:
        return np.zeros((0, K or 0))
    return np.array(rows, dtype=float)


def _headline(scalars: list[str]) -> list[str]:
    keys = [c for c in scalars if c.startswith("mean_ospa.")]
    if not keys:
        keys = [c for c in ("fused_ospa", "local_ospa") if c in scalars]
    return keys or scalars[:3]


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _methods(data: dict[str, Any], prefix: str) -> list[str]:
    return [c[len(prefix):] for c in data if c.startswith(prefix)]


def _band(ax, k, s: np.ndarray, label: str, **kw) -> None:
    mean = np.nanmean(s, axis=0)
    line, = ax.plot(k, mean, label=label, **kw)
    if len(s) > 1:
        from scipy.stats import t

        half = t.ppf(0.975, len(s) - 1) * np.nanstd(s, axis=0, ddof=1) / math.sqrt(len(s))
        ax.fill_between(k, mean - half, mean + half, color=line.get_color(), alpha=0.2, lw=0)


def seed000_figures(cell: dict, data: dict[str, Any], out: Path) -> list[tuple[str, Path]]:
    """Figs. 4-8 of seed 000 for one cell of an ``experiment`` campaign."""
    plt = _plt()
    if "n_true_k" not in data or not data["n_true_k"]:
        return []
    n_true = _series(data["n_true_k"])
    runs, K = n_true.shape
    k = np.arange(1, K + 1)
    methods = _methods(data, "ospa_k.")
    tag = f"cell{cell['index']}"
    title = f"{cell['label']} ({runs} runs)"
    figs: list[tuple[str, Path]] = []

    def save(fig, ax, name: str, ylabel: str, caption: str) -> None:
        ax.set_xlabel("scan")
        ax.set_ylabel(ylabel)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
        ax.set_title(title, fontsize=10)
        fig.tight_layout()
        path = out / f"{tag}-{name}.png"
        fig.savefig(path, dpi=100)
        plt.close(fig)
        figs.append((caption, path))

    fig, ax = plt.subplots(figsize=(8, 4))
    for m in methods:
        ax.plot(k, _series(data[f"n_est_k.{m}"]).mean(axis=0), label=m)
    ax.plot(k, n_true.mean(axis=0), "k--", label="truth")
    save(fig, ax, "cardinality", "mean number of targets",
         "Cardinality: mean number of estimated targets against the truth (Fig. 4)")
    fig, ax = plt.subplots(figsize=(8, 4))
    for m in methods:
        err = _series(data[f"n_est_k.{m}"]) - n_true
        ax.plot(k, np.sqrt((err ** 2).mean(axis=0)), label=m)
    save(fig, ax, "cardinality-rmse", "cardinality RMSE (targets)",
         "Cardinality RMSE over the runs per scan (Fig. 5)")
    fig, ax = plt.subplots(figsize=(8, 4))
    for m in methods:
        _band(ax, k, _series(data[f"ospa_k.{m}"]), m,
              lw=2 if m in ("fused", "centralized") else 1)
    save(fig, ax, "ospa", "OSPA (m)",
         "OSPA over time: each sensor alone, GCI-fused, centralized; 95 % bands (Figs. 6-7)")
    comp = [(c, f"comp_k.{c}") for c in ("local", "level2", "fused") if f"comp_k.{c}" in data]
    if comp:
        fig, ax = plt.subplots(figsize=(8, 4))
        names = {"local": "local filter output (after level-1 pruning)",
                 "level2": "after level-2 pruning (published)", "fused": "after fusion"}
        for c, col in comp:
            ax.plot(k, _series(data[col]).mean(axis=0), label=names[c])
        save(fig, ax, "components", "mean number of components",
             "Components at the fusing sensor before and after each pruning level (Fig. 8)")
    return figs


def seed001_table(cell: dict, data: dict[str, Any], out: Path) -> tuple[list[str], Path | None]:
    """Seed 001's Table 1 for one cell of a ``seed001`` campaign: x-axis RMSE over the runs
    whose track was not lost, beside the paper's numbers; and a bar chart of the x position
    RMSE with the paper's values marked."""
    from sim.seed001 import PAPER_TABLE1

    methods = _methods(data, "msx_pos.")
    if not methods:
        return [], None
    lines = ["| filter | estimate | x pos RMSE (m) | x vel RMSE (m/s) | x acc RMSE (m/s²) | "
             "lost tracks |", "|---|---|---:|---:|---:|---:|"]
    pos: dict[str, float] = {}
    for m in methods:
        lost = np.array(data[f"lost.{m}"], dtype=float) > 0.5
        kept = ~lost
        rmse = [math.sqrt(float(np.mean(np.array(data[f"msx_{q}.{m}"], dtype=float)[kept])))
                if kept.any() else math.nan for q in ("pos", "vel", "acc")]
        filt, rule = m.split(".", 1)
        pos[m] = rmse[0]
        lines.append(f"| {filt} | {rule.replace('_', ' ')} | {rmse[0]:.3f} | {rmse[1]:.4f} | "
                     f"{rmse[2]:.4f} | {int(lost.sum())}/{len(lost)} |")
    for (filt, rule), (p, v, a) in PAPER_TABLE1.items():
        lines.append(f"| {filt} (paper, 300 runs) | {rule} | {p} | {v} | {a} | – |")
    plt = _plt()
    fig, ax = plt.subplots(figsize=(8, 4))
    x = np.arange(len(methods))
    ax.bar(x, [0.0 if math.isnan(pos[m]) else pos[m] for m in methods], color="tab:blue",
           label="measured")
    for i, m in enumerate(methods):
        if math.isnan(pos[m]):
            ax.text(i, 0.5, "every track lost", ha="center", va="bottom", fontsize=8)
    labelled = False
    for i, m in enumerate(methods):
        filt, rule = m.split(".", 1)
        paper = PAPER_TABLE1.get((filt, "fusion")) if "fusion" in rule.lower() else None
        if paper is not None:
            ax.plot([i - 0.4, i + 0.4], [paper[0]] * 2, "r-", lw=2,
                    label=None if labelled else "paper (its fusion row)")
            labelled = True
    ax.set_xticks(x, [m.replace(".", "\n").replace("_", " ") for m in methods], fontsize=7)
    ax.set_ylabel("x position RMSE (m)")
    ax.set_ylim(bottom=0)
    ax.grid(alpha=0.3, axis="y")
    ax.legend(fontsize=8)
    ax.set_title(f"seed 001 Table 1, {cell['label']} ({len(data['key'])} runs)", fontsize=10)
    fig.tight_layout()
    path = out / f"cell{cell['index']}-table1.png"
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return lines, path


def _tick_labels(values: list) -> dict[str, str]:
    """Short labels: for tables (``{kind = "scans", low = 0, high = 2}``) only the entries
    that differ between the values (``high=2``)."""
    if values and all(isinstance(v, dict) for v in values):
        keys = [k for k in dict.fromkeys(k for v in values for k in v)
                if len({repr(v.get(k)) for v in values}) > 1]
        if keys:
            return {repr(v): ", ".join(f"{k}={_fmt(v.get(k))}" for k in keys) for v in values}
    return {repr(v): _fmt(v) for v in values}


def sweep_figure(spec: dict, manifest: dict, cells: dict[int, dict], out: Path,
                 n: int) -> tuple[str, Path] | None:
    plt = _plt()
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
    labels = _tick_labels([v for pts in groups.values() for v, _, _ in pts])
    numeric = all(isinstance(v, int | float) and not isinstance(v, bool)
                  for pts in groups.values() for v, _, _ in pts)
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for g, pts in groups.items():
        px = [v if numeric else xs.index(repr(v)) for v, _, _ in pts]
        bar = ax.errorbar(px, [m for _, m, _ in pts], yerr=[0 if math.isnan(h) else h
                                                             for _, _, h in pts],
                          marker="o", capsize=3, label=g)
        if g in base:
            bx = [v if numeric else xs.index(repr(v)) for v, _, _ in base[g]]
            ax.plot(bx, [m for _, m, _ in base[g]], "--", color=bar[0].get_color(), alpha=0.7,
                    label=f"{base_key}, {g}")
    paper = spec.get("paper")
    if isinstance(paper, dict) and isinstance(paper.get("value"), int | float):
        ax.axhline(paper["value"], color="red", lw=1.5,
                   label=str(paper.get("label", "paper")))
    if not numeric:
        ax.set_xticks(range(len(xs)), [labels[v] for v in xs],
                      rotation=20 if max(len(labels[v]) for v in xs) > 12 else 0)
    ax.set_xlabel(spec.get("xlabel", x))
    ax.set_ylabel(spec.get("ylabel", y))
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


def ospa_time_figure(manifest: dict, cells: dict[int, dict], out: Path,
                     n: int) -> tuple[str, Path] | None:
    plt = _plt()
    fig, ax = plt.subplots(figsize=(8, 4.5))
    drew = False
    for cell in manifest["cells"]:
        data = cells[cell["index"]]
        col = "ospa_k.fused" if "ospa_k.fused" in data else None
        if col is None or not data[col]:
            continue
        s = _series(data[col])
        _band(ax, np.arange(1, s.shape[1] + 1), s, cell["label"])
        drew = True
    if not drew:
        plt.close(fig)
        return None
    ax.set_xlabel("scan")
    ax.set_ylabel("fused OSPA (m)")
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
        for h in head:
            mean, half, _ = interval(np.array(d.get(h, []), dtype=float))
            parts.append(f"{_num(mean)} ± {_num(half)}")
        lines.append(f"| {cell['label']} | {len(d['key'])} | " + " | ".join(parts) + " |")
    return lines


_CSS = """body{font-family:system-ui,sans-serif;max-width:1000px;margin:2em auto;padding:0 1em;
color:#222}table{border-collapse:collapse;margin:1em 0;font-size:.9em}th,td{border:1px solid
#ccc;padding:.25em .6em}th{background:#f3f3f3}td.r,th.r{text-align:right}figure{margin:1em 0}
img{max-width:100%}figcaption{font-style:italic;color:#555}code{background:#f3f3f3;padding:0
.2em}"""


def _inline(text: str, folder: Path) -> str:
    """The report's inline markdown (code, links, italics) as HTML; files linked from the
    report are embedded as ``data:`` URIs."""
    import base64
    import html
    import re

    parts = re.split(r"(`[^`]*`)", text)
    out = []
    for part in parts:
        if part.startswith("`") and part.endswith("`") and len(part) > 1:
            out.append(f"<code>{html.escape(part[1:-1])}</code>")
            continue
        part = html.escape(part, quote=False)

        def link(m: re.Match) -> str:
            target = folder / html.unescape(m.group(2))
            href = html.unescape(m.group(2))
            if target.is_file():
                kind = "text/csv" if target.suffix == ".csv" else "application/octet-stream"
                href = f"data:{kind};base64," + base64.b64encode(target.read_bytes()).decode()
                return (f'<a href="{href}" download="{html.escape(target.name)}">'
                        f"{m.group(1)}</a>")
            return f'<a href="{html.escape(href)}">{m.group(1)}</a>'

        part = re.sub(r"\[([^\]]+)\]\(([^)\s]+)\)", link, part)
        part = re.sub(r"\*\*([^*]+)\*\*", r"<strong>\1</strong>", part)
        part = re.sub(r"(?<![\w*])\*([^*]+)\*(?![\w*])", r"<em>\1</em>", part)
        out.append(part)
    return "".join(out)


def _table_html(rows: list[str], folder: Path) -> list[str]:
    def cells(line: str) -> list[str]:
        return [c.strip() for c in line.strip().strip("|").split("|")]

    head, align, body = cells(rows[0]), cells(rows[1]), [cells(r) for r in rows[2:]]
    right = [a.endswith(":") for a in align]

    def tr(tag: str, cs: list[str]) -> str:
        return "<tr>" + "".join(
            f'<{tag}{" class=r" if i < len(right) and right[i] else ""}>'
            f"{_inline(c, folder)}</{tag}>" for i, c in enumerate(cs)) + "</tr>"

    return ["<table>", "<thead>", tr("th", head), "</thead>", "<tbody>",
            *(tr("td", r) for r in body), "</tbody>", "</table>"]


def markdown_html(md: str, folder: Path, title: str) -> str:
    """The report's markdown (headings, paragraphs, pipe tables, images with a caption line)
    as one self-contained HTML page: every image embedded as a base64 ``data:`` URI, the
    per-run CSV as a download link of the same kind; no external file, script or style."""
    import base64
    import html
    import re

    lines = md.splitlines()
    body: list[str] = []
    para: list[str] = []

    def flush() -> None:
        if para:
            body.append(f"<p>{_inline(' '.join(para), folder)}</p>")
            para.clear()

    i = 0
    while i < len(lines):
        line = lines[i]
        img = re.fullmatch(r"!\[(.*)\]\(([^)\s]+)\)", line.strip())
        heading = re.match(r"(#{1,6}) (.*)", line)
        if heading:
            flush()
            n = len(heading.group(1))
            body.append(f"<h{n}>{_inline(heading.group(2), folder)}</h{n}>")
        elif line.startswith("|"):
            flush()
            rows = []
            while i < len(lines) and lines[i].startswith("|"):
                rows.append(lines[i])
                i += 1
            body += _table_html(rows, folder)
            continue
        elif img:
            flush()
            png = folder / img.group(2)
            alt = html.escape(img.group(1))
            src = ("data:image/png;base64," + base64.b64encode(png.read_bytes()).decode()
                   if png.is_file() else html.escape(img.group(2)))
            caption = ""
            j = i + 1
            while j < len(lines) and not lines[j].strip():
                j += 1
            if j < len(lines) and lines[j].strip() == f"*{img.group(1)}*":
                caption = f"<figcaption>{alt}</figcaption>"
                i = j
            body.append(f'<figure><img src="{src}" alt="{alt}">{caption}</figure>')
        elif not line.strip():
            flush()
        else:
            para.append(line.strip())
        i += 1
    flush()
    return ("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
            f"<title>{html.escape(title)}</title><style>{_CSS}</style></head><body>\n"
            + "\n".join(body) + "\n</body></html>\n")


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
             "(Student t: mean ± t(0.975, n−1)·s/√n).", ""]
    written: list[Path] = []
    if table.num_rows == 0:
        lines.append("No results yet.")
        path = out / "report.md"
        path.write_text("\n".join(lines) + "\n")
        return [path, *_html(path, manifest, html)]
    scalars, _ = _columns(table)
    cells = _by_cell(table, manifest)
    lines += ["## Overview", "", *overview(table, manifest), ""]
    figures = manifest.get("figures") or [{"kind": "ospa-time"}]
    campaign_figs: list[tuple[str, Path]] = []
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
            ci = (f"[{_num(mean - half)}, {_num(mean + half)}]" if math.isfinite(half)
                  else "–")
            lines.append(f"| {s} | {_num(mean)} | {ci} | {k} |")
        lines.append("")
        if any(f["kind"] == "seed001" for f in figures):
            table1, png = seed001_table(cell, d, out)
            if table1:
                lines += ["Table 1 (x axis; RMSE over the runs not lost):", "", *table1, ""]
            if png is not None:
                caption = "x position RMSE per filter and estimate; red: the paper's"
                lines += [f"![{caption}]({png.name})", "", f"*{caption}*", ""]
                written.append(png)
        if any(f["kind"] == "seed000" for f in figures):
            for caption, path in seed000_figures(cell, d, out):
                lines += [f"![{caption}]({path.name})", "", f"*{caption}*", ""]
                written.append(path)
    csv_path = out / "per_run.csv"
    with csv_path.open("w", newline="") as fh:
        import csv

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
