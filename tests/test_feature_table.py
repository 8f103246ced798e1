"""README's feature table, cell by cell: every shipped scenario with every feature.

Per scenario two tests cover the seven columns in as few runs as the features combine into:
one short run of real processes over Zenoh on 127.0.0.1 with ``--record``, ``--fault kill:...``
and ``--secure DIR`` (keys from ``sensornet keys``) together, then ``replay`` of its recordings;
and ``run --sim``, a one-cell campaign of one twin run, and ``report`` on that campaign. Runs are
shortened with ``--set`` (12 scans at 20x; seed 004 on 4 of its 20 sensors, so a 2-core machine
starts 5 processes, not 21). A last test holds the README table to these scenarios and columns.
"""

from __future__ import annotations

import csv
import json
import math
import os
import re
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest
from sensornet.sim.scenario import builtin_scenarios, load_scenario, parse_overrides

from sensornet.cli import main

ROOT = Path(__file__).resolve().parents[1]
NETWORK = "feat"
SCANS, KILL_AT = 12, 6
FEATURES = ("run", "run --sim", "--record + replay", "--fault kill", "--secure DIR", "campaign",
            "report")


@dataclass(frozen=True)
class Case:
    """A shipped scenario as the table runs it."""

    name: str
    sets: tuple[str, ...] = ()
    """``--set`` items beyond the shortening (seed 004: fewer sensors)."""
    kind: str = ""
    """A peer kind run on this scenario instead of its own: a README row of its own,
    ``SCENARIO --set network.filter=KIND``."""

    @property
    def row(self) -> str:
        """Its README row's first cell (without the backticks)."""
        return f"{self.name} --set network.filter={self.kind}" if self.kind else self.name

    @property
    def id(self) -> str:
        return f"{self.name}-{self.kind}" if self.kind else self.name

    def overrides(self) -> list[str]:
        kind = [f'network.filter="{self.kind}"'] if self.kind else []
        # 5x (a scan every 200 ms): at 20x a secure run on a busy machine (load 15) left a
        # survivor 2 scans short; the cells' subject is the features, not the pace
        return [f"scenario.num_scans={SCANS}", "network.speed=5", *kind, *self.sets]

    def scenario(self):
        return load_scenario(self.name, overrides=parse_overrides(self.overrides()))


FOUR = "sensors.positions=[[0, 0], [500, 0], [0, 500], [500, 500]]"
CASES = [Case("seed000"), Case("seed001"), Case("seed002"), Case("seed003"), Case("seed004",
                                                                                   (FOUR,)),
         Case("seed000", kind="lmb")]
MEMBERS = sorted({"world", *(n for c in CASES for n in c.scenario().sensor_names)})


def _sets(case: Case) -> list[str]:
    return [a for s in case.overrides() for a in ("--set", s)]


def _cli(capsys, *args: str) -> tuple[int, str, str]:
    """``sensornet ARGS`` in this process: exit code, stdout, stderr."""
    capsys.readouterr()
    code = main(list(args))
    out = capsys.readouterr()
    return code, out.out, out.err


@pytest.fixture(scope="module")
def keys(tmp_path_factory) -> Path:
    """One network's keys for every member of every case (``sensornet keys``)."""
    d = tmp_path_factory.mktemp("keys")
    p = subprocess.run([sys.executable, "-m", "sensornet", "keys", NETWORK, "--out", str(d),
                        "--members", ",".join(MEMBERS)], capture_output=True, text=True,
                       timeout=120, cwd=ROOT)
    assert p.returncode == 0, p.stderr
    assert (d / "ca.pem").is_file() and all((d / f"{m}.pem").is_file() for m in MEMBERS)
    return d


