"""``world``: play a scenario's truth and scans over Zenoh."""

from __future__ import annotations

import argparse
from pathlib import Path

from sensornet.cli.budgets import check_budget
from sensornet.cli.common import UserError, _resolve_viewer
from sensornet.cli.scenarios import load
from sensornet.cli.security import member_security
from sensornet.sim.run.world_process import WorldError, run_world


def cmd_world(args: argparse.Namespace) -> int:
    scn = load(args, args.scenario)
    peers = [p for p in (args.peers or "").split(",") if p]
    unknown = [p for p in peers if p not in scn.sensor_names]
    if unknown:
        raise UserError(f"--peers names unknown sensors {unknown} "
                        f"(sensors: {', '.join(scn.sensor_names)})")
    check_budget(scn, args, wire=True)
    _resolve_viewer(args)
    out = Path(args.out) if args.out else None
    every = args.progress_every

    def progress(k: int) -> None:
        if k % every == 0 or k == scn.num_scans:
            print(f"world: scan {k}/{scn.num_scans} published", flush=True)

    try:
        sent = run_world(scn, args.network, run=args.run, listen=args.listen or [],
                         connect=args.connect or [], config_file=args.config, wait_for=peers,
                         wait_timeout=args.wait, out_dir=out, run_id=args.run_id,
                         viewer=args.viewer, speed=args.speed, rerun=not args.no_rerun,
                         progress=progress, say=lambda line: print(line, flush=True),
                         security=member_security(args, "world", scn), recover=args.recover,
                         bundles=_bundles(args.bundle), view_wait=args.view_wait or 0.0)
    except WorldError as exc:
        raise UserError(str(exc)) from None
    print(f"world: published {sent['scans_published']} scans of {len(scn.sensors)} sensors "
          f"({sent['bytes'] / 1e3:.1f} kB)", flush=True)
    return 0


def _bundles(flags: list[str] | None) -> dict[str, list[str]]:
    """``--bundle HOST=S1,S2`` flags as ``{host: [sensors]}`` (a bad one: a one-line error)."""
    out: dict[str, list[str]] = {}
    for f in flags or []:
        host, sep, names = f.partition("=")
        sensors = [n for n in names.split(",") if n]
        if not sep or not host or not sensors:
            raise UserError(f"--bundle {f!r}: expected HOST=SENSOR,SENSOR,...")
        out.setdefault(host, []).extend(sensors)
    return out
