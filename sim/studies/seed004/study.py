"""Seed 004's reproduction as a study: flooding with IDPC / FTC clustering against distributed
GM-PHD filters with GCI and AA consensus, IC, centralised and local
(:mod:`sim.studies.seed004.montecarlo`);
``sensornet experiment seed004`` (or a file named ``seed004.toml``), and ``python -m
sim.studies.seed004.montecarlo`` (:func:`main`: the same path, plus flooding under link loss and a
redraw)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from sensornet.peers.faultplan import FaultPlan, LinkFaults, Uniform
from sensornet.sim.scenario import ScenarioError, parse_overrides
from sensornet.sim.studies import command
from sensornet.sim.studies.base import Outcome, Request, Study
from sensornet.sim.studies.seed004 import output as out
from sensornet.sim.studies.seed004 import scenario as s4


@dataclass(frozen=True)
class Setup:
    """The scenario, and whether the GCI and AA consensus rows are computed (option
    ``consensus``; without them a run is fast: flooding, IC, centralised, local)."""

    scn: s4.Seed004
    consensus: bool = True


def claims(source: str, overrides: Mapping[str, Any]) -> bool:
    return source == "seed004" or Path(source).name == "seed004.toml"


def load(req: Request) -> list[Setup]:
    path = s4.SCENARIO if req.source == "seed004" else Path(req.source)
    try:
        scn = s4.load(path, dict(req.overrides))
    except OSError as exc:
        raise ScenarioError(f"seed004: {path}: {exc.strerror or exc}") from None
    except ScenarioError as exc:
        raise ScenarioError(f"seed004: {exc}") from None
    return [Setup(scn, bool(req.options.get("consensus", True)))]


def run_once(s: Setup, run: int) -> dict[str, dict[str, float]]:
    # heavy optional dependency: sklearn (sim.studies.seed004.montecarlo imports it for FTC's
    # DBSCAN, 1-3 s: not
    # for every 'experiment' that asks this study whether it reads a scenario)
    from sensornet.sim.studies.seed004 import montecarlo as seed004

    return seed004.run_once(s.scn, run, s.consensus)


def summarise(s: Setup, per_run: list) -> dict[str, dict[str, float]]:
    from sensornet.sim.studies.seed004 import (
        montecarlo as seed004,  # heavy optional dependency: sklearn, as above
    )

    return seed004.aggregate(per_run)


def table(o: Outcome) -> str:
    return out.report_text(o.setup.scn, o.runs, o.summary, o.seconds)


def figures(o: Outcome, folder: Path) -> list[Path]:
    return out.write_outputs(o.summary, folder, out.table_title(o.setup.scn, o.runs))


def flood_loss_table(scn: s4.Seed004, losses: Sequence[float], first_run: int) -> str:
    """Flooding's completion under link loss (fault layer, 0-20 ms uniform delay, deadline
    half a scan), one row per loss probability."""
    from sensornet.sim.studies.seed004 import (
        montecarlo as seed004,  # heavy optional dependency: sklearn, as above
    )

    lines = ["| link loss | (peer, scan) complete | missing / peer / scan | duplicates | late |",
             "|---|---|---|---|---|"]
    for p_loss in losses:
        plan = FaultPlan(LinkFaults(delay=Uniform(0.0, 0.02), loss=p_loss),
                         interval=scn.scan_period)
        r = seed004.flooding_under_faults(scn, plan, scn.num_scans, first_run)
        lines.append(f"| {p_loss:g} | {100 * r['complete']:.1f} % | {r['missing']:.3f} | "
                     f"{r['duplicates']:.1f} | {r['late']:.3f} |")
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m sensornet.sim.studies.seed004.montecarlo``: the table (``--out DIR``: its CSVs
    and PNG), or
    ``--flood-loss``: flooding's completion under link loss, or ``--replot``: the PNG again."""
    p = command.parser("seed004", s4.__doc__, runs=20,
                       set_help="override a scenario value (TOML syntax), e.g. "
                                "scenario.variant='mixed'")
    p.add_argument("--scenario", type=Path, default=s4.SCENARIO)
    p.add_argument("--out", type=Path, help="write the CSVs and the PNG here")
    p.add_argument("--no-consensus", action="store_true",
                   help="leave out GCI and AA (fast: flooding, IC, centralised, local only)")
    p.add_argument("--flood-loss", metavar="P1,P2,...",
                   help="only measure flooding completion under these link-loss probabilities "
                        "(fault layer, 0-20 ms uniform delay, deadline 0.5 scan)")
    p.add_argument("--replot", metavar="TITLE",
                   help="redraw the PNG in --out from its CSVs (no runs) with this title")
    a = p.parse_args(argv)
    if a.replot is not None:
        if a.out is None:
            p.error("--replot needs --out")
        print(f"wrote {out.write_outputs(out.read_outputs(a.out), a.out, a.replot)[-1]}")
        return 0
    try:
        req = command.request(a, a.scenario, parse_overrides(a.set), a.out,
                              consensus=not a.no_consensus)
        if a.flood_loss:
            losses = [float(x) for x in a.flood_loss.split(",")]
            print(flood_loss_table(load(req)[0].scn, losses, a.first_run))
            return 0
    except (ScenarioError, ValueError) as exc:
        return command.fail("seed004", exc)
    return command.drive(STUDY, req)


STUDY = Study(
    name="seed004",
    about="seed 004: flooding + IDPC/FTC against GCI/AA consensus, IC, centralised, local",
    load=load, run_once=run_once, summarise=summarise,
    table=table, figures=figures, claims=claims, command=main)
