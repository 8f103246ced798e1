"""Fuzzy association degrees and the Neyman-Pearson manoeuvre detector (seed 003 §3-4,
eq. 37-48; docs/seed003.md).

The fuzzy inference system (Wang's fuzzy basis functions, the paper's ref. [6]): rules
``R_r: IF y1 is A_r1 AND y2 is A_r2 THEN mu is B_r``, Gaussian input membership functions
``mu_A(y) = exp(-((y - c) / w)^2 / 2)``, singleton fuzzifier, product inference and
centre-of-gravity defuzzification over the output centres ``ybar_r`` (the points where
``mu_B_r`` is largest, eq. 49):

    mu(y1, y2) = sum_r ybar_r prod_i mu_A_ri(y_i) / sum_r prod_i mu_A_ri(y_i)

Inputs (eq. 47, 37): ``y1 = g_j = nu_j^T S^-1 nu_j`` (the return's NIS) and
``y2 = D_L(k) / (L n_z)``, the detector's window sum over its chi-square mean (1 with no
manoeuvre). The rule base and membership functions are a configuration (the ``[fuzzy]``
section of ``sim/scenarios/seed003.toml``); the paper trains them, we ship a fixed one
(**our reading**).

The detector (eq. 37-44, our reading of the lost formulas as in the issue): ``eps(k)`` is the
no-manoeuvre model's PDA-combined NIS ``nubar^T S^-1 nubar`` summed over the sensors of scan
``k``; ``D_L(k) = sum_{i=k-L+1..k} eps(i)``; with no manoeuvre and a matched filter
(no clutter) ``D_L ~ chi2(L n_z)``, so the Neyman-Pearson threshold for false-alarm rate
``pf`` is ``chi2.isf(pf, L n_z)``. In clutter the combined innovation is smaller than a
single return's, so the realised false-alarm rate is lower than ``pf`` (measured, not
assumed, in ``sim.studies.seed003.montecarlo``).

:class:`FuzzyWeighting` joins them into the :class:`tracking.pda.ReturnWeighting` the PDA
filters take: mode ``"switched"`` applies ``W_j = mu_j beta_j / c`` only while the detector
fires (the paper's "mu and beta switch by the target's motion state", §3), ``"always"``
applies it at every scan (eq. 34 literally).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from sensornet.tracking.chi2 import chi2_isf

WEIGHTING_MODES = ("switched", "always")


@dataclass(frozen=True)
class FuzzySystem:
    """Two-input product-inference fuzzy system with centre-of-gravity defuzzification."""

    centres: np.ndarray
    """(R, 2) input membership centres of each rule (y1 = NIS, y2 = D_L / (L n_z))."""
    widths: np.ndarray
    """(R, 2) input membership widths (Gaussian standard deviations), > 0."""
    outputs: np.ndarray
    """(R,) output centres ``ybar_r`` in [0, 1]."""

    def firing(self, y1: np.ndarray, y2: np.ndarray | float) -> np.ndarray:
        """Rule firing strengths ``(..., R)``: ``prod_i exp(-((y_i - c_ri) / w_ri)^2 / 2)``."""
        y = np.stack(np.broadcast_arrays(np.asarray(y1, float), np.asarray(y2, float)), -1)
        u = (y[..., None, :] - self.centres) / self.widths  # (..., R, 2)
        return np.exp(-0.5 * (u * u).sum(axis=-1))

    def __call__(self, y1: np.ndarray, y2: np.ndarray | float) -> np.ndarray:
        """Association degrees ``mu`` (broadcast shape of ``y1``, ``y2``)."""
        f = self.firing(y1, y2)
        return (f @ self.outputs) / np.maximum(f.sum(axis=-1), 1e-300)

    @classmethod
    def from_config(cls, cfg: Mapping) -> FuzzySystem:
        """From the ``[fuzzy]`` table: ``inputs.nis`` and ``inputs.dl`` map term names to
        ``[centre, width]``, ``outputs`` maps term names to centres, ``rules`` is a list of
        ``[nis_term, dl_term, output_term]``. A wrong name is reported in one line."""
        try:
            nis, dl = cfg["inputs"]["nis"], cfg["inputs"]["dl"]
            out, rules = cfg["outputs"], cfg["rules"]
        except KeyError as exc:
            raise ValueError(f"[fuzzy]: missing key {exc.args[0]!r}") from None
        centres, widths, ybar = [], [], []
        for r, rule in enumerate(rules):
            if len(rule) != 3:
                raise ValueError(f"[fuzzy] rule {r}: expected [nis_term, dl_term, output_term]")
            for table, term, what in ((nis, rule[0], "inputs.nis"), (dl, rule[1], "inputs.dl"),
                                      (out, rule[2], "outputs")):
                if term not in table:
                    raise ValueError(f"[fuzzy] rule {r}: unknown {what} term {term!r} "
                                     f"(have {sorted(table)})")
            centres.append((nis[rule[0]][0], dl[rule[1]][0]))
            widths.append((nis[rule[0]][1], dl[rule[1]][1]))
            ybar.append(out[rule[2]])
        w = np.asarray(widths, float)
        if (w <= 0).any():
            raise ValueError("[fuzzy]: membership widths must be > 0")
        return cls(np.asarray(centres, float), w, np.asarray(ybar, float))


@lru_cache(maxsize=1024)
def _chi2_isf(p: float, dof: int) -> float:
    return chi2_isf(p, dof)


class ManoeuvreDetector:
    """Neyman-Pearson test on the sliding innovation sum ``D_L`` (eq. 37-44).

    Each scan's bin sums the ``eps`` and degrees of freedom of its sensor updates; ``D_L`` sums
    the last ``window`` bins; the test fires when ``D_L > chi2.isf(false_alarm, dof)``.
    """

    def __init__(self, window: int, false_alarm: float) -> None:
        if window < 1 or not 0.0 < false_alarm < 1.0:
            raise ValueError(f"detector: window {window} must be >= 1 and false_alarm "
                             f"{false_alarm} in (0, 1)")
        self.window = int(window)
        self.false_alarm = float(false_alarm)
        self._bins: deque[list[float]] = deque(maxlen=self.window)

    def new_scan(self) -> None:
        self._bins.append([0.0, 0])

    def observe(self, eps: float, dof: int) -> None:
        if not self._bins:
            self.new_scan()
        self._bins[-1][0] += eps
        self._bins[-1][1] += dof

    @property
    def statistic(self) -> tuple[float, int]:
        """``(D_L, dof)`` over the window (fewer scans before the window fills)."""
        return (float(sum(b[0] for b in self._bins)), int(sum(b[1] for b in self._bins)))

    def threshold(self, dof: int) -> float:
        """``chi2.isf(false_alarm, dof)``: ``P(D_L > threshold | H0) = false_alarm``."""
        return _chi2_isf(self.false_alarm, int(dof)) if dof > 0 else np.inf

    @property
    def fired(self) -> bool:
        d, dof = self.statistic
        return dof > 0 and d > self.threshold(dof)


class FuzzyWeighting:
    """The fuzzy part of fuzzy PDA / fuzzy IMM: detector + fuzzy system -> degrees ``mu``."""

    def __init__(self, fis: FuzzySystem, detector: ManoeuvreDetector,
                 mode: str = "switched") -> None:
        if mode not in WEIGHTING_MODES:
            raise ValueError(f"fuzzy weighting: unknown mode {mode!r}; expected {WEIGHTING_MODES}")
        self.fis, self.detector, self.mode = fis, detector, mode
        self.fired_scans = 0
        self._fired_now = False

    def new_scan(self) -> None:
        self.detector.new_scan()
        self._fired_now = False

    def observe(self, nis: float, dof: int) -> None:
        self.detector.observe(nis, dof)

    def normalised_statistic(self) -> float:
        """``D_L / (L n_z)``: the second input (1 on average with no manoeuvre)."""
        d, dof = self.detector.statistic
        return d / dof if dof else 1.0

    def degrees(self, g: np.ndarray) -> np.ndarray | None:
        fired = self.detector.fired
        if fired and not self._fired_now:
            self.fired_scans += 1
            self._fired_now = True
        if self.mode == "switched" and not fired:
            return None
        return self.fis(g, self.normalised_statistic())


def fit(fis: FuzzySystem, g: np.ndarray, d: np.ndarray, target: np.ndarray,
        what: str = "all", max_samples: int = 20000,
        rng: np.random.Generator | None = None) -> FuzzySystem:
    """Fit the system to labelled returns (the trainable option; the paper trains by steepest
    descent, its ref. [5]): minimise the binary cross-entropy of ``mu(g, d)`` against
    ``target`` (1: the return is the target's) with bounded L-BFGS-B (outputs in [0.01, 0.99],
    NIS centres in [0, 20], D centres in [0, 10], widths in [0.3, 10]). ``what``:
    ``"outputs"`` fits the output centres only, ``"all"`` also the input centres and widths.
    At most ``max_samples`` returns (a random subset). Fit on training runs only
    (``sim.studies.seed003.montecarlo --train-fuzzy``), never on the runs a table reports."""
    # heavy dependency: scipy.optimize (only fitting needs it, not the fuzzy system's use)
    from scipy.optimize import minimize

    g, d, t = (np.asarray(a, float) for a in (g, d, target))
    if len(g) > max_samples:
        pick = (rng or np.random.default_rng(0)).choice(len(g), max_samples, replace=False)
        g, d, t = g[pick], d[pick], t[pick]
    R = len(fis.outputs)
    p0 = [np.clip(fis.outputs, 0.01, 0.99)]
    bounds = [(0.01, 0.99)] * R
    if what == "all":
        p0 += [fis.centres.ravel(), np.clip(fis.widths.ravel(), 0.3, 10.0)]
        bounds += [(0.0, 20.0), (0.0, 10.0)] * R + [(0.3, 10.0)] * (2 * R)
    elif what != "outputs":
        raise ValueError(f"fuzzy fit: {what!r}, expected 'outputs' or 'all'")

    def unpack(p: np.ndarray) -> FuzzySystem:
        if what == "outputs":
            return FuzzySystem(fis.centres, fis.widths, p[:R].copy())
        return FuzzySystem(p[R:3 * R].reshape(R, 2), p[3 * R:].reshape(R, 2), p[:R].copy())

    def loss(p: np.ndarray) -> float:
        mu = np.clip(unpack(p)(g, d), 1e-6, 1 - 1e-6)
        return float(-np.mean(t * np.log(mu) + (1 - t) * np.log(1 - mu)))

    res = minimize(loss, np.concatenate(p0), method="L-BFGS-B", bounds=bounds,
                   options={"maxiter": 200})
    return unpack(res.x)


def to_config(fis: FuzzySystem, mode: str = "switched") -> dict:
    """A ``[fuzzy]`` table for ``fis`` (one term per rule and input: fitted rules need not
    share terms)."""
    nis = {f"r{r}": [float(c), float(w)] for r, (c, w) in
           enumerate(zip(fis.centres[:, 0], fis.widths[:, 0], strict=True))}
    dl = {f"r{r}": [float(c), float(w)] for r, (c, w) in
          enumerate(zip(fis.centres[:, 1], fis.widths[:, 1], strict=True))}
    out = {f"r{r}": float(y) for r, y in enumerate(fis.outputs)}
    return {"mode": mode, "rules": [[f"r{r}"] * 3 for r in range(len(out))],
            "inputs": {"nis": nis, "dl": dl}, "outputs": out}


def weighting_from_config(cfg: Mapping, detector_cfg: Mapping) -> FuzzyWeighting:
    """A :class:`FuzzyWeighting` from the ``[fuzzy]`` and ``[detector]`` tables."""
    det = ManoeuvreDetector(int(detector_cfg.get("window", 5)),
                            float(detector_cfg.get("false_alarm", 0.01)))
    return FuzzyWeighting(FuzzySystem.from_config(cfg), det, str(cfg.get("mode", "switched")))


def rule_table(fis: FuzzySystem) -> Sequence[tuple[float, float, float]]:
    """``(nis centre, dl centre, output)`` per rule (for docs and the tests)."""
    return [(float(c[0]), float(c[1]), float(o))
            for c, o in zip(fis.centres, fis.outputs, strict=True)]
