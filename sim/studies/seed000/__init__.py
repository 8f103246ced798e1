"""Seed 000's reproduction: local vs fused vs centralised GM-PHD, offline Monte Carlo
(:mod:`.montecarlo`), as the ``experiment`` study (:mod:`.study`)."""
