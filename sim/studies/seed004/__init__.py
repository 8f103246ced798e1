"""Seed 004's reproduction: measurement flooding against distributed GM-PHD filters
(docs/seed004.md): its scenario format (:mod:`.scenario`), the Monte Carlo (:mod:`.montecarlo`),
its outputs (:mod:`.output`) and the study (:mod:`.study`)."""
