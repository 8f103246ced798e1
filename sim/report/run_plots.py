"""Figures of one run from its per-scan results table (``sensornet plot RUN``).

Two PNGs: ``tracks.png``, the truth's paths and each peer's fused estimates on the ground
plane, and ``metrics.png``, OSPA (with its cut-off), GOSPA's parts, the estimated against the
true number of targets and scan-to-track latency, over scans. Truth rows carry no target
identities, so a path joins each scan's true positions to the next scan's by an optimal
assignment (``scipy.optimize.linear_sum_assignment``) gated at the OSPA cut-off.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.optimize import linear_sum_assignment
from sensornet.peers.scan_results import LIST_COLUMNS, merge_parts, read_table
from sensornet.sim.report.report_plots import plt_module


class PlotError(ValueError):
    """A run folder that has no per-scan results to draw."""


def load_results(run: Path) -> tuple[dict[str, np.ndarray | list], dict]:
    """The run's table as columns (NumPy arrays for the scalar ones) and its meta; merges the
    peers' parts first when the run ended before ``results.parquet`` was written."""
    run = Path(run)
    if not run.is_dir():
        raise PlotError(f"{run}: no such run folder")
    table = run / "results.parquet"
    if not table.is_file():
        parts = sorted(run.glob("*.scans.msgpack"))
        if not parts or merge_parts(parts, table) is None:
            raise PlotError(f"{run}: no per-scan results (results.parquet or peer parts); "
                            "runs made before per-scan results cannot be plotted")
    cols, meta = read_table(table)
    out: dict[str, np.ndarray | list] = {}
    for name, values in cols.items():
        out[name] = values if name in LIST_COLUMNS else np.asarray(values)
    return out, meta


def truth_paths(scans: np.ndarray, truths: list, pos: list[int], gate: float) -> list:
    """Truth positions joined scan to scan into paths: a list of ``(n, 2)`` arrays."""
    by_scan: dict[int, np.ndarray] = {}
    for k, t in zip(scans.tolist(), truths, strict=True):
        if k not in by_scan:
            arr = np.asarray(t, float)
            by_scan[k] = arr[:, pos] if arr.size else np.zeros((0, 2))
    done: list[list] = []
    open_paths: list[list] = []
    for k in sorted(by_scan):
        X = by_scan[k]
        ends = np.array([p[-1] for p in open_paths]) if open_paths else np.zeros((0, 2))
        taken = np.zeros(len(X), bool)
        keep: list[list] = []
        if len(ends) and len(X):
            D = np.linalg.norm(ends[:, None, :] - X[None, :, :], axis=-1)
            r, c = linear_sum_assignment(D)
            for i, j in zip(r, c, strict=True):
                if D[i, j] < gate:
                    open_paths[i].append(X[j])
                    taken[j] = True
                    keep.append(open_paths[i])
        kept_ids = {id(p) for p in keep}
        done.extend(p for p in open_paths if id(p) not in kept_ids)
        open_paths = keep + [[x] for x in X[~taken]]
    done.extend(open_paths)
    return [np.array(p) for p in done]


