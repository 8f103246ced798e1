"""Streaming a process's view of the run to Rerun (one shared recording per run).

Every process (world, peers) calls :meth:`RerunSink.open` with the same ``run_id``: Rerun merges
their streams into one recording. Each process always writes its own ``.rrd`` file (the
launcher merges them); with ``viewer`` it also streams to a viewer (``"spawn"`` starts one,
a ``rerun+http://...`` URL connects to a running one).

The 2-D map is drawn north-up (y negated: Rerun's 2-D views point y down).
Entity paths: ``world/truth``, ``world/scans/<sensor>``, ``world/sensors``, ``world/region``
and ``world/grid`` (the surveillance region and a grid with labelled lines),
``peers/<peer>/{local,fused}`` (points and 2-sigma covariance ellipses: local dashed, fused
solid), ``peers/<peer>/tail``, ``metrics/<quantity>/<peer>/...`` time series (each peer in its
own colour: local dotted, fused solid; ``metrics/cardinality/truth`` in gold), ``legend`` (a
text document saying what each mark means), ``follow`` (a transform that centres the "around
the target" view on a single target). Timeline ``scan`` (sequence) and ``sim`` (s).

Only the process that passes ``peers`` to :meth:`RerunSink.open` (the world) sends the
blueprint and the static decorations (:meth:`RerunSink.decorate`), so the viewer gets one
layout whatever order the processes connect in.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from tracking.mixture import GaussianMixture

APP = "sensornet"
_CIRCLE = np.stack([np.cos(np.linspace(0, 2 * np.pi, 33)),
                    np.sin(np.linspace(0, 2 * np.pi, 33))], axis=1)  # (33, 2)
PALETTE = [(230, 25, 75), (0, 130, 200), (245, 130, 48), (145, 30, 180), (60, 180, 75),
           (240, 50, 230), (0, 128, 128), (170, 110, 40), (70, 240, 240), (128, 128, 0)]
"""Peer colours, far apart in hue (no two greens among the first four)."""
COLOR_NAMES = ["red", "blue", "orange", "purple", "green", "magenta", "teal", "brown", "cyan",
               "olive"]
TRUTH_COLOR = (255, 215, 0)
GRID_COLOR = (90, 90, 90)
REGION_COLOR = (170, 170, 170)
CUTOFF_COLOR = (120, 120, 120)
TICK_GAP = 0.03
"""Grid labels sit this fraction of the region's larger side outside its frame."""
TRUTH_PATH_KEEP = 500
"""Scans of each true target's path drawn (the newest; memory stays flat in long runs)."""


def position_columns(dim: int) -> list[int]:
    """Columns of (px, py): ``[0, 2]`` in ``[px, vx, py, vy]``, ``[0, 3]`` in the 6-D state."""
    return [0, 3] if dim == 6 else [0, 2]


def ellipses(means: np.ndarray, covs: np.ndarray, sigma: float = 2.0) -> np.ndarray:
    """``sigma``-ellipses of the (px, py) marginals: ``(n, 33, 2)`` polylines, vectorised."""
    if len(means) == 0:
        return np.zeros((0, 33, 2))
    c = position_columns(means.shape[1])
    P = covs[:, c][:, :, c]  # (n, 2, 2) position block
    vals, vecs = np.linalg.eigh(P)
    axes = vecs * (sigma * np.sqrt(np.maximum(vals, 0.0)))[:, None, :]  # (n, 2, 2)
    return means[:, None, c] + np.einsum("pj,nij->npi", _CIRCLE, axes)


def dashed(strips: np.ndarray) -> np.ndarray:
    """Every other segment of ``(n, m, 2)`` polylines as ``(n * (m // 2), 2, 2)`` two-point
    strips: Rerun draws no dashed lines, so a dashed ellipse is half its segments."""
    strips = np.asarray(strips, dtype=float)
    n, m = strips.shape[:2]
    if n == 0 or m < 2:
        return np.zeros((0, 2, 2))
    half = (m - 1) // 2
    a, b = strips[:, 0:2 * half:2], strips[:, 1:2 * half + 1:2]
    return np.stack([a, b], axis=2).reshape(-1, 2, 2)


