"""Labelled centralised references (issue 33 item 6): every sensor's scans through one filter.

Both are iterated correctors (Mahler's multi-sensor corrector applied sensor by sensor, as the
centralised GM-PHD of :mod:`sim.studies.seed000.montecarlo`): predict once per scan, then
correct with each sensor's scan in the scenario's sensor order.

* :class:`CentralLmb`: one LMB (:class:`tracking.lmb.LmbFilter`, Reuter et al. 2014), one
  ``LmbFilter`` per sensor (its sensor model, ``Pd``, ``kappa``) sharing one label space
  (origin 0). Confirmation counts a scan once (after its last corrector), as a peer's does.
  Adaptive births (linear sensors): ``births="every"`` queues the births of every sensor's
  unexplained measurements with ``lambda_B`` split evenly over the sensors; ``"first"`` queues
  the first sensor's only, at the full ``lambda_B`` (chosen on training runs: docs/
  labelled-tracking.md). Fixed births (range-bearing sensors) come from the first filter.
* :class:`CentralGmphd`: the GM-PHD with tags (:class:`tracking.labels.LabelledGMPHD` over
  :func:`sim.world.build.make_filter` of every sensor: the same numbers as the unlabelled
  centralised filter) and the peers' confirmation rule (:class:`tracking.labels.Confirmation`).

Output per scan, as peers report tracks: :class:`Extracted` (states ``(p, d)``, labels
``(p, 3)`` int64, status ``(p,)`` int8).
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from sensornet.peers.consensus_types import ConsensusOptions
from sensornet.sim.kinds.lmb import make_lmb_filter
from sensornet.sim.scenario import Scenario
from sensornet.sim.world.build import make_filter
from sensornet.tracking.labels import Confirmation, LabelledGMPHD, LabelledMixture, label_keys
from sensornet.tracking.lmb import LmbFilter, LmbState
from sensornet.tracking.mixture import GaussianMixture

BIRTH_RULES = ("every", "first")


@dataclass(frozen=True)
class Extracted:
    """One scan's tracks: ``states (p, d)``, ``labels (p, 3)`` int64, ``status (p,)`` int8
    (1 confirmed, 0 tentative)."""

    states: np.ndarray
    labels: np.ndarray
    status: np.ndarray


@dataclass
class CentralLmb:
    """An iterated-corrector LMB over several sensors (module docstring). ``filters``: one per
    sensor, in corrector order; the first predicts (its motion, ``Ps``, fixed births)."""

    filters: Sequence[LmbFilter]
    births: str = "first"

    def __post_init__(self) -> None:
        if not self.filters:
            raise ValueError("CentralLmb needs at least one sensor's filter")
        if self.births not in BIRTH_RULES:
            raise ValueError(f"CentralLmb.births must be one of {BIRTH_RULES}, "
                             f"got {self.births!r}")
        if len({f.origin for f in self.filters}) != 1:
            raise ValueError("CentralLmb's filters must share one label origin")
        n = len(self.filters)
        if self.births == "every" and n > 1:  # lambda_B split over the sensors
            self.filters = [dataclasses.replace(f, birth_rate=f.birth_rate / n)
                            for f in self.filters]
        else:
            self.filters = list(self.filters)

    def initial(self) -> LmbState:
        return self.filters[0].initial()

    def step(self, state: LmbState, scans: Sequence[np.ndarray], k: int | None = None
             ) -> LmbState:
        """Predict to scan ``k`` (default the next), correct with ``scans[i] (m_i, dz)`` in
        sensor order; hits counted once, after the last corrector."""
        if len(scans) != len(self.filters):
            raise ValueError(f"expected {len(self.filters)} scans, got {len(scans)}")
        pred = self.filters[0].predict(state, k)
        st = pred
        pending = []
        for i, (f, z) in enumerate(zip(self.filters, scans, strict=True)):
            st = f.correct(LmbState(st.tracks, pred.hits if i == 0 else st.hits, st.k,
                                    st.pending), z)
            if self.births == "every" or i == 0:
                pending.append(st.pending)
        # correct() only drops tracks (in order): the survivors' hits from the prediction,
        # plus one if r reached the confirmation level after the last corrector
        rows = np.flatnonzero(np.isin(label_keys(pred.tracks.labels),
                                      label_keys(st.tracks.labels)))
        hits = pred.hits[rows] + (st.tracks.existence >= self.filters[-1].confirm_existence)
        return LmbState(st.tracks, hits.astype(np.int64), st.k,
                        GaussianMixture.concatenate(pending) if pending
                        else GaussianMixture.empty(self.filters[0].motion.dim))

    def extract(self, state: LmbState) -> Extracted:
        tr = self.filters[0].extract(state)
        return Extracted(tr.states, tr.labels, tr.status)


@dataclass
class CentralGmphd:
    """The centralised GM-PHD with tags and the peers' confirmation rule."""

    filter: LabelledGMPHD
    confirmation: Confirmation

    def initial(self) -> LabelledMixture:
        return self.filter.initial()

    def step(self, lm: LabelledMixture, scans: Sequence[np.ndarray], k: int
             ) -> LabelledMixture:
        lm = self.filter.step(lm, k, *scans)
        self.confirmation.observe(lm)
        return lm

    def extract(self, lm: LabelledMixture) -> Extracted:
        states, labels = self.filter.extract(lm)
        return Extracted(states, labels, self.confirmation.status(labels))


def central_lmb(scn: Scenario, births: str = "first") -> CentralLmb:
    """The centralised LMB of a scenario: each sensor's LMB filter as the ``lmb`` peer kind
    builds it (:func:`sim.kinds.lmb.make_lmb_filter`), one label origin (0)."""
    return CentralLmb([make_lmb_filter(scn, s.name, 0) for s in scn.sensors], births)


def central_gmphd(scn: Scenario) -> CentralGmphd:
    """The centralised GM-PHD with tags of a scenario (its peers' confirmation scans)."""
    f = make_filter(scn, scn.sensor_names)
    return CentralGmphd(LabelledGMPHD(f, origin=0),
                        Confirmation(ConsensusOptions.confirm_scans))


def run_central(central: CentralLmb | CentralGmphd, scans: Sequence[Sequence[np.ndarray]]
                ) -> tuple[list[Extracted], float]:
    """Every scan through ``central``: ``scans[s][k-1]`` is sensor ``s``'s scan ``k``.
    Returns the tracks per scan (index ``k - 1``) and the CPU seconds the filter took."""
    K = len(scans[0])
    state = central.initial()
    out = []
    c0 = time.process_time()
    for k in range(1, K + 1):
        state = central.step(state, [s[k - 1] for s in scans], k)
        out.append(central.extract(state))
    return out, time.process_time() - c0
