"""Single-target PDA peers (seed 003): a :class:`peers.contracts.LocalEstimator` running a
(fuzzy) IMM-PDAF on this peer's sensor, and a :class:`peers.contracts.Fuser` that fuses the
neighbours' posteriors by covariance intersection (estimate sharing).

Covariance intersection (Julier & Uhlmann 1997) of Gaussians ``(x_i, P_i)``:
``P^-1 = sum_i w_i P_i^-1``, ``x = P sum_i w_i P_i^-1 x_i``, ``sum w_i = 1``; consistent
whatever the (unknown) correlation between the inputs, which feedback of the fused estimate
into every peer's filter creates. With two inputs ``w`` minimises ``log det P`` (the usual
choice, ``omega="det"``); otherwise the consensus weights are used.

Measurement sharing (each peer applies every peer's returns in a fixed sensor order, the
paper's sequential scheme, :func:`sim.studies.seed003.montecarlo.run_filter` with two sensors) is
the pair
:class:`SequentialPdaEstimator` / :class:`SequentialFuser`: a peer predicts, publishes the
returns of its own scan that fall in a wide pre-gate (``pregate`` times the gate threshold, on
the union of the models' gates) in the consensus slot ``"returns"``, and, once every peer's
returns are in (or at the deadline), runs the PDA update sensor by sensor in the fixed order on
its own filter. With identical initial states every peer then holds the same estimate. A
sensor whose returns did not arrive in time is left out of that scan (the update falls back to
the sensors that did), and counted.

On the wire a return set is a :class:`~protocol.messages.Returns` message: the returns
``(m, 2)`` alone, 16 bytes each (the sensor is the sender's, its noise ``R`` the scenario's).
It replaced a mixture of the state's dimension (one unit-weight component per return, the
noise in the position block: 224 bytes a return in 6-D), which cost a peer ~6.5 MB per 100
scans.
"""

from __future__ import annotations

import copy
from collections import Counter
from collections.abc import Mapping, Sequence

import numpy as np
from scipy.optimize import minimize_scalar
from sensornet.peers.contracts import FusionInput, LocalOutput
from sensornet.tracking.mixture import GaussianMixture
from sensornet.tracking.pda import ImmPda, LinearSensor, SensorUpdate, _quadratic_form