def lighter(color, amount: float = 0.45) -> tuple[int, int, int]:
    """``color`` blended towards white by ``amount``."""
    return tuple(int(round(c + (255 - c) * amount)) for c in color[:3])


def nice_step(span: float, lines: int = 6) -> float:
    """A grid step of 1, 2 or 5 x 10^k giving about ``lines`` lines over ``span``."""
    raw = max(span, 1e-9) / max(lines, 1)
    base = 10.0 ** np.floor(np.log10(raw))
    for f in (1.0, 2.0, 5.0, 10.0):
        if raw <= f * base:
            return float(f * base)
    return float(10 * base)


def region_outline(region) -> np.ndarray:
    """The closed rectangle ``((xmin, xmax), (ymin, ymax))`` as a ``(5, 2)`` polyline."""
    (x0, x1), (y0, y1) = region
    return np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1], [x0, y0]], dtype=float)


def grid_lines(region, step: float | None = None) -> tuple[list[np.ndarray], np.ndarray,
                                                             list[str]]:
    """Grid lines every ``step`` m over ``region`` and the positions and labels of their ticks
    (along the bottom and left edges)."""
    (x0, x1), (y0, y1) = region
    step = step or nice_step(max(x1 - x0, y1 - y0))
    xs = np.arange(np.ceil(x0 / step) * step, x1 + 1e-9, step)
    ys = np.arange(np.ceil(y0 / step) * step, y1 + 1e-9, step)
    lines = [np.array([[x, y0], [x, y1]]) for x in xs] + [np.array([[x0, y], [x1, y]])
                                                          for y in ys]
    # labels just outside the frame (x below it, y left of it): a sensor on the edge or in a
    # corner keeps its own label clear of the grid's (seed 001's radars sit on the edge)
    gap = TICK_GAP * max(x1 - x0, y1 - y0)
    ticks = np.array([[x, y0 - gap] for x in xs] + [[x0 - gap, y] for y in ys],
                     dtype=float).reshape(-1, 2)
    labels = [f"x {x:g} m" for x in xs] + [f"y {y:g} m" for y in ys]
    return lines, ticks, labels


def legend_markdown(peers: list[str], single_target: bool = False, imm: bool = False,
                    follow_radius: float | None = None) -> str:
    """The legend panel: what each mark on the map and each line in the plots means."""
    colours = ", ".join(f"**{p}** {COLOR_NAMES[i % len(COLOR_NAMES)]}"
                        for i, p in enumerate(peers)) or "one colour per peer"
    local = "particles (a sample) and local estimate" if imm else "local components"
    lines = [
        f"**Colours**: {colours} (a peer's marks, its sensor's scans, its plot lines).",
        "",
        "**Map** (north up, metres):",
        "- gold, numbered, with their paths: true targets; big labelled dots: sensors",
        "- small dots: measurements of this scan (detections and clutter)",
        f"- dashed 2-sigma ellipses, light dots: {local} (before fusion)",
        "- solid ellipses: fused; dots with a trail: fused tracks, labelled peer/number (a "
        "number follows a track from scan to scan by association: for the eye, not scored)",
        "- grey frame: surveillance region; grid labelled just outside its edges",
    ]
    if single_target and follow_radius:
        lines.append(f"- 'around the target': the same, centred on the true target "
                     f"(+-{follow_radius:g} m)")
    lines += ["", "**Plots**: dotted = local, solid = fused, gold = truth. OSPA: error with "
              "cut-off (the grey line), lower is better."
              + (" Model probabilities: CV solid, CA dotted." if imm else "")]
    return "\n".join(lines)


