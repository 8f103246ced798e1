"""Cut the shipped real-traffic excerpt from the full recording, reproducibly (issue 34).

    python -m sensornet.sim.traffic.excerpt /work/shared/data/adsb/quickstart.json.gz \\
        sim/traffic/data/paris_excerpt.json.gz

The defaults are the shipped excerpt: the 15 minutes from 14:00 UTC on 7 October 2021 (the
busiest quarter hour of the recording near Paris), the reports within 70 km of a point midway
between Paris-Charles de Gaulle and Paris-Orly, reports repeating their aircraft's previous
position dropped (stale: see ``opensky.trajectories``), then one report per aircraft per
``every_s`` seconds (the first of each bin). The records keep their recorded fields and values,
the output is written with sorted keys and a zero gzip time stamp, so the same input gives the
same bytes. The attribution (``ATTRIBUTION.md`` beside the excerpt) is the data README's.
"""

from __future__ import annotations

import argparse
import gzip
import json
from pathlib import Path

import numpy as np
from pymap3d import vincenty
from sensornet.sim.traffic.opensky import to_epoch

CENTRE = (48.868, 2.456)
"""Midway between CDG (49.0097 N, 2.5479 E) and Orly (48.7262 N, 2.3652 E)."""
RADIUS_M = 70_000.0
START = "2021-10-07T14:00:00+00:00"
END = "2021-10-07T14:15:00+00:00"
EVERY_S = 2.0
EXCERPT = Path(__file__).resolve().parent / "data" / "paris_excerpt.json.gz"
"""The shipped excerpt."""


def cut(records: list[dict], *, start: float | str = START, end: float | str = END,
        centre: tuple[float, float] = CENTRE, radius_m: float = RADIUS_M,
        every_s: float = EVERY_S) -> list[dict]:
    """The records (``traffic``'s JSON form, ``timestamp`` in ms) inside the window and radius,
    stale repeats dropped, one per aircraft per ``every_s`` seconds; sorted by time, icao24."""
    t = np.array([r["timestamp"] for r in records], dtype=float) / 1000.0
    icao = np.array([r["icao24"] for r in records])
    lat = np.array([np.nan if r["latitude"] is None else r["latitude"] for r in records])
    lon = np.array([np.nan if r["longitude"] is None else r["longitude"] for r in records])
    keep = (t >= to_epoch(start, "start")) & (t < to_epoch(end, "end")) & np.isfinite(lat + lon)
    idx = np.flatnonzero(keep)
    dist, _ = vincenty.vdist(centre[0], centre[1], lat[idx], lon[idx])
    idx = idx[np.atleast_1d(dist) <= radius_m]
    idx = idx[np.lexsort((t[idx], icao[idx]))]
    fresh = np.ones(len(idx), bool)
    fresh[1:] = ~((icao[idx][1:] == icao[idx][:-1]) & (lat[idx][1:] == lat[idx][:-1])
                  & (lon[idx][1:] == lon[idx][:-1]))
    idx = idx[fresh]
    bins = np.floor(t[idx] / every_s)
    first = np.ones(len(idx), bool)
    first[1:] = (icao[idx][1:] != icao[idx][:-1]) | (bins[1:] != bins[:-1])
    idx = idx[first]
    idx = idx[np.lexsort((icao[idx], t[idx]))]
    return [records[i] for i in idx]


def write(records: list[dict], path: Path) -> None:
    """Gzipped JSON, sorted keys, no name or time in the gzip header (same records, same bytes)."""
    text = json.dumps(records, sort_keys=True, separators=(",", ":")).encode()
    with open(path, "wb") as raw, gzip.GzipFile(filename="", fileobj=raw, mode="wb", mtime=0) as f:
        f.write(text)


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("source", type=Path, help="the full recording (gzipped JSON)")
    p.add_argument("out", type=Path, nargs="?", default=EXCERPT)
    p.add_argument("--start", default=START)
    p.add_argument("--end", default=END)
    p.add_argument("--lat", type=float, default=CENTRE[0])
    p.add_argument("--lon", type=float, default=CENTRE[1])
    p.add_argument("--radius-m", type=float, default=RADIUS_M)
    p.add_argument("--every-s", type=float, default=EVERY_S)
    a = p.parse_args(argv)
    with gzip.open(a.source, "rt", encoding="utf-8") as f:
        records = json.load(f)
    out = cut(records, start=a.start, end=a.end, centre=(a.lat, a.lon), radius_m=a.radius_m,
              every_s=a.every_s)
    a.out.parent.mkdir(parents=True, exist_ok=True)
    write(out, a.out)
    n = len({r["icao24"] for r in out})
    print(f"{a.out}: {len(out)} reports of {n} aircraft, {a.out.stat().st_size} bytes")


if __name__ == "__main__":
    main()
