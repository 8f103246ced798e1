"""Seed 003's peer modes as a study: local, CI, CI + feedback and sequential, on the peers' own
parts, offline (:mod:`sim.studies.seed003.peers`); ``python -m
sensornet.sim.studies.seed003.peers`` (:func:`main`).
It reads no scenario of its own (the shipped ``seed003`` file with the world's region clutter),
so ``sensornet experiment`` never picks it."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from sensornet.sim.scenario import ScenarioError, parse_overrides
from sensornet.sim.studies import command
from sensornet.sim.studies.base import Outcome, Request, Study
from sensornet.sim.studies.seed003 import montecarlo as seed003
from sensornet.sim.studies.seed003 import peers as seed003_peers


@dataclass(frozen=True)
class Setup:
    """The seed-003 settings (region clutter) and the filter every peer runs."""

    cfg: dict
    method: str = "IMM-PDAF"


def load(req: Request) -> list[Setup]:
    """The shipped ``seed003`` file with ``clutter.mode = "region"`` and the overrides; option
    ``method``: one of :data:`sim.studies.seed003.montecarlo.METHODS`."""
    method = req.options.get("method") or "IMM-PDAF"
    if method not in seed003.METHODS:
        raise ScenarioError(f"method {method!r}: expected one of {', '.join(seed003.METHODS)}")
    try:
        cfg = seed003.load(overrides={"clutter.mode": "region", **req.overrides})
    except (ValueError, OSError) as exc:
        raise ScenarioError(str(exc)) from None
    return [Setup(cfg, method)]


def run_once(s: Setup, run: int) -> dict[str, Any]:
    return seed003_peers.run_once(s.cfg, run, s.method)


def summarise(s: Setup, results: list) -> list[dict]:
    return seed003_peers.summarise(s.cfg, results)


def table(o: Outcome) -> str:
    return (seed003_peers.format_table(o.summary) + f"\n({o.setup.method}, {len(o.runs)} runs "
            f"from {o.runs.start}, region clutter, {o.seconds:.0f} s)")


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m sensornet.sim.studies.seed003.peers --runs 200 --jobs 2``: the peer modes'
    table."""
    p = command.parser("seed003_peers", seed003_peers.__doc__, runs=200,
                       set_help="override a setting of the seed003 file (TOML value)",
                       module="sensornet.sim.studies.seed003.peers")
    p.add_argument("--method", default="IMM-PDAF", choices=seed003.METHODS)
    a = p.parse_args(argv)
    try:
        req = command.request(a, "seed003", parse_overrides(a.set), method=a.method)
    except ScenarioError as exc:
        return command.fail("seed003_peers", exc)
    return command.drive(STUDY, req)


STUDY = Study(
    name="seed003-peers",
    about="seed 003 peer modes: local, CI, CI + feedback, sequential (offline, region clutter)",
    load=load, run_once=run_once, summarise=summarise, table=table, command=main)