def default_blueprint(peers: list[str], *, single_target: bool = False, imm: bool = False,
                      follow_radius: float = 500.0, ospa_cutoff: float | None = None):
    """Map and legend beside time series of the health metrics.

    ``single_target``: a second map view centred on the target (the ``follow`` transform the
    world logs), for scenarios whose region dwarfs the target and its particle cloud;
    ``imm``: the model probabilities in view instead of the component counts.
    """
    import rerun.blueprint as rrb

    hidden = rrb.PlotLegend(visible=False)  # the legend panel names the colours instead

    def series(name: str, origin: str, legend=hidden, y_range=None):
        axis = rrb.ScalarAxis(range=y_range, zoom_lock=False) if y_range else None
        return rrb.TimeSeriesView(name=name, origin=origin, plot_legend=legend, axis_y=axis)

    probabilities = series("model probabilities (IMM)", "metrics/model_probability",
                           y_range=(0.0, 1.0))
    ospa = series("OSPA (m; grey: cut-off)", "metrics/ospa",
                  y_range=(0.0, 1.05 * ospa_cutoff) if ospa_cutoff else None)

    map_view = rrb.Spatial2DView(name="map", origin="/", contents=["/world/**", "/peers/**"])
    if single_target:
        r = float(follow_radius)
        maps = rrb.Vertical(
            map_view,
            rrb.Spatial2DView(name="around the target", origin="/follow",
                              contents=["/world/**", "/peers/**"],
                              visual_bounds=rrb.VisualBounds2D(x_range=[-r, r],
                                                               y_range=[-r, r])),
            row_shares=[1, 1])
    else:
        maps = map_view
    third = (probabilities if imm
             else series("components (fused solid, local dotted)", "metrics/components"))
    tabs = [
        series("estimate age (scans)", "metrics/age"),
        series("late / redundant / too old", "metrics/out_of_sequence"),
        series("rejected messages", "metrics/rejected"),
        series("compute per scan (ms)", "metrics/compute_ms"),
        series("latency (ms)", "metrics/latency_ms"),
        (series("components", "metrics/components") if imm else probabilities),
    ]
    return rrb.Blueprint(
        rrb.Horizontal(
            maps,
            rrb.Vertical(
                rrb.TextDocumentView(name="legend", origin="legend"),
                ospa,
                series("cardinality (truth gold)", "metrics/cardinality"),
                third,
                rrb.Tabs(*tabs),
                row_shares=[1.6, 1, 1, 1, 1],
            ),
            column_shares=[3, 2],
        ),
        # open on the scan timeline (the other, "sim", is the scenario's seconds)
        rrb.TimePanel(timeline="scan", state="collapsed"),
        collapse_panels=True,
    )


def north_up(xy: np.ndarray) -> np.ndarray:
    """Map coordinates ``(..., 2)`` for Rerun's y-down 2-D views: y negated, so north is up."""
    out = np.array(xy, dtype=float, copy=True)
    out[..., 1] *= -1.0
    return out


def viewer_executable() -> str | None:
    """The ``rerun`` viewer installed with the SDK (next to this Python), else from PATH."""
    import shutil
    import sys

    here = Path(sys.executable).with_name("rerun")
    return str(here) if here.is_file() else shutil.which("rerun")


