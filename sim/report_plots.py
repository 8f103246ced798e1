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
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def methods(data: dict[str, Any], prefix: str) -> list[str]:
    return [c[len(prefix):] for c in data if c.startswith(prefix)]


def band(ax, k, s: np.ndarray, label: str, **kw) -> None:
    mean = np.nanmean(s, axis=0)
    line, = ax.plot(k, mean, label=label, **kw)
    if len(s) > 1:
        from scipy.stats import t

        half = t.ppf(0.975, len(s) - 1) * np.nanstd(s, axis=0, ddof=1) / math.sqrt(len(s))
        ax.fill_between(k, mean - half, mean + half, color=line.get_color(), alpha=0.2, lw=0)
