"""``report``: markdown + PNG (and HTML) report of a campaign folder."""

from __future__ import annotations

import argparse

from sensornet.cli.common import UserError
from sensornet.sim.campaign.report import write_report


def cmd_report(args: argparse.Namespace) -> int:
    try:
        written = write_report(args.dir, args.out, html=args.html)
    except ImportError as exc:
        raise UserError(str(exc)) from None
    for path in written:
        print(f"wrote {path}")
    return 0