def covariance_intersection(means: np.ndarray, covs: np.ndarray,
                            weights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """CI of ``means (n, d)``, ``covs (n, d, d)`` with ``weights (n,)``: ``(x (d,), P (d, d))``."""
    info = np.linalg.inv(covs)
    Y = np.einsum("n,nij->ij", weights, info)
    P = np.linalg.inv(Y)
    x = P @ np.einsum("n,nij,nj->i", weights, info, means)
    return x, 0.5 * (P + P.T)


def ci_det_weight(means: np.ndarray, covs: np.ndarray) -> float:
    """The weight ``w`` of input 0 (``1 - w`` of input 1) minimising ``log det`` of the CI."""
    info = np.linalg.inv(covs)

    def cost(w: float) -> float:
        return -float(np.linalg.slogdet(w * info[0] + (1 - w) * info[1])[1])

    return float(minimize_scalar(cost, bounds=(0.0, 1.0), method="bounded",
                                 options={"xatol": 1e-4}).x)


def _single(x: np.ndarray, P: np.ndarray) -> GaussianMixture:
    return GaussianMixture(np.ones(1), x[None], P[None])


class PdaEstimator:
    """A (fuzzy) IMM-PDAF on one sensor; publishes its moment-matched posterior (one
    Gaussian). With ``feedback`` the fused density becomes the next scan's prior."""

    kinds = ("posterior",)

    def __init__(self, filt: ImmPda, sensor: LinearSensor, position_index: tuple[int, int],
                 feedback: bool = True) -> None:
        self.filter = filt
        self.sensor = sensor
        self.dim = filt.x.shape[1]
        self.position_index = position_index
        self.feedback = feedback

    def step(self, steps: int, z: np.ndarray) -> LocalOutput:
        self.filter.predict(steps)
        up = self.filter.update(self.sensor, np.asarray(z, float).reshape(-1, 2))
        self.last_update = up
        x, P = self.filter.estimate()
        mix = _single(x, P)
        return LocalOutput(mix, {"posterior": mix},
                           {"gated": float(len(up.returns)), "beta0": up.beta0})

    def predict(self, mix: GaussianMixture, steps: int) -> GaussianMixture:
        return mix  # single-target peers fuse only estimates of the same scan

    def extract(self, mix: GaussianMixture) -> np.ndarray:
        return (mix.weights @ mix.means)[None, :] / max(float(mix.weights.sum()), 1e-300)

    def adopt(self, fused: GaussianMixture) -> None:
        if self.feedback and len(fused) == 1:
            self.filter.adopt(fused.means[0], fused.covs[0])

    def pda_view(self) -> dict | None:
        """This sensor's last update for the Rerun view (see :func:`pda_view`)."""
        up = getattr(self, "last_update", None)
        return None if up is None else pda_view(self.filter, {"own": self.sensor}, {"own": up})


class CiFuser:
    """Covariance intersection of this peer's posterior with its neighbours' (one round)."""

    kinds = ("posterior",)
    max_rounds = 1

    def __init__(self, omega: str = "det") -> None:
        if omega not in ("det", "consensus"):
            raise ValueError(f"CI weight {omega!r}: expected 'det' or 'consensus'")
        self.omega = omega
        self.counts: Counter = Counter()

    def fuse(self, inp: FusionInput) -> GaussianMixture:
        mixes = [inp.own] + [inp.neighbours[s]["posterior"] for s in sorted(inp.neighbours)]
        if len(mixes) == 1:
            return inp.own
        means = np.stack([m.means[0] for m in mixes])
        covs = np.stack([m.covs[0] for m in mixes])
        if self.omega == "det" and len(mixes) == 2:
            w0 = ci_det_weight(means, covs)
            w = np.array([w0, 1.0 - w0])
        else:
            w = np.asarray(inp.weights, float)
        x, P = covariance_intersection(means, covs, w)
        if not (np.all(np.isfinite(x)) and np.all(np.isfinite(P))):
            self.counts["fusion_fallbacks"] += 1
            return inp.own
        return _single(x, P)


# -- measurement sharing ------------------------------------------------------------------------


class SequentialPdaEstimator:
    """Measurement sharing: a (fuzzy) IMM-PDAF that every peer runs on every sensor's returns
    in the fixed order ``order`` (this peer's sensor is ``own``).

    :meth:`step` predicts and publishes this peer's pre-gated returns (kind ``"returns"``);
    its local density (for the local score and display) is this sensor's update alone, on a
    copy of the filter. :meth:`apply` (called by :class:`SequentialFuser`) runs the updates.
    """

    kinds = ("returns",)

    def __init__(self, filt: ImmPda, sensors: Mapping[str, LinearSensor], order: Sequence[str],
                 own: str, position_index: tuple[int, int], pregate: float = 4.0) -> None:
        if own not in order or set(order) != set(sensors):
            raise ValueError(f"sequential PDA: own sensor {own!r} and order {list(order)} "
                             f"must name the sensors {sorted(sensors)}")
        if pregate < 1.0:
            raise ValueError(f"sequential PDA: pregate {pregate} must be >= 1")
        self.filter = filt
        self.sensors = dict(sensors)
        self.order = tuple(order)
        self.own = own
        self.dim = filt.x.shape[1]
        self.position_index = position_index
        self.pregate = float(pregate)
        self.own_returns = np.zeros((0, 2))
        self.last_updates: dict[str, SensorUpdate] = {}
        self.counts: Counter = Counter()

    def gate(self, Z: np.ndarray) -> np.ndarray:
        """The rows of ``Z`` inside ``pregate`` x the gate of any model (after predicting)."""
        s = self.sensors[self.own]
        f = self.filter
        zhat = f.x @ s.H.T
        S = s.H @ f.P @ s.H.T + s.R
        g = _quadratic_form(Z[None] - zhat[:, None], np.linalg.inv(S))
        return Z[(g < self.pregate * s.gamma).any(axis=0)]

    def step(self, steps: int, z: np.ndarray) -> LocalOutput:
        self.filter.predict(steps)
        Z = np.asarray(z, float).reshape(-1, 2)
        self.own_returns = self.gate(Z)
        solo = copy.copy(self.filter)  # update replaces x, P, probs; only the detector mutates
        solo.weighting = copy.deepcopy(self.filter.weighting)
        up = solo.update(self.sensors[self.own], self.own_returns)
        local = _single(*solo.estimate())
        return LocalOutput(local, {"posterior": local, "returns": self.own_returns},
                           {"returns": float(len(Z)), "published": float(len(self.own_returns)),
                            "gated": float(len(up.returns))})

    def apply(self, returns: Mapping[str, np.ndarray]) -> GaussianMixture:
        """Update with each sensor's returns in the fixed order (absent sensors skipped)."""
        self.last_updates = {}
        for name in self.order:
            Z = returns.get(name)
            if Z is not None:
                self.last_updates[name] = self.filter.update(self.sensors[name], Z)
        return _single(*self.filter.estimate())

    def predict(self, mix: GaussianMixture, steps: int) -> GaussianMixture:
        return mix

    def extract(self, mix: GaussianMixture) -> np.ndarray:
        return (mix.weights @ mix.means)[None, :] / max(float(mix.weights.sum()), 1e-300)

    def adopt(self, fused: GaussianMixture) -> None:
        pass  # the filter itself ran the sequential update

    def pda_view(self) -> dict | None:
        """The last sequential update for the Rerun view: per sensor the gate (``zhat``,
        ``S``, ``gamma``) and the validated returns with their weights; the detector's
        ``D_L`` and threshold (fuzzy filters)."""
        return pda_view(self.filter, self.sensors, self.last_updates)


def pda_view(filt: ImmPda, sensors: Mapping[str, LinearSensor],
             updates: Mapping[str, SensorUpdate]) -> dict | None:
    """What the Rerun view draws of a PDA filter's last updates (see
    :meth:`SequentialPdaEstimator.pda_view`)."""
    if not updates:
        return None
    view: dict = {"sensors": {n: {"zhat": u.zhat, "S": u.S, "gamma": sensors[n].gamma,
                                  "returns": u.returns, "weights": u.weights}
                              for n, u in updates.items()}}
    w = filt.weighting
    if w is not None:
        d, dof = w.detector.statistic
        view["detector"] = (d, w.detector.threshold(dof) if dof else float("nan"))
    return view


class SequentialFuser:
    """Measurement sharing's "fusion": the sequential PDA update with every sensor's returns
    that arrived (one round). A scan missing some sensor's returns (late, lost, its peer gone)
    falls back to the others; counted per missing sensor (``missing_<name>``), in
    ``fallbacks``, and the first such scan in ``first_fallback_scan``."""

    kinds = ("returns",)
    max_rounds = 1

    def __init__(self, estimator: SequentialPdaEstimator) -> None:
        self.estimator = estimator
        self.counts: Counter = Counter()

    def fuse(self, inp: FusionInput) -> GaussianMixture:
        est = self.estimator
        got = {est.own: est.own_returns}
        for s, kinds in inp.neighbours.items():
            if s in est.sensors:
                got[s] = np.asarray(kinds["returns"], float).reshape(-1, 2)
        missing = [s for s in est.order if s not in got]
        for s in missing:
            self.counts[f"missing_{s}"] += 1
        if missing:
            self.counts["fallbacks"] += 1
            self.counts.setdefault("first_fallback_scan", inp.k)
        self.counts["scans"] += 1
        return est.apply(got)
