"""The fusion-quality study (:mod:`sim.studies.fusion.quality`): a campaign file with a ``[study]``
table
of ``kind = "fusion-quality"`` expands into twin and experiment cells."""

from __future__ import annotations

from sensornet.sim.studies.base import Study
from sensornet.sim.studies.fusion import quality as fs

STUDY = Study(name=fs.STUDY_KIND,
              about="which fusion rule, how many rounds, on which network (a campaign)",
              expand=fs.study_campaign)