@pytest.mark.network
@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_processes_record_kill_secure_then_replay(case, keys, tmp_path, capsys):
    """Cells run, --record + replay, --fault kill, --secure DIR: one run of real processes."""
    scn = case.scenario()
    names = scn.sensor_names
    victim, survivors = names[-1], names[:-1]
    out = tmp_path / "run"
    env = {**os.environ, "RERUN_ANALYTICS": "0"}
    p = subprocess.run([sys.executable, "-m", "sensornet", "run", case.name, *_sets(case),
                        "--record", "--fault", f"kill:{victim}@{KILL_AT}", "--secure", str(keys),
                        "--network", NETWORK, "--no-rerun", "--out", str(out)],
                       capture_output=True, text=True, timeout=600, cwd=ROOT, env=env)
    assert p.returncode == 0, p.stderr[-3000:]
    # run: world + one process per sensor, each survivor scored every scan and fused
    assert f"world + {len(names)} peers as processes" in p.stdout
    for n in survivors:
        s = json.loads((out / f"peer-{n}.json").read_text())
        assert s["scans"] == SCANS and math.isfinite(s["mean_ospa_fused"]), s
        assert not s["internal_errors"] and s["messages_received"] > 0
    # --secure DIR: said, and every process was started on tls/ endpoints with those keys
    assert f"secure mode: mutual TLS + access control on network {NETWORK}" in p.stdout
    cmds = json.loads((out / "commands.json").read_text())
    for name, cmd in cmds.items():
        assert "--secure" in cmd and str(keys) in cmd, (name, cmd)
        eps = [cmd[i + 1] for i, a in enumerate(cmd) if a in ("--listen", "--connect")]
        assert eps and all(e.startswith("tls/") for e in eps), (name, eps)
    # --fault kill: applied at its scan, the victim wrote no summary, the others saw it leave
    done = json.loads((out / "process-faults.json").read_text())
    assert [(f["action"], f["peer"], f["scan"]) for f in done] == [("kill", victim, KILL_AT)]
    assert not (out / f"peer-{victim}.json").exists()
    line = next(ln for ln in p.stdout.splitlines() if ln.startswith(f"kill {victim} at scan"))
    assert all(n in line for n in survivors), line
    # --record + replay: each survivor's fused tracks come out identical
    code, text, err = _cli(capsys, "replay", str(out), "--peer", survivors[0])
    assert code == 0, err
    assert f"| {survivors[0]} | peer-{survivors[0]}.mcap | {SCANS} | {SCANS} | yes |" in text
    # the killed peer never closed its recording: one line, not a traceback
    code, text, err = _cli(capsys, "replay", str(out / "record" / f"peer-{victim}.mcap"))
    assert code == 2 and "not a complete recording" in err and len(err.splitlines()) == 1


# all in this process (campaign --jobs 1 starts no worker): not marked network, so it runs on
# the fast tests' worker beside the process tests, not in their one-at-a-time queue
@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_twin_campaign_and_report(case, tmp_path, capsys):
    """Cells run --sim, campaign (one cell, one twin run) and report on that campaign."""
    names = case.scenario().sensor_names
    code, text, err = _cli(capsys, "run", case.name, "--sim", *_sets(case))
    assert code == 0, err
    assert f"twin run {case.name}" in text
    for n in names:
        assert re.search(rf"^\| {n} \| {SCANS} \| [0-9.]+ \| [0-9.]+ \|", text, re.M), text
    sets = "\n".join(f'"{k}" = {v}' for k, v in (s.split("=", 1) for s in case.overrides()))
    cfile = tmp_path / "one.toml"
    cfile.write_text(f'[campaign]\nname = "one-{case.name}"\nscenario = "{case.name}"\n'
                     f'runner = "twin"\nruns = 1\n\n[set]\n{sets}\n')
    folder = tmp_path / "campaign"
    code, text, err = _cli(capsys, "campaign", str(cfile), "--jobs", "1", "--quiet",
                           "--out", str(folder))
    assert code == 0, err
    assert "ran 1 runs" in text
    code, text, err = _cli(capsys, "report", str(folder))
    assert code == 0, err
    md = (folder / "report" / "report.md").read_text()
    assert f"scenario `{case.name}`" in md and "1/1 runs computed" in md
    rows = list(csv.DictReader((folder / "report" / "per_run.csv").open()))
    assert len(rows) == 1 and math.isfinite(float(rows[0]["fused_ospa"]))
    assert {f"fused_ospa.{n}" for n in names} <= set(rows[0])


def test_readme_feature_table_is_these_tests():
    """README's table: one row per shipped scenario (and per kind run on another's scenario),
    one column per feature, each cell names the test above that backs it."""
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    section = text.split("## Every scenario, every feature", 1)[1].split("\n## ", 1)[0]
    lines = [ln for ln in section.splitlines() if ln.startswith("|")]
    head = [c.strip().strip("`") for c in lines[0].strip("|").split("|")]
    assert head == ["scenario", *FEATURES], head
    rows = {}
    for ln in lines[2:]:
        cells = [c.strip() for c in ln.strip("|").split("|")]
        rows[cells[0].strip("`")] = cells[1:]
    shipped = [n for n in builtin_scenarios() if re.fullmatch(r"seed\d{3}", n)]
    assert sorted(shipped) == [c.name for c in CASES if not c.kind]
    assert sorted(rows) == sorted(c.row for c in CASES)
    for cells in rows.values():
        assert len(cells) == len(FEATURES) and all(c.startswith("yes") for c in cells), cells
