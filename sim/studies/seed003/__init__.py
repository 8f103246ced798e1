"""Seed 003's reproduction (docs/seed003.md): the PDA-family Monte Carlo (:mod:`.montecarlo`,
study ``seed003``), the peer modes offline (:mod:`.peers`, study ``seed003-peers``) and the
network scenario of the study's file (:mod:`.network`). Its world is :mod:`sim.world.seed003`,
its peers the ``pda`` kind (:mod:`sim.kinds.pda`)."""
