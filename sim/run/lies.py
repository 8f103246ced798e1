"""The lies of a member that lies about its own estimate (issue 24, docs/security.md): what each
does to the liar's real mixture, and a peer core that tells one in every estimate it sends.

Used by the lying study (:mod:`sim.studies.lying.study`) and by the test-only scenario key
``fusion.lie``
(:func:`sim.run.peers.make_peer`), so the twin, the study and a real process tell the same lie.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np
from sensornet.peers.core import Output, PeerCore
from sensornet.protocol.messages import Estimate
from sensornet.sim.scenario import Scenario
from sensornet.sim.scenario.common import LIE_KINDS, parse_lie
from sensornet.tracking.mixture import GaussianMixture

SHIFT = 110.0
"""Metres the ``shifted`` lie moves every component along x."""
TIGHT = 1.0
"""Variance (m^2, (m/s)^2) on the diagonal of the lies' covariances: confident."""
INFLATE = 5.0
"""The ``inflated`` lie's weight factor."""
BIAS = 30.0
"""Metres the ``biased`` sensor's estimates sit off along x (its covariance stays honest)."""
DRIFT_RATE = 2.0
"""Metres per scan by which the ``drift`` liar's offset along x grows (issue 36 item 4: a
sensor whose bias keeps growing, its covariance honest; :func:`drift_lie` for other rates)."""

Lie = Callable[[GaussianMixture, int], GaussianMixture]
"""``lie(mixture, k)``: what the liar tells for its real ``mixture`` in its estimate of scan
``k`` (only the ``drift`` lie uses ``k``)."""


def _tight(n: int, d: int) -> np.ndarray:
    return np.broadcast_to(TIGHT * np.eye(d), (n, d, d)).copy()


def phantom_positions(scn: Scenario) -> np.ndarray:
    """The ``phantoms`` lie's three fixed points: 10 % in from the region's top-left,
    top-right and bottom-left corners (far from every seed-000 and seed-004 track)."""
    (x0, x1), (y0, y1) = scn.region
    dx, dy = 0.1 * (x1 - x0), 0.1 * (y1 - y0)
    return np.array([[x0 + dx, y1 - dy], [x1 - dx, y1 - dy], [x0 + dx, y0 + dy]])


def make_lie(kind: str, scn: Scenario, position_index: tuple[int, int] = (0, 2)) -> Lie:
    """The function that turns the liar's real mixture into lie ``kind`` (:data:`LIES`;
    ``"drift:RATE"``: the drift lie at ``RATE`` m/scan, :data:`DRIFT_RATE` without one)."""
    kind, rate = parse_lie(kind)
    if kind == "drift":
        return drift_lie(DRIFT_RATE if rate is None else rate, position_index)
    ix, iy = position_index

    def empty(mix: GaussianMixture, k: int = 0) -> GaussianMixture:
        return GaussianMixture.empty(mix.dim)

    def shifted(mix: GaussianMixture, k: int = 0) -> GaussianMixture:
        means = mix.means.copy()
        means[:, ix] += SHIFT
        return GaussianMixture(mix.weights.copy(), means, _tight(len(mix), mix.dim))

    def inflated(mix: GaussianMixture, k: int = 0) -> GaussianMixture:
        return mix.scaled(INFLATE)

    def phantoms(mix: GaussianMixture, k: int = 0) -> GaussianMixture:
        pos = phantom_positions(scn)
        means = np.zeros((len(pos), mix.dim))
        means[:, ix], means[:, iy] = pos[:, 0], pos[:, 1]
        extra = GaussianMixture(np.ones(len(pos)), means, _tight(len(pos), mix.dim))
        return GaussianMixture.concatenate([mix, extra])

    def biased(mix: GaussianMixture, k: int = 0) -> GaussianMixture:
        means = mix.means.copy()
        means[:, ix] += BIAS
        return GaussianMixture(mix.weights.copy(), means, mix.covs.copy())

    held: list[GaussianMixture] = []

    def stuck(mix: GaussianMixture, k: int = 0) -> GaussianMixture:
        if not held and len(mix):
            held.append(mix.copy())
        return held[0].copy() if held else mix

    lies = {"empty": empty, "shifted": shifted, "inflated": inflated, "phantoms": phantoms,
            "biased": biased, "stuck": stuck}
    return lies[kind]


def drift_lie(rate: float, position_index: tuple[int, int] = (0, 2)) -> Lie:
    """The ``drift`` lie at ``rate`` metres per scan: every component's position moved
    ``rate * k`` metres along x at scan ``k`` (1-based: already ``rate`` off at the first),
    its covariance honest. A biased sensor whose bias keeps growing: each scan's offset is
    within an honest neighbour's scatter of the last one's, so a registration that takes it
    to be constant runs behind it. ``rate`` must be positive and finite."""
    if not (np.isfinite(rate) and rate > 0):
        raise ValueError(f"the drift lie's rate must be a positive number of metres per scan, "
                         f"got {rate!r}")
    ix = position_index[0]

    def drift(mix: GaussianMixture, k: int = 0) -> GaussianMixture:
        means = mix.means.copy()
        means[:, ix] += rate * k
        return GaussianMixture(mix.weights.copy(), means, mix.covs.copy())

    return drift


LIES = LIE_KINDS


class LyingCore(PeerCore):
    """A peer that publishes ``lie(its real mixture)`` in every estimate it sends (twin only).

    Built from a peer made by :func:`sim.run.peers.make_peer` (same parts, same settings); the lie
    is applied to each outgoing :class:`Estimate` before the core encodes it, so the bytes are
    as well-formed as an honest peer's. ``lies_told`` counts them.
    """

    def __init__(self, core: PeerCore, lie: Lie) -> None:
        super().__init__(core.cfg, core.consensus, core.scorer)
        self.lie = lie
        self.lies_told = 0

    def _wrap(self, messages: list) -> list[Output]:
        told = []
        for m in messages:
            if type(m) is Estimate:
                told_mix = self.lie(m.mixture, m.k)
                m = replace(m, mixture=told_mix, labels=told_labels(m.labels, len(told_mix)),
                            label_masks=None)  # holder words 1.. (past 39 peers) not told
                self.lies_told += 1
            told.append(m)
        return super()._wrap(told)


def told_labels(labels: np.ndarray | None, n: int) -> np.ndarray | None:
    """A liar's labels for the ``n`` rows it tells: its own rows keep theirs and rows a lie
    appends (padding, phantoms) carry label 0 ``(0, 0, 0)``, so the estimate stays well-formed
    (protocol 2 refuses a label array of another length); a lie that drops rows sends none."""
    if labels is None or n < len(labels):
        return None
    return np.concatenate([labels, np.zeros((n - len(labels), 3), np.int64)])
