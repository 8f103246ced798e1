"""Streaming a process's view of the run to Rerun (one shared recording per run).

Since issue 38 the live view process (``sensornet view``, :mod:`sensornet.view`) is the one
that logs: it subscribes to the network and opens a :class:`RerunSink` with the peers' names
(blueprint and decorations); the peers log nothing (they publish telemetry,
:mod:`peers.observer`), the world only in secure runs (no view there). A sink writes an
``.rrd`` file (the launcher merges the run's into ``recording.rrd``); with ``viewer`` it also
streams to a viewer (``"spawn"`` starts one, a ``rerun+http://...`` URL connects to a
running one).

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
import shutil
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
from sensornet.peers.rerun_layout import (  # noqa: F401  (names importers take from here)
    _CIRCLE,
    APP,
    COLOR_NAMES,
    CUTOFF_COLOR,
    GRID_COLOR,
    PALETTE,
    REGION_COLOR,
    TICK_GAP,
    TRUTH_COLOR,
    TRUTH_PATH_KEEP,
    color_of,
    dashed,
    default_blueprint,
    ellipses,
    grid_lines,
    legend_markdown,
    lighter,
    nice_step,
    north_up,
    position_columns,
    region_outline,
)
from sensornet.tracking.mixture import GaussianMixture


def viewer_executable() -> str | None:
    """The ``rerun`` viewer installed with the SDK (next to this Python), else from PATH."""
    here = Path(sys.executable).with_name("rerun")
    return str(here) if here.is_file() else shutil.which("rerun")


def spawn_viewer(port: int = 9876) -> bool:
    """Start a native Rerun viewer listening on ``port`` for the run's processes.

    Without a display or without the viewer binary it prints one line and returns False: the
    recording still goes to the ``.rrd`` files. A viewer already on ``port`` is reused.
    """
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


def warm_up(rr) -> None:
    """Build one of each archetype the sinks log, logging nothing: the SDK's first archetype
    costs about 0.3 s (its lazy imports), paid here at start-up, not on the first scan's path
    (a routed peer's first three scans went to their deadline for it)."""
    rr.Points2D(np.zeros((1, 2)), colors=(0, 0, 0), radii=-1.0, labels=["x"])
    rr.LineStrips2D([np.zeros((2, 2))], colors=(0, 0, 0), radii=-1.0)
    rr.Scalars(0.0)
    rr.TextLog("x", level="INFO")


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
        # heavy dependency: rerun (runs without a recording never load it)
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
        warm_up(rr)
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
            self.decorate_peer(p, i, imm, models)

    def decorate_peer(self, p: str, i: int, imm: bool = False,
                      models: tuple[str, ...] = ("CV", "CA")) -> None:
        """Peer ``p``'s series styles in colour ``i`` (a view adds each peer it first hears)."""
        if not self.enabled:
            return
        rr = self.rr
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
        # heavy dependency: scipy.optimize (only the viewer's colour matching needs it)
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