def spawn_viewer(port: int = 9876) -> bool:
    """Start a native Rerun viewer listening on ``port`` for the run's processes.

    Without a display or without the viewer binary it prints one line and returns False: the
    recording still goes to the ``.rrd`` files. A viewer already on ``port`` is reused.
    """
    import socket
    import subprocess
    import sys
    import time

    with socket.socket() as probe:
        if probe.connect_ex(("127.0.0.1", port)) == 0:
            return True  # a viewer (or server) is already listening
    if sys.platform.startswith("linux") and not (os.environ.get("DISPLAY")
                                                 or os.environ.get("WAYLAND_DISPLAY")):
        print("sensornet: no display for a Rerun viewer; recording to files only (watch it "
              "later with `rerun <run>/recording.rrd`, or stream to a web viewer: see --viewer)",
              file=sys.stderr)
        return False
    exe = viewer_executable()
    if exe is None:
        print("sensornet: no Rerun viewer found; recording to files only", file=sys.stderr)
        return False
    proc = subprocess.Popen([exe, "--port", str(port)], stdin=subprocess.DEVNULL,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            start_new_session=True)
    deadline = time.monotonic() + 10.0
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            print("sensornet: the Rerun viewer did not start (no display?); recording to "
                  "files only", file=sys.stderr)
            return False
        with socket.socket() as probe:
            if probe.connect_ex(("127.0.0.1", port)) == 0:
                return True
        time.sleep(0.1)
    print("sensornet: the Rerun viewer did not open its port in 10 s; recording to files only",
          file=sys.stderr)
    return False


class _Stream:
    """The ``rerun`` module, with logging, time and sinks of one ``RecordingStream`` of its
    own: several sinks in one process (the peers of a host), each its own ``.rrd``."""

    def __init__(self, rr, stream) -> None:
        self._rr, self._stream = rr, stream

    def __getattr__(self, name: str):
        return getattr(self._rr, name)

    def log(self, *args, **kwargs) -> None:
        self._stream.log(*args, **kwargs)

    def set_time(self, *args, **kwargs) -> None:
        self._stream.set_time(*args, **kwargs)

    def set_sinks(self, *sinks, default_blueprint=None) -> None:
        self._stream.set_sinks(*sinks, default_blueprint=default_blueprint)

    def disconnect(self) -> None:
        self._stream.disconnect()


