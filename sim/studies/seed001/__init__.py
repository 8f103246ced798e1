"""Seed 001's reproduction: two radars, one manoeuvring target, IMM peers (docs/seed001.md):
the model (:mod:`.model`), the GCI weight tuning (:mod:`.tuning`), the Monte Carlo
(:mod:`.montecarlo`) and the study (:mod:`.study`)."""
