"""What the Rerun view looks like, apart from streaming: colours, the map's geometry (2-sigma
ellipses, dashes, the region's outline and grid, north-up), the legend and the blueprint.
Pure NumPy and ``rerun.blueprint`` values; :mod:`peers.rerun_sink` logs them."""

from __future__ import annotations

import numpy as np

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
GEO_ZOOM = 9.0
"""The geographic map view's zoom level (web-map tiles: 9 is about 140 km across a panel)."""
TRUTH_PATH_KEEP = 500
"""Scans of each true target's path drawn (the newest; memory stays flat in long runs)."""


def position_columns(dim: int) -> list[int]:
    """Columns of (px, py): ``[0, 2]`` in ``[px, vx, py, vy]``, ``[0, 3]`` in the 6-D state."""
    return [0, 3] if dim == 6 else [0, 2]


def ellipses(means: np.ndarray, covs: np.ndarray, sigma: float = 2.0) -> np.ndarray:
    """``sigma``-ellipses of the (px, py) marginals: ``(n, 33, 2)`` polylines, vectorised.

    The unit circle mapped by the 2x2 Cholesky factor ``L`` of each position block (any
    ``L`` with ``L L^T = P`` maps it onto the same ellipse), in closed form: no LAPACK call
    per component, which a view drawing 100 peers' mixtures pays thousands of times a second.
    """
    if len(means) == 0:
        return np.zeros((0, 33, 2))
    c = position_columns(means.shape[1])
    a, b, d = covs[:, c[0], c[0]], covs[:, c[0], c[1]], covs[:, c[1], c[1]]
    l11 = np.sqrt(np.maximum(a, 0.0))
    l21 = np.divide(b, l11, out=np.zeros_like(b), where=l11 > 0)
    l22 = np.sqrt(np.maximum(d - l21 * l21, 0.0))
    cx, cy = sigma * _CIRCLE[:, 0], sigma * _CIRCLE[:, 1]  # (33,)
    out = np.empty((len(means), 33, 2))
    out[:, :, 0] = means[:, None, c[0]] + l11[:, None] * cx
    out[:, :, 1] = means[:, None, c[1]] + l21[:, None] * cx + l22[:, None] * cy
    return out


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
        "number follows a track from scan to scan by association: for the eye, not scored); "
        "tracks with identities: labelled origin.birth.index, one colour per identity, the "
        "same at every peer",
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
                      follow_radius: float = 500.0, ospa_cutoff: float | None = None,
                      geo: bool = False):
    """Map and legend beside time series of the health metrics.

    ``single_target``: a second map view centred on the target (the ``follow`` transform the
    world logs), for scenarios whose region dwarfs the target and its particle cloud;
    ``imm``: the model probabilities in view instead of the component counts; ``geo``: a
    geographic map view of ``map/**`` beside the local map (a scenario with a geographic
    origin, :mod:`sensornet.view_map`).
    """
    # heavy dependency: rerun (runs without a recording never load it)
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
    if geo:  # WGS84 on OpenStreetMap tiles; zoom 9 shows about 140 km across
        maps = rrb.Horizontal(maps, rrb.MapView(name="geographic map", origin="/map",
                                                zoom=GEO_ZOOM,
                                                background=rrb.MapProvider.OpenStreetMap))
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


def cell_marks(z: np.ndarray, labels: np.ndarray) -> tuple[np.ndarray, np.ndarray, list]:
    """A scan ``z (m, 2)`` coloured by cell of its most probable partition (``labels (m,)``):
    ``(colors (m, 3), extents (c, 33, 2), extent colours)``. One-point cells (the clutter the
    grid method removed, isolated points) grey; the 2-sigma extents of the cells of 3 or more
    points in their cell's colour."""
    z = np.asarray(z, float).reshape(-1, 2)
    _, inv, counts = np.unique(np.asarray(labels).reshape(-1), return_inverse=True,
                               return_counts=True)
    inv = inv.reshape(-1)
    single = counts[inv] == 1
    colors = np.array([color_of(i) for i in range(len(counts))], dtype=np.uint8)[inv] \
        if len(counts) else np.zeros((0, 3), np.uint8)
    colors[single] = (128, 128, 128)
    big = np.flatnonzero(counts >= 3)
    means = np.zeros((len(big), 4))
    covs = np.zeros((len(big), 4, 4))
    for i, c in enumerate(big):  # a few cells a scan
        w = z[inv == c]
        means[i, [0, 2]] = w.mean(axis=0)
        covs[i][np.ix_([0, 2], [0, 2])] = np.cov(w.T)
    return colors, ellipses(means, covs), [color_of(int(c)) for c in big]


def north_up(xy: np.ndarray) -> np.ndarray:
    """Map coordinates ``(..., 2)`` for Rerun's y-down 2-D views: y negated, so north is up."""
    out = np.array(xy, dtype=float, copy=True)
    out[..., 1] *= -1.0
    return out


def color_of(index: int) -> tuple[int, int, int]:
    return PALETTE[index % len(PALETTE)]
