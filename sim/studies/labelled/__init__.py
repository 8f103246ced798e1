"""Labelled tracking study (issue 33, docs/labelled-tracking.md): the labelled centralised
references (:mod:`.centralised`) and the local / fused / centralised table (:mod:`.study`)."""