class RerunSink:
    """Logs one process's records; every method is a no-op when disabled.

    ``own_stream``: log to a recording stream of this sink's own, not the process's global
    one (a process with several sinks: the peers of a host)."""

    def __init__(self, own_stream: bool = False) -> None:
        self.own_stream = own_stream
        self.enabled = False
        self.rr = None
        self.path: Path | None = None

    def open(self, run_id: str, path: Path | None, viewer: str | None = None,
             peers: list[str] | None = None, **layout) -> RerunSink:
        """Start logging to ``path`` (an ``.rrd``) and optionally a viewer.

        With ``peers`` (the world) it also sends the blueprint, :func:`default_blueprint` with
        ``layout`` (``single_target``, ``imm``, ``follow_radius``); without (a peer) none, so
        that one layout reaches the viewer.
        """
        if path is None and not viewer:
            return self
        os.environ.setdefault("RERUN_ANALYTICS", "0")
        import rerun as rr

        if self.own_stream:
            rr = _Stream(rr, rr.RecordingStream(APP, recording_id=run_id))
        else:
            rr.init(APP, recording_id=run_id, spawn=False)
        self.rr = rr
        sinks = []
        if path is not None:
            path.parent.mkdir(parents=True, exist_ok=True)
            sinks.append(rr.FileSink(str(path)))
            self.path = path
        if viewer == "spawn":
            if spawn_viewer():
                sinks.append(rr.GrpcSink("rerun+http://127.0.0.1:9876/proxy"))
        elif viewer:
            sinks.append(rr.GrpcSink(viewer))
        blueprint = default_blueprint(peers, **layout) if peers is not None else None
        rr.set_sinks(*sinks, default_blueprint=blueprint)
        self.enabled = True
        return self

    def time(self, k: int, t: float) -> None:
        if self.enabled:
            self.rr.set_time("scan", sequence=int(k))
            self.rr.set_time("sim", duration=float(t))

    def points(self, path: str, xy: np.ndarray, color=None, radius: float = 4.0,
               labels: list[str] | None = None) -> None:
        """Points with ``radius`` in UI points (the same size at any zoom)."""
        if self.enabled:
            self.rr.log(path, self.rr.Points2D(north_up(np.asarray(xy, float).reshape(-1, 2)),
                                               colors=color, radii=-abs(radius),
                                               labels=labels))

    def mixture(self, path: str, mix: GaussianMixture, color) -> None:
        """Component means as points (radius by weight) and their 2-sigma ellipses.

        A ``.../local`` path is drawn dashed and lighter (before fusion), any other solid."""
        if not self.enabled:
            return
        rr = self.rr
        local = path.rstrip("/").endswith("local")
        xy = mix.means[:, position_columns(mix.dim)] if len(mix) else np.zeros((0, 2))
        shown = lighter(color) if local else color
        rr.log(f"{path}/means", rr.Points2D(north_up(xy), colors=shown,
                                            radii=-(2.0 + 2.0 * np.minimum(mix.weights, 2.0))))
        strips = north_up(ellipses(mix.means, mix.covs))
        rr.log(f"{path}/ellipses", rr.LineStrips2D(dashed(strips) if local else list(strips),
                                                   colors=shown,
                                                   radii=-1.0 if local else -1.5))

    def scalar(self, path: str, value: float | None) -> None:
        if self.enabled and value is not None and np.isfinite(value):
            self.rr.log(path, self.rr.Scalars(float(value)))

    def strips(self, path: str, lines: list[np.ndarray], color=None) -> None:
        if self.enabled:
            self.rr.log(path, self.rr.LineStrips2D([north_up(a) for a in lines], colors=color,
                                                   radii=-1.5))

    def text(self, path: str, message: str, level: str = "INFO") -> None:
        if self.enabled:
            self.rr.log(path, self.rr.TextLog(message, level=level))

    def decorate(self, peers: list[str], region=None, imm: bool = False,
                 single_target: bool = False, follow_radius: float | None = None,
                 models: tuple[str, ...] = ("CV", "CA")) -> None:
        """Static marks that explain the view (the world logs them once): the legend text,
        the region outline and grid, and each series' colour, style and name (IMM ``models``:
        the first solid, the others dotted)."""
        if not self.enabled:
            return
        rr = self.rr
        rr.log("legend", rr.TextDocument(
            legend_markdown(peers, single_target, imm, follow_radius),
            media_type=rr.MediaType.MARKDOWN), static=True)
        if region is not None:
            rr.log("world/region", rr.LineStrips2D([north_up(region_outline(region))],
                                                   colors=REGION_COLOR, radii=-1.5),
                   static=True)
            lines, ticks, labels = grid_lines(region)
            rr.log("world/grid/lines", rr.LineStrips2D([north_up(a) for a in lines],
                                                       colors=GRID_COLOR, radii=-0.5),
                   static=True)
            rr.log("world/grid/ticks", rr.Points2D(north_up(ticks), colors=GRID_COLOR,
                                                   radii=-1.0, labels=labels,
                                                   show_labels=True), static=True)
        rr.log("metrics/cardinality/truth",
               rr.SeriesLines(colors=TRUTH_COLOR, widths=3.0, names="truth"), static=True)
        rr.log("metrics/ospa/cutoff",
               rr.SeriesLines(colors=CUTOFF_COLOR, widths=1.0, names="cut-off c"), static=True)
        for i, p in enumerate(peers):
            c = color_of(i)
            solid = {"colors": c, "widths": 2.0}
            for q in ("ospa", "cardinality"):
                rr.log(f"metrics/{q}/{p}/fused", rr.SeriesLines(**solid, names=f"{p} fused"),
                       static=True)
                rr.log(f"metrics/{q}/{p}/local",
                       rr.SeriesPoints(colors=c, markers="circle", marker_sizes=1.5,
                                       names=f"{p} local"), static=True)
            rr.log(f"metrics/components/{p}/fused",
                   rr.SeriesLines(**solid, names=f"{p} fused"), static=True)
            for what, marker in (("before_level2", "circle"), ("after_level2", "cross")):
                rr.log(f"metrics/components/{p}/{what}",
                       rr.SeriesPoints(colors=c, markers=marker, marker_sizes=1.5,
                                       names=f"{p} local {what.replace('_', ' ')}"),
                       static=True)
            for q in ("age", "rejected", "latency_ms"):
                rr.log(f"metrics/{q}/{p}", rr.SeriesLines(**solid, names=p), static=True)
            rr.log(f"metrics/compute_ms/{p}/filter",
                   rr.SeriesLines(**solid, names=f"{p} filter step"), static=True)
            rr.log(f"metrics/compute_ms/{p}/fusion",
                   rr.SeriesPoints(colors=c, markers="circle", marker_sizes=1.5,
                                   names=f"{p} fusion"), static=True)
            if imm:
                for j, model in enumerate(models):
                    style = (rr.SeriesLines(**solid, names=f"{p} {model}") if j == 0 else
                             rr.SeriesPoints(colors=c, markers="circle", marker_sizes=1.5,
                                             names=f"{p} {model}"))
                    rr.log(f"metrics/model_probability/{p}/{model}", style, static=True)

    def labelled_points(self, path: str, xy: np.ndarray, color, labels: list[str],
                        radius: float = 5.0) -> None:
        """Points that always show their labels (track and target identities)."""
        if self.enabled:
            self.rr.log(path, self.rr.Points2D(north_up(np.asarray(xy, float).reshape(-1, 2)),
                                               colors=color, radii=-abs(radius),
                                               labels=labels, show_labels=True))

    def follow(self, xy) -> None:
        """Centre the "around the target" view on ``xy`` (map coordinates) at this time."""
        if self.enabled:
            x, y = north_up(np.asarray(xy, dtype=float).reshape(2))
            self.rr.log("follow", self.rr.Transform3D(translation=[x, y, 0.0]))

    def close(self) -> None:
        """Flush and close the sinks (the ``.rrd`` is complete afterwards)."""
        if self.enabled:
            try:
                self.rr.disconnect()
            finally:
                self.enabled = False


