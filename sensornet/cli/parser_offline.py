"""The subcommands that need no running network: Monte Carlo (``experiment``, ``sweep``,
``campaign``, ``report``), ``replay`` of recordings, ``scenario`` files and ``keys``. One
function per subcommand, each taking the subparsers action of
:func:`sensornet.cli.parser.build_parser`."""

from __future__ import annotations

import argparse

from sensornet.cli.common import (
    DEFAULT_SCENARIO,
    POSITIVE_INT,
    RUNS,
    _network_name,
)
from sensornet.cli.parser_flags import add_budget_flags, add_mc_flags
from sensornet.sim.choices import BIRTH_MODELS, MIXTURE_RULES


def add_experiment(sub) -> None:
    """``sensornet experiment``: offline Monte Carlo of local, fused and centralized."""
    e = sub.add_parser("experiment", help="offline Monte Carlo: local vs fused vs centralized")
    e.add_argument("scenario", nargs="?", default=DEFAULT_SCENARIO,
                   help=f"scenario file (.toml) or built-in name (default {DEFAULT_SCENARIO})")
    e.add_argument("--birth", choices=[*BIRTH_MODELS, "both"],
                   help="birth model (default: the scenario's)")
    e.add_argument("--fusion", choices=MIXTURE_RULES,
                   help="override the fusion rule")
    e.add_argument("--set", action="append", metavar="KEY=VALUE",
                   help="override a scenario value, e.g. --set fusion.level2_pruning=false "
                        "or --set sensors.s1.clutter_rate=50 (repeatable)")
    add_mc_flags(e, 50)
    add_budget_flags(e)


def add_replay(sub) -> None:
    """``sensornet replay``: a recorded run's peers again, offline."""
    rp = sub.add_parser("replay", help="feed a recorded run through the peers offline: the "
                        "same fused tracks bit for bit, or a what-if with --set")
    rp.add_argument("path", help="a run folder (its record/*.mcap) or one .mcap file")
    rp.add_argument("--peer", help="only this peer's recording")
    rp.add_argument("--set", action="append", metavar="KEY=VALUE",
                    help="change a setting for the replay (what-if), e.g. fusion.cardinality=emd "
                         "(not network.rounds: the recording holds only the rounds it had)")


def add_sweep(sub) -> None:
    """``sensornet sweep``: a fault parameter x out-of-sequence policy."""
    sw = sub.add_parser("sweep", help="sweep a fault parameter x out-of-sequence policy "
                        "over Monte Carlo runs (twin by default): CSV and plot")
    sw.add_argument("scenario", nargs="?", default=DEFAULT_SCENARIO)
    sw.add_argument("--param", required=True,
                    help="scenario key to sweep, e.g. faults.default.delay.high")
    sw.add_argument("--values", required=True,
                    help="comma-separated values (TOML literals), or ';'-separated")
    sw.add_argument("--policies", default="nale,drop-late,as-is")
    sw.add_argument("--real", action="store_true",
                    help="real processes over Zenoh instead of the twin (slow)")
    sw.add_argument("--set", action="append", metavar="KEY=VALUE",
                    help="base scenario overrides (repeatable)")
    add_mc_flags(sw, 50)
    add_budget_flags(sw, peers=True)


def add_campaign(sub) -> None:
    """``sensornet campaign``: a campaign file's cells x runs, resumable."""
    ca = sub.add_parser("campaign", help="run an experiment campaign file (cells x Monte "
                        "Carlo runs; resumable; local pool or Dask)")
    ca.add_argument("file", help="campaign .toml (or a shipped one: seed000-figures, "
                    "seed000-twin, policy-sweep, loss-sweep)")
    ca.add_argument("--runs", type=RUNS, help="Monte Carlo runs per cell "
                    "(default: the file's)")
    ca.add_argument("--jobs", type=POSITIVE_INT, help="worker processes, or LocalCluster "
                    "workers with --dask local (default: all cores; 1 for runner 'real')")
    ca.add_argument("--dask", choices=["local"], help="run on a Dask LocalCluster")
    ca.add_argument("--scheduler", metavar="tcp://HOST:8786",
                    help="run on a running Dask scheduler (see README: campaigns)")
    ca.add_argument("--status", action="store_true", help="show progress without running")
    ca.add_argument("--out", help="campaign folder (default: runs/campaign-<name>)")
    ca.add_argument("--quiet", action="store_true", help="no progress bar")
    ca.add_argument("--stop-after", type=POSITIVE_INT, help=argparse.SUPPRESS)  # tests:
    # stop as an interrupt would once this many runs have finished


def add_report(sub) -> None:
    """``sensornet report``: markdown and figures of a campaign folder."""
    rp = sub.add_parser("report", help="markdown + PNG report of a campaign folder")
    rp.add_argument("dir", help="campaign folder (runs/campaign-<name>)")
    rp.add_argument("--out", help="report folder (default: DIR/report)")
    rp.add_argument("--html", action="store_true",
                    help="also report.html beside report.md: one self-contained file (tables, "
                         "every figure embedded)")


def add_scenario(sub) -> None:
    """``sensornet scenario list|show``: the built-in scenario files."""
    s = sub.add_parser("scenario", help="list or print built-in scenario files")
    s.add_argument("action", choices=["list", "show"])
    s.add_argument("name", nargs="?", default=DEFAULT_SCENARIO)


def add_keys(sub) -> None:
    """``sensornet keys``: a network's CA and its members' keys (for ``--secure``)."""
    k = sub.add_parser("keys", help="make a network's CA and each member's key and "
                       "certificate (for --secure)")
    k.add_argument("network", type=_network_name, help="the network the keys are for")
    k.add_argument("--out", required=True, help="folder for the PEM files")
    k.add_argument("--scenario", default=DEFAULT_SCENARIO,
                   help="members: the world and the scenario's sensors "
                   f"(default {DEFAULT_SCENARIO})")
    k.add_argument("--members", help="comma-separated member names instead, e.g. "
                   "world,s1,s2,s3")
    k.add_argument("--hosts", help="host names and addresses the certificates are valid for "
                   "(default localhost,127.0.0.1)")
    k.add_argument("--days", type=POSITIVE_INT, default=365, help="validity (default 365)")
    k.add_argument("--rotate", action="store_true",
                   help="issue new keys for the named members (same CA)")
    k.set_defaults(set=None)
