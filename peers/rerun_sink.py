"""Streaming a process's view of the run to Rerun (one shared recording per run).

Every process (world, peers) calls :meth:`RerunSink.open` with the same ``run_id``: Rerun merges
their streams into one recording. Each process always writes its own ``.rrd`` file (the
launcher merges them); with ``viewer`` it also streams to a viewer (``"spawn"`` starts one,
a ``rerun+http://...`` URL connects to a running one).

The 2-D map is drawn north-up (y negated: Rerun's 2-D views point y down).
Entity paths: ``world/truth``, ``world/scans/<sensor>``, ``world/sensors``,
``peers/<peer>/{local,fused}`` (points and 2-sigma covariance ellipses), ``peers/<peer>/tail``,
``metrics/<quantity>/<peer>/...`` time series. Timeline ``scan`` (sequence) and ``sim`` (s).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from tracking.mixture import GaussianMixture

APP = "sensornet"
_CIRCLE = np.stack([np.cos(np.linspace(0, 2 * np.pi, 33)),
                    np.sin(np.linspace(0, 2 * np.pi, 33))], axis=1)  # (33, 2)
PALETTE = [(230, 25, 75), (60, 180, 75), (0, 130, 200), (245, 130, 48), (145, 30, 180),
           (70, 240, 240), (240, 50, 230), (210, 245, 60), (0, 128, 128), (170, 110, 40)]


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


def default_blueprint(peers: list[str]):
    """Map view of the world and all peers beside time series of the health metrics."""
    import rerun.blueprint as rrb

    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Spatial2DView(name="world", origin="/", contents=["world/**", "peers/**"]),
            rrb.Vertical(
                rrb.TimeSeriesView(name="OSPA", origin="metrics/ospa"),
                rrb.TimeSeriesView(name="cardinality", origin="metrics/cardinality"),
                rrb.TimeSeriesView(name="components", origin="metrics/components"),
                rrb.Tabs(
                    rrb.TimeSeriesView(name="estimate age (scans)", origin="metrics/age"),
                    rrb.TimeSeriesView(name="late / redundant / too old",
                                       origin="metrics/out_of_sequence"),
                    rrb.TimeSeriesView(name="rejected messages", origin="metrics/rejected"),
                    rrb.TimeSeriesView(name="compute (ms)", origin="metrics/compute_ms"),
                    rrb.TimeSeriesView(name="latency (ms)", origin="metrics/latency_ms"),
                    rrb.TimeSeriesView(name="model probabilities (IMM)",
                                       origin="metrics/model_probability"),
                ),
            ),
            column_shares=[3, 2],
        ),
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


class RerunSink:
    """Logs one process's records; every method is a no-op when disabled."""

    def __init__(self) -> None:
        self.enabled = False
        self.rr = None
        self.path: Path | None = None

    def open(self, run_id: str, path: Path | None, viewer: str | None = None,
             peers: list[str] | None = None) -> RerunSink:
        """Start logging to ``path`` (an ``.rrd``) and optionally a viewer."""
        if path is None and not viewer:
            return self
        os.environ.setdefault("RERUN_ANALYTICS", "0")
        import rerun as rr

        self.rr = rr
        rr.init(APP, recording_id=run_id, spawn=False)
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
        blueprint = default_blueprint(peers or [])
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
        """Component means as points (radius by weight) and their 2-sigma ellipses."""
        if not self.enabled:
            return
        rr = self.rr
        xy = mix.means[:, position_columns(mix.dim)] if len(mix) else np.zeros((0, 2))
        rr.log(f"{path}/means", rr.Points2D(north_up(xy), colors=color,
                                            radii=-(2.0 + 2.0 * np.minimum(mix.weights, 2.0))))
        rr.log(f"{path}/ellipses", rr.LineStrips2D(list(north_up(ellipses(mix.means, mix.covs))),
                                                   colors=color, radii=-1.0))

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

    def close(self) -> None:
        """Flush and close the sinks (the ``.rrd`` is complete afterwards)."""
        if self.enabled:
            try:
                self.rr.disconnect()
            finally:
                self.enabled = False


def color_of(index: int) -> tuple[int, int, int]:
    return PALETTE[index % len(PALETTE)]
