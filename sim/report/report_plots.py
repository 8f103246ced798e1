"""Plot helpers the campaign report and the studies' report hooks share."""

from __future__ import annotations

import math
from typing import Any

import numpy as np


def series(rows: list, K: int | None = None) -> np.ndarray:
    """Runs x scans from a list of per-run lists (None rows dropped)."""
    rows = [r for r in rows if r is not None]
    if not rows:
        return np.zeros((0, K or 0))
    return np.array(rows, dtype=float)


def plt_module():
    """``matplotlib.pyplot`` on the Agg backend (files, no display): the one place the
    project's figures load it."""
    # heavy dependency: matplotlib (commands that draw nothing never load it)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # heavy dependency: matplotlib, as above

    return plt


def methods(data: dict[str, Any], prefix: str) -> list[str]:
    return [c[len(prefix):] for c in data if c.startswith(prefix)]


def band(ax, k, s: np.ndarray, label: str, lo: float | None = None, hi: float | None = None,
         **kw) -> None:
    """Mean line and 95 % Student-t band over runs, the band clipped to ``[lo, hi]``: a metric
    that cannot leave that range (OSPA: 0 to its cut-off) is not drawn outside it."""
    mean = np.nanmean(s, axis=0)
    line, = ax.plot(k, mean, label=label, **kw)
    if len(s) > 1:
        # heavy dependency: scipy.stats (a campaign's workers draw nothing and never load it)
        from scipy.stats import t

        half = t.ppf(0.975, len(s) - 1) * np.nanstd(s, axis=0, ddof=1) / math.sqrt(len(s))
        low, high = mean - half, mean + half
        if lo is not None or hi is not None:
            low, high = np.clip(low, lo, hi), np.clip(high, lo, hi)
        ax.fill_between(k, low, high, color=line.get_color(), alpha=0.2, lw=0)


UNITS = (("gospa", "m"), ("ospa", "m"), ("rmse", "m"), ("latency_ms", "ms"), ("_ms", "ms"),
         ("seconds", "s"), ("bytes", "B"), ("tuples", "tuples per peer per scan"))
"""Units of metric columns by a part of their name (first match)."""


def axis_label(name: str) -> str:
    """A metric column's name with its unit, e.g. ``fused_ospa (m)``; the name alone if its
    unit is not known."""
    for part, unit in UNITS:
        if part in name:
            return f"{name} ({unit})"
    return name
