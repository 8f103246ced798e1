"""Chi-square quantiles from :mod:`scipy.special` (what gates and detectors need).

``scipy.stats`` costs about 2 s to import on these machines, paid by every peer and world
process that only needs ``chi2.ppf``/``chi2.isf``; the regularised incomplete gamma
inverses give the same quantiles: for ``X ~ chi2(k)``, ``P(X <= x) = P(k/2, x/2)``.
"""

from __future__ import annotations

from scipy.special import gammainccinv, gammaincinv


def chi2_ppf(p: float, dof: float) -> float:
    """``x`` with ``P(X <= x) = p`` for ``X ~ chi2(dof)`` (``scipy.stats.chi2.ppf``)."""
    if not 0.0 <= p <= 1.0 or not dof > 0:
        raise ValueError(f"chi2 quantile needs 0 <= p <= 1 and dof > 0, got p={p}, dof={dof}")
    return float(2.0 * gammaincinv(0.5 * dof, p))


def chi2_isf(q: float, dof: float) -> float:
    """``x`` with ``P(X > x) = q`` for ``X ~ chi2(dof)`` (``scipy.stats.chi2.isf``)."""
    if not 0.0 <= q <= 1.0 or not dof > 0:
        raise ValueError(f"chi2 quantile needs 0 <= q <= 1 and dof > 0, got q={q}, dof={dof}")
    return float(2.0 * gammainccinv(0.5 * dof, q))
