"""Seed 002's reproduction: ET-GM-PHD partitioning (:mod:`.montecarlo`, :mod:`.study`)."""
