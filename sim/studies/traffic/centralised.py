"""The centralised GM-PHD with tags for measurement-driven birth (issue 34): every radar's
scans through one :class:`sim.world.birth.MeasurementBirthGMPHD` (the iterated corrector of
:func:`sim.world.build.make_filter` over all sensors, each radar's beam-aware ``Pd``), its
components labelled by Panta, Clark & Vo's tag rules (2009, Sec. IV): survivors keep their
labels, the births that enter at a prediction get ``(0, k, i)``, every posterior component
inherits its parent's label (``correct_parents``), then the duplicate rule
(:func:`tracking.labels.split_duplicates`); confirmation as the peers'
(:class:`tracking.labels.Confirmation`).

:func:`sim.studies.labelled.centralised.central_gmphd` wraps
:class:`tracking.labels.LabelledGMPHD`, whose predictions add the scenario's fixed birth
components only; the measurement births live in the filter (``pending``), hence this one.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from sensornet.peers.consensus_types import ConsensusOptions
from sensornet.sim.scenario import Scenario
from sensornet.sim.studies.labelled.centralised import Extracted
from sensornet.sim.world.birth import MeasurementBirthGMPHD
from sensornet.sim.world.build import make_filter
from sensornet.tracking.labels import (
    Confirmation,
    LabelledMixture,
    extract_labelled,
    new_labels,
    split_duplicates,
)


@dataclass
class CentralMeasurementGmphd:
    """One labelled measurement-birth GM-PHD over every sensor (module docstring)."""

    filter: MeasurementBirthGMPHD
    confirmation: Confirmation

    def initial(self) -> LabelledMixture:
        return LabelledMixture.empty(self.filter.motion.dim)

    def step(self, lm: LabelledMixture, scans: Sequence[np.ndarray], k: int
             ) -> LabelledMixture:
        """Predict to scan ``k`` (one step), correct with ``scans[i] (m_i, dz)`` in sensor
        order."""
        f = self.filter
        pred = f.predict(lm.mixture, 1)  # survivors in order, then the births
        nb = len(pred) - len(lm)
        labels = np.concatenate((lm.labels, new_labels(0, k, nb)))
        mix, par = f.correct_parents(pred, scans)
        out = split_duplicates(LabelledMixture(mix, labels[par]), f.extraction_threshold, 0,
                               k, nb)
        self.confirmation.observe(out)
        return out

    def extract(self, lm: LabelledMixture) -> Extracted:
        states, labels = extract_labelled(lm, self.filter.extraction_threshold,
                                          self.filter.extraction)
        return Extracted(states, labels, self.confirmation.status(labels))


def central_measurement_gmphd(scn: Scenario) -> CentralMeasurementGmphd:
    """The scenario's centralised labelled GM-PHD (``birth.model = "measurements"``)."""
    f = make_filter(scn, scn.sensor_names)
    if not isinstance(f, MeasurementBirthGMPHD):
        raise ValueError(f"{scn.name}: central_measurement_gmphd needs birth.model "
                         f"'measurements', got {scn.birth.model!r}")
    return CentralMeasurementGmphd(f, Confirmation(ConsensusOptions.confirm_scans))