class TruthPaths:
    """Each true target's path so far (by its id), the newest :data:`TRUTH_PATH_KEEP` points."""

    def __init__(self) -> None:
        self._paths: dict[int, list] = {}

    def add(self, ids, xy: np.ndarray) -> None:
        for i, p in zip(np.asarray(ids).tolist(), np.asarray(xy, float).reshape(-1, 2),
                        strict=True):
            path = self._paths.setdefault(int(i), [])
            path.append(p)
            del path[:-TRUTH_PATH_KEEP]

    def strips(self) -> list[np.ndarray]:
        """One polyline per target with at least two points."""
        return [np.array(p) for p in self._paths.values() if len(p) > 1]


class TrackLabels:
    """Display identities for a peer's fused tracks: each scan's tracks are matched to the last
    scan's by an optimal assignment (``scipy.optimize.linear_sum_assignment``) within ``gate``
    metres and keep their number; the others get new numbers. The filters carry no labels
    (GM-PHD): these are for the eye, not scored."""

    def __init__(self, gate: float) -> None:
        self.gate = float(gate)
        self._last = np.zeros((0, 2))
        self._ids: list[int] = []
        self._next = 0

    def assign(self, xy: np.ndarray) -> list[int]:
        from scipy.optimize import linear_sum_assignment

        xy = np.asarray(xy, float).reshape(-1, 2)
        ids = [-1] * len(xy)
        if len(xy) and len(self._last):
            D = np.linalg.norm(xy[:, None, :] - self._last[None, :, :], axis=-1)
            rows, cols = linear_sum_assignment(D)
            for r, c in zip(rows, cols, strict=True):
                if D[r, c] <= self.gate:
                    ids[r] = self._ids[c]
        for r in range(len(ids)):
            if ids[r] < 0:
                ids[r], self._next = self._next, self._next + 1
        self._last, self._ids = xy, ids
        return ids


def color_of(index: int) -> tuple[int, int, int]:
    return PALETTE[index % len(PALETTE)]