def plot_run(run: Path, out: Path | None = None) -> list[Path]:
    """Draw ``tracks.png`` and ``metrics.png`` for a run folder into ``out`` (default: the
    run folder); the paths written."""
    plt = plt_module()

    cols, meta = load_results(run)
    out = Path(out) if out is not None else Path(run)
    out.mkdir(parents=True, exist_ok=True)
    pos, cutoff = list(meta["position_index"]), float(meta["cutoff"])
    peers = sorted(set(cols["peer"].tolist()))
    colours = plt.get_cmap("tab10" if len(peers) <= 10 else "tab20")

    fig, ax = plt.subplots(figsize=(7, 6.5))
    for i, path in enumerate(truth_paths(cols["scan"], cols["truth"], pos, cutoff)):
        ax.plot(path[:, 0], path[:, 1], "-", color="0.2", lw=1.5,
                label="truth (o: first scan)" if i == 0 else None)
        ax.plot(path[:1, 0], path[:1, 1], "o", color="0.2", ms=4, mfc="none")
    fused = cols["estimate"] == "fused"
    for i, peer in enumerate(peers):
        pts = [np.asarray(t, float)[:, pos] for t, keep in
               zip(cols["tracks"], fused & (cols["peer"] == peer), strict=True) if keep and t]
        if pts:
            P = np.vstack(pts)
            ax.plot(P[:, 0], P[:, 1], ".", ms=3, color=colours(i % colours.N), alpha=0.6,
                    label=f"{peer} fused")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_title(f"{Path(run).name}: truth and fused estimates")
    ax.legend(loc="best", fontsize=7, markerscale=3, ncol=1 if len(peers) < 8 else 2)
    fig.tight_layout()
    tracks_png = out / "tracks.png"
    fig.savefig(tracks_png, dpi=110)
    plt.close(fig)

    fig, axes = plt.subplots(2, 2, figsize=(11, 7.5), sharex=True)
    a_ospa, a_gospa, a_card, a_lat = axes.ravel()
    for i, peer in enumerate(peers):
        colour = colours(i % colours.N)
        for which, style in (("fused", "-"), ("local", ":")):
            sel = (cols["peer"] == peer) & (cols["estimate"] == which)
            order = np.argsort(cols["scan"][sel])
            a_ospa.plot(cols["scan"][sel][order], cols["ospa"][sel][order], style,
                        color=colour, lw=1, label=f"{peer} {which}")
        sel = (cols["peer"] == peer) & fused
        order = np.argsort(cols["scan"][sel])
        a_card.plot(cols["scan"][sel][order], cols["n_estimated"][sel][order], "-",
                    color=colour, lw=1, label=f"{peer} fused")
        lat = cols["latency_ms"][sel][order]
        if np.isfinite(lat).any():
            a_lat.plot(cols["scan"][sel][order], lat, "-", color=colour, lw=1, label=peer)
    a_ospa.axhline(cutoff, color="k", ls="--", lw=0.8, label=f"cut-off c = {cutoff:g} m")
    a_ospa.set_ylim(0, cutoff * 1.05)
    a_ospa.set_ylabel("OSPA (m)")
    a_ospa.set_title("OSPA per peer (solid fused, dotted local)")
    a_ospa.legend(fontsize=6, ncol=2)
    scans = np.unique(cols["scan"][fused])
    p = float(meta["order"])
    parts = {name: np.array([cols[name][fused & (cols["scan"] == k)].mean() for k in scans])
             for name in ("gospa_localisation", "gospa_missed", "gospa_false")}
    half = cutoff**p / 2
    a_gospa.stackplot(scans, parts["gospa_localisation"], half * parts["gospa_missed"],
                      half * parts["gospa_false"],
                      labels=["localisation", "missed targets", "false estimates"], alpha=0.8)
    a_gospa.set_ylabel(f"GOSPA$^{{{p:g}}}$ (m$^{{{p:g}}}$), mean over peers")
    a_gospa.set_title("GOSPA's parts (fused)")
    a_gospa.legend(fontsize=7, loc="upper right")
    n_true = np.array([cols["n_true"][fused & (cols["scan"] == k)].max() for k in scans])
    a_card.step(scans, n_true, where="mid", color="k", lw=2, label="true")
    a_card.set_ylabel("number of targets")
    a_card.yaxis.get_major_locator().set_params(integer=True)
    a_card.set_title("Estimated (fused) and true number of targets")
    a_card.legend(fontsize=6, ncol=2)
    if a_lat.lines:
        a_lat.set_ylabel("scan → fused track (ms)")
        a_lat.set_title("Latency per scan")
        a_lat.legend(fontsize=6, ncol=2)
    else:
        a_lat.text(0.5, 0.5, "no latency measured\n(a --sim run has no wall clock)",
                   ha="center", va="center", transform=a_lat.transAxes)
        a_lat.set_yticks([])
    for a in (a_card, a_lat):
        a.set_xlabel("scan")
    fig.tight_layout()
    metrics_png = out / "metrics.png"
    fig.savefig(metrics_png, dpi=110)
    plt.close(fig)
    return [tracks_png, metrics_png]
