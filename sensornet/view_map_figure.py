"""What a recording's geographic map view shows, as a PNG without a viewer (issue 34, "What
must show": tracks over the real trajectories): reads the ``map/**`` entities the live view
logged (:mod:`sensornet.view_map`) back from the ``.rrd`` (``rerun.chunk.RrdReader``) and
draws them on latitude/longitude axes with matplotlib: the aircraft's true paths (grey) and
their last positions labelled by icao24, one peer's fused tracks over the whole run (one
colour per track id), the radar sites, their coverage and the traffic disc. No map tiles
(the Rerun viewer fetches those).

    python -m sensornet.view_map_figure RUN/recording.rrd --peer cdg --out map.png
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from rerun.chunk import RrdReader

MAP = "/map"


@dataclass
class MapRecord:
    """The ``map/**`` entities of a recording: per entity its static row (or None) and its
    rows by scan, each ``{component: value}`` (e.g. ``"GeoPoints:positions"``: a list of
    [lat, lon])."""

    static: dict[str, dict] = field(default_factory=dict)
    rows: dict[str, dict[int, dict]] = field(default_factory=dict)

    def names(self) -> dict[int, str]:
        """Class id -> name (icao24, track id, site) from the ``map`` annotation context."""
        ctx = self.static.get(MAP, {}).get("AnnotationContext:context") or [[]]
        ctx = ctx[0]  # one context (a list of classes) per row
        return {c["class_id"]: c["class_description"]["info"]["label"] for c in ctx}

    def peers(self) -> list[str]:
        """The peers whose tracks are on the map, in the order first logged."""
        head = f"{MAP}/peers/"
        return [p[len(head):-len("/tracks")] for p in self.rows
                if p.startswith(head) and p.endswith("/tracks")]


def read_map(path: Path) -> MapRecord:
    """The ``map/**`` entities of the recording at ``path`` (a later row of a scan replaces an
    earlier one). Raises ``ValueError`` naming the file if it holds none."""
    out = MapRecord()
    for chunk in RrdReader(path).stream():
        entity = str(chunk.entity_path)
        if entity != MAP and not entity.startswith(MAP + "/"):
            continue
        batch = chunk.to_record_batch().to_pydict()
        comps = [c for c in batch if ":" in c and not c.startswith("rerun.")]
        for i in range(len(batch["rerun.controls.RowId"])):
            row = {c: batch[c][i] for c in comps if batch[c][i] is not None}
            if chunk.is_static:
                out.static.setdefault(entity, {}).update(row)
            else:
                out.rows.setdefault(entity, {}).setdefault(int(batch["scan"][i]), {}).update(row)
    if not out.static and not out.rows:
        raise ValueError(f"{path}: no map/** entities (not a geographic scenario's view "
                         f"recording?)")
    return out


def _rgb(colors) -> np.ndarray:
    """Rerun's packed RGBA ``uint32`` values as ``(n, 3)`` floats in [0, 1]."""
    c = np.asarray(colors, np.uint64).reshape(-1)
    return np.column_stack([(c >> 24) & 255, (c >> 16) & 255, (c >> 8) & 255]) / 255.0


def track_lines(rows: dict[int, dict]) -> list[tuple[int, np.ndarray, np.ndarray]]:
    """A peer's ``tracks`` rows as one ``(class id, lat_lon (m, 2), rgb (3,))`` per track id
    (class 0, unnamed, left out), points in scan order."""
    scans = sorted(rows)
    parts = [(np.asarray(rows[k].get("GeoPoints:positions") or np.zeros((0, 2)), float),
              np.asarray(rows[k].get("GeoPoints:class_ids") or [], np.int64),
              _rgb(rows[k].get("GeoPoints:colors") or [])) for k in scans]
    ll = np.concatenate([p[0].reshape(-1, 2) for p in parts])
    cid = np.concatenate([p[1] for p in parts])
    rgb = np.concatenate([np.broadcast_to(p[2], (len(p[1]), 3)) if len(p[2]) else
                          np.zeros((len(p[1]), 3)) for p in parts])
    order = np.argsort(cid, kind="stable")  # by id, each in scan order
    ids, first, counts = np.unique(cid[order], return_index=True, return_counts=True)
    return [(int(i), ll[order][f:f + n], rgb[order][f]) for i, f, n
            in zip(ids, first, counts, strict=True) if i > 0]


def plot_map(rec: MapRecord, peer: str, out: Path, title: str | None = None) -> Path:
    """Draw ``rec`` (truth paths, ``peer``'s fused tracks, sites, coverage) to ``out``."""
    import matplotlib  # heavy optional dependency: matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # heavy optional dependency: matplotlib

    if f"{MAP}/peers/{peer}/tracks" not in rec.rows:
        raise ValueError(f"--peer {peer}: no tracks of that peer on the map "
                         f"(peers: {', '.join(rec.peers()) or 'none'})")
    names = rec.names()
    fig, ax = plt.subplots(figsize=(7.0, 7.0), dpi=90)
    region = rec.static.get(f"{MAP}/region", {}).get("GeoLineStrings:line_strings") or []
    for line in region:
        a = np.asarray(line)
        ax.plot(a[:, 1], a[:, 0], color="0.6", lw=1, ls="--", zorder=0)
    cover = rec.static.get(f"{MAP}/sensors/coverage", {})
    for line, c in zip(cover.get("GeoLineStrings:line_strings") or [],
                       _rgb(cover.get("GeoLineStrings:colors") or []), strict=False):
        a = np.asarray(line)
        ax.plot(a[:, 1], a[:, 0], color=c, lw=0.8, alpha=0.5, zorder=0)
    paths = rec.rows.get(f"{MAP}/truth/paths", {})
    if paths:  # the newest row holds every path so far
        for line in paths[max(paths)].get("GeoLineStrings:line_strings") or []:
            a = np.asarray(line)
            ax.plot(a[:, 1], a[:, 0], color="0.78", lw=3.5, zorder=1, solid_capstyle="round")
    truth = rec.rows.get(f"{MAP}/truth", {})
    if truth:
        last = truth[max(truth)]
        ll = np.asarray(last.get("GeoPoints:positions") or np.zeros((0, 2)), float)
        ax.scatter(ll[:, 1], ll[:, 0], s=14, color="goldenrod", zorder=3)
        for (la, lo), c in zip(ll, last.get("GeoPoints:class_ids") or [], strict=False):
            ax.annotate(names.get(c, ""), (lo, la), fontsize=6, color="0.3",
                        xytext=(3, 3), textcoords="offset points", zorder=4)
    lines = track_lines(rec.rows[f"{MAP}/peers/{peer}/tracks"])
    for _, ll, c in lines:
        ax.plot(ll[:, 1], ll[:, 0], color=c * 0.8, lw=1.0, zorder=2)
    sites = rec.static.get(f"{MAP}/sensors", {})
    for (la, lo), c, cid in zip(sites.get("GeoPoints:positions") or [],
                                _rgb(sites.get("GeoPoints:colors") or []),
                                sites.get("GeoPoints:class_ids") or [], strict=False):
        ax.scatter([lo], [la], marker="^", s=80, color=c, edgecolor="k", zorder=5)
        ax.annotate(names.get(cid, ""), (lo, la), fontsize=8, xytext=(5, -10),
                    textcoords="offset points", zorder=5)
    if region:
        a = np.asarray(region[0])
        pad = 0.15 * (a[:, 0].max() - a[:, 0].min())
        ax.set_ylim(a[:, 0].min() - pad, a[:, 0].max() + pad)
        ax.set_xlim(a[:, 1].min() - pad / np.cos(np.radians(a[:, 0].mean())),
                    a[:, 1].max() + pad / np.cos(np.radians(a[:, 0].mean())))
    lat0 = np.mean(ax.get_ylim())
    ax.set_aspect(1.0 / np.cos(np.radians(lat0)))  # a degree of longitude is shorter
    ax.set_xlabel("longitude (deg E)")
    ax.set_ylabel("latitude (deg N)")
    ax.set_title(title or f"{peer}: {len(lines)} fused track ids over the true paths (grey)",
                 fontsize=9)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out)
    plt.close(fig)
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m sensornet.view_map_figure",
                                 description=__doc__.split("\n\n")[0])
    ap.add_argument("recording", help="a view's .rrd (a run's recording.rrd)")
    ap.add_argument("--peer", help="whose fused tracks (default: the first on the map)")
    ap.add_argument("--out", default="map.png")
    ap.add_argument("--title")
    a = ap.parse_args(argv)
    try:
        rec = read_map(Path(a.recording))
        peer = a.peer or (rec.peers() or [""])[0]
        path = plot_map(rec, peer, Path(a.out), a.title)
    except (OSError, ValueError) as exc:
        print(f"view_map_figure: {exc}", file=sys.stderr)
        return 2
    print(path)
    return 0


if __name__ == "__main__":
    sys.exit(main())
