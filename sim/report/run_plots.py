"""Figures of one run from its per-scan results table (``sensornet plot RUN``).

Two PNGs: ``tracks.png``, the truth's paths and each peer's fused tracks on the ground plane,
and ``metrics.png``, OSPA (with its cut-off), GOSPA's parts, the estimated against the true
number of targets and scan-to-track latency, over scans. In ``tracks.png`` each peer has a panel
with one line per track id (its colour a hash of the id, :func:`id_colour`, so a target's
colour is the same at every peer and in the live view) over the true trajectories, thin grey
lines by true target id. Tables without ids (older runs, kinds without labels) get the fused
estimates as dots, and truth paths joined scan to scan by an optimal assignment
(``scipy.optimize.linear_sum_assignment``) gated at the OSPA cut-off.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
from scipy.optimize import linear_sum_assignment
from sensornet.peers.scan_results import LIST_COLUMNS, merge_parts, read_table
from sensornet.sim.report.report_plots import plt_module

MAX_PANELS = 6
"""Peers drawn in ``tracks.png`` (the first ones in name order; the title says how many)."""


def id_colour(ids: np.ndarray) -> np.ndarray:
    """``(n, 3)`` RGB in 0..1 of track ids ``(n, 3)``: bytes of a BLAKE2 hash of the id, as
    the live view colours them (:func:`sensornet.view.id_color`), the same at every peer."""
    ids = np.asarray(ids, dtype=np.int64).reshape(-1, 3)
    out = np.empty((len(ids), 3))
    for i, row in enumerate(ids):
        h = hashlib.blake2b(row.tobytes(), digest_size=3).digest()
        out[i] = [(64 + b * 191 // 255) / 255 for b in h]
    return out


def tracks_by_id(cols: dict, peer: str, pos: list[int], which: str = "fused"
                 ) -> dict[tuple[int, int, int], np.ndarray]:
    """``{id: (T, 2) positions in scan order}`` of one peer's ``which`` tracks (an id twice in
    a scan keeps its first, heaviest row); ``{}`` when its rows carry no ids."""
    by: dict[tuple[int, int, int], list] = {}
    sel = np.nonzero((cols["peer"] == peer) & (cols["estimate"] == which))[0]
    for i in sel[np.argsort(cols["scan"][sel], kind="stable")]:
        tracks, ids = cols["tracks"][i], cols["track_ids"][i]
        if len(ids) != len(tracks):
            return {}
        seen: set = set()
        for x, lab in zip(tracks, ids, strict=True):
            key = tuple(int(v) for v in lab)
            if key not in seen:
                seen.add(key)
                by.setdefault(key, []).append([x[pos[0]], x[pos[1]]])
    return {k: np.asarray(v, float) for k, v in sorted(by.items())}


def truth_by_id(cols: dict, pos: list[int]) -> dict[int, np.ndarray] | None:
    """``{true target id: (T, 2) positions in scan order}``; None without truth ids."""
    by: dict[int, list] = {}
    done: set[int] = set()
    order = np.argsort(cols["scan"], kind="stable")
    for i in order:
        k, t, ids = int(cols["scan"][i]), cols["truth"][i], cols["truth_ids"][i]
        if k in done:
            continue
        if len(ids) != len(t):
            return None
        done.add(k)
        for x, j in zip(t, ids, strict=True):
            by.setdefault(int(j), []).append([x[pos[0]], x[pos[1]]])
    return {j: np.asarray(v, float) for j, v in sorted(by.items())} if by else None


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

    tracks_png = _tracks_figure(plt, cols, pos, cutoff, peers, colours, Path(run).name, out)
    fused = cols["estimate"] == "fused"

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


def _tracks_figure(plt, cols: dict, pos: list[int], cutoff: float, peers: list[str], colours,
                   name: str, out: Path) -> Path:
    """``tracks.png``: a panel per peer (at most :data:`MAX_PANELS`), a line per fused track id
    over the true trajectories by id; dots and assignment-joined truth without ids."""
    truth = truth_by_id(cols, pos)
    paths = (list(truth.values()) if truth is not None
             else truth_paths(cols["scan"], cols["truth"], pos, cutoff))
    by_peer = {p: tracks_by_id(cols, p, pos) for p in peers}
    if not any(by_peer.values()):  # no ids: one panel of every peer's fused estimates as dots
        fig, ax = plt.subplots(figsize=(7, 6.5))
        _truth_lines(ax, paths, truth is not None)
        fused = cols["estimate"] == "fused"
        for i, peer in enumerate(peers):
            pts = [np.asarray(t, float)[:, pos] for t, keep in
                   zip(cols["tracks"], fused & (cols["peer"] == peer), strict=True)
                   if keep and t]
            if pts:
                P = np.vstack(pts)
                ax.plot(P[:, 0], P[:, 1], ".", ms=3, color=colours(i % colours.N), alpha=0.6,
                        label=f"{peer} fused")
        _finish(ax, f"{name}: truth and fused estimates (no track ids)", len(peers))
        axes = [ax]
    else:
        shown = peers[:MAX_PANELS]
        ncols = min(len(shown), 3)
        nrows = -(-len(shown) // ncols)
        fig, grid = plt.subplots(nrows, ncols, figsize=(5.2 * ncols, 4.8 * nrows),
                                 squeeze=False)
        axes = list(grid.ravel())
        for ax, peer in zip(axes, shown, strict=False):
            _truth_lines(ax, paths, truth is not None)
            tracks = by_peer[peer]
            rgb = id_colour(np.array(list(tracks), dtype=np.int64).reshape(-1, 3))
            for (key, P), c in zip(tracks.items(), rgb, strict=True):
                ax.plot(P[:, 0], P[:, 1], "-", color=c, lw=1.6, marker=".", ms=3)
                if len(P) >= 5:  # a short-lived id's label would only clutter
                    ax.annotate(".".join(map(str, key)), P[-1], fontsize=6, color=c)
            ax.set_title(f"{peer}: {len(tracks)} fused track ids", fontsize=9)
            _finish(ax, None, 1)
        for ax in axes[len(shown):]:
            ax.set_visible(False)
        more = f" (first {len(shown)} of {len(peers)} peers)" if len(peers) > len(shown) else ""
        fig.suptitle(f"{name}: fused tracks, one colour per id (origin.birth.index; the same "
                     f"at every peer), truth in grey{more}", fontsize=10)
    fig.tight_layout()
    path = out / "tracks.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _truth_lines(ax, paths: list[np.ndarray], by_id: bool) -> None:
    for i, path in enumerate(paths):
        ax.plot(path[:, 0], path[:, 1], "-", color="0.55", lw=0.8, zorder=0,
                label=("truth by target id" if by_id else "truth") + " (o: start)"
                if i == 0 else None)
        ax.plot(path[:1, 0], path[:1, 1], "o", color="0.55", ms=3, mfc="none", zorder=0)


def _finish(ax, title: str | None, n: int) -> None:
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_aspect("equal", adjustable="datalim")
    if title:
        ax.set_title(title)
    ax.legend(loc="best", fontsize=7, markerscale=3, ncol=1 if n < 8 else 2)
