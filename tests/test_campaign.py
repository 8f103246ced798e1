"""Campaigns: resumption after an interruption, worker-count invariance, status and report."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from sensornet.sim.campaign import (
    LOCK,
    CampaignError,
    canonical_rows,
    format_status,
    load_campaign,
    results_table,
    run_campaign,
    status,
)
from sensornet.sim.campaign.results import ResultStore

from sensornet.cli import main

TWIN = """
[campaign]
name = "t-twin"
scenario = "seed000"
runner = "twin"
runs = 6

[set]
"scenario.num_scans" = 8
"faults.default.loss" = 0.2

[grid]
"network.rounds" = [1, 2]
"""

EXPERIMENT = """
[campaign]
name = "t-exp"
scenario = "seed000"
runner = "experiment"
runs = 4

[set]
"scenario.num_scans" = 8

[grid]
"birth.model" = ["truth", "paper"]

[[figures]]
kind = "seed000"

[[figures]]
kind = "sweep"
x = "birth.model"
"""


@pytest.fixture(autouse=True)
def _pinned_code_version(monkeypatch):
    """Other work may edit the source tree while these tests run: pin the code version (the
    subprocesses and Dask workers inherit it)."""
    monkeypatch.setenv("SENSORNET_CODE_VERSION", "test-pinned")


def _says_running(status_text: str) -> bool:
    """A ``running:`` state line, or a cell marked running."""
    import re

    return bool(re.search(r"^running:|  running$", status_text, re.M))


def _file(tmp_path: Path, text: str, name: str = "c.toml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


@pytest.mark.network
def test_stopped_campaign_resumes_to_the_uninterrupted_table(tmp_path):
    c = load_campaign(_file(tmp_path, TWIN))
    whole = run_campaign(c, tmp_path / "whole", jobs=1, progress=False)
    assert (whole.ran, whole.skipped, whole.stopped) == (12, 0, False)
    seen: list[str] = []
    first = run_campaign(c, tmp_path / "cut", jobs=2, progress=False, stop_after=5,
                         on_row=lambda r: seen.append(r["key"]))
    assert first.stopped and first.ran == 5
    stored = ResultStore(tmp_path / "cut" / "results").done_keys()
    assert stored == set(seen)  # every finished run kept; runs in flight lost, nothing else
    assert status(c, tmp_path / "cut").done == 5
    rest = run_campaign(c, tmp_path / "cut", jobs=2, progress=False)
    assert (rest.ran, rest.skipped, rest.stopped) == (7, 5, False)
    again = run_campaign(c, tmp_path / "cut", jobs=2, progress=False)
    assert (again.ran, again.skipped) == (0, 12)
    a, b = results_table(tmp_path / "whole"), results_table(tmp_path / "cut")
    assert a.num_rows == b.num_rows == 12
    assert canonical_rows(a) == canonical_rows(b)
    assert b.column("run").to_pylist() == list(range(6)) * 2


@pytest.mark.network
def test_killed_campaign_process_resumes(tmp_path):
    """``kill -9`` of the campaign process half-way: only its run in flight is redone."""
    path = _file(tmp_path, TWIN.replace('"scenario.num_scans" = 8', '"scenario.num_scans" = 20'))
    out = tmp_path / "killed"
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parent.parent)}
    proc = subprocess.Popen([sys.executable, "-m", "sensornet", "campaign", str(path), "--out",
                             str(out), "--jobs", "1", "--quiet"], env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    store = ResultStore(out / "results")
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and proc.poll() is None:
        if store.count_files() >= 4:
            break
        time.sleep(0.05)
    assert proc.poll() is None, proc.stderr.read().decode()
    c = load_campaign(path)
    st = status(c, out)  # while it runs: its lock names it
    assert st.running is not None and st.running["pid"] == proc.pid, st.running
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    proc.stderr.close()
    done = len(store.done_keys())
    assert 4 <= done < 12
    st = status(c, out)  # killed: its lock is left, nothing runs
    assert st.running is None and st.died["pid"] == proc.pid
    text = format_status(c, out, st)
    assert f"stopped: the process that ran it (pid {proc.pid} on" in text
    assert not _says_running(text)
    summary = run_campaign(c, out, jobs=2, progress=False)
    assert (summary.ran, summary.skipped) == (12 - done, done)
    whole = run_campaign(c, tmp_path / "whole", jobs=2, progress=False)
    assert whole.ran == 12
    assert canonical_rows(results_table(out)) == canonical_rows(results_table(tmp_path / "whole"))


@pytest.mark.network
def test_same_numbers_from_one_two_workers_and_a_dask_local_cluster(tmp_path):
    pytest.importorskip("distributed", reason="needs the campaign extra (dask[distributed])")
    c = load_campaign(_file(tmp_path, EXPERIMENT))
    tables = []
    for name, kw in (("one", {"jobs": 1}), ("two", {"jobs": 2}),
                     ("dask", {"jobs": 2, "dask": "local"})):
        s = run_campaign(c, tmp_path / name, progress=False, **kw)
        assert s.ran == 8
        tables.append(canonical_rows(results_table(tmp_path / name, complete_only=True)))
    assert tables[0] == tables[1] == tables[2]
    # and the twin runner on the cluster (fault draws included)
    t = load_campaign(_file(tmp_path, TWIN.replace("runs = 6", "runs = 2"), "t.toml"))
    run_campaign(t, tmp_path / "t1", jobs=1, progress=False)
    run_campaign(t, tmp_path / "td", jobs=2, dask="local", progress=False)
    assert canonical_rows(results_table(tmp_path / "t1")) == \
        canonical_rows(results_table(tmp_path / "td"))


@pytest.mark.network
def test_status_without_running_and_cli(tmp_path, capsys):
    path = _file(tmp_path, TWIN.replace("runs = 6", "runs = 3"))
    out = tmp_path / "camp"
    assert main(["campaign", str(path), "--out", str(out), "--status"]) == 0
    text = capsys.readouterr().out
    assert "0/6 runs done, 0/2 cells complete" in text
    assert "cell   0  network.rounds=1" in text and "0/3" in text
    assert not (out / "results").exists()  # --status runs nothing
    assert main(["campaign", str(path), "--out", str(out), "--jobs", "1", "--quiet",
                 "--stop-after", "4"]) == 1
    text = capsys.readouterr().out
    assert "stopped after 4 runs" in text
    assert main(["campaign", str(path), "--out", str(out), "--status"]) == 0
    text = capsys.readouterr().out
    assert "4/6 runs done, 1/2 cells complete" in text
    assert "3/3  done" in text and "1/3  incomplete" in text and not _says_running(text)
    assert "incomplete: no process is running it, 2 runs to go" in text
    # against the folder's recorded plan (3 runs per cell), not whatever --runs says
    assert main(["campaign", str(path), "--out", str(out), "--runs", "4", "--status"]) == 0
    text = capsys.readouterr().out
    assert "4/6 runs done, 1/2 cells complete" in text and "4/8" not in text
    assert "(--runs 4 not counted: the folder's plan is 3 runs per cell" in text
    assert main(["campaign", str(path), "--out", str(out), "--jobs", "2", "--quiet"]) == 0
    text = capsys.readouterr().out
    assert "6/6 runs done, 2/2 cells complete" in text and "2 runs in" in text
    assert "4 already stored" in text


@pytest.mark.network
def test_report_tables_and_seed000_figures(tmp_path, capsys):
    path = _file(tmp_path, EXPERIMENT)
    out = tmp_path / "exp"
    assert main(["campaign", str(path), "--out", str(out), "--jobs", "2", "--quiet"]) == 0
    capsys.readouterr()
    assert main(["report", str(out)]) == 0
    written = [Path(line.split(" ", 1)[1]) for line in capsys.readouterr().out.splitlines()]
    names = {p.name for p in written}
    for cell in (0, 1):
        for fig in ("cardinality", "cardinality-rmse", "ospa", "components"):
            assert f"cell{cell}-{fig}.png" in names
    assert "sweep-1.png" in names
    assert all(p.stat().st_size > 1000 for p in written)
    md = (out / "report" / "report.md").read_text()
    assert "| birth.model=truth | 4 |" in md and "95 % CI" in md
    assert "mean_ospa.fused" in md and "mean_ospa.centralized" in md
    csv_lines = (out / "report" / "per_run.csv").read_text().splitlines()
    assert len(csv_lines) == 9 and csv_lines[0].startswith("cell,cell_label,run,mean_ospa.")


def test_status_says_running_only_while_a_live_process_holds_the_lock(tmp_path):
    """running.json names the process running the campaign: status says running while it
    lives, stopped once it is gone (a kill -9 leaves the file), incomplete without one; a
    second run of the same folder is refused while the first lives."""
    import json
    import socket

    from sensornet.sim.campaign import _claim

    c = load_campaign(_file(tmp_path, TWIN.replace("runs = 6", "runs = 2")))
    out = tmp_path / "camp"
    out.mkdir()
    assert "not started" in format_status(c, out, status(c, out))
    host = socket.gethostname()
    other = os.getppid()  # a live process that is not this one
    (out / LOCK).write_text(json.dumps({"pid": other, "host": host}))
    st = status(c, out)
    assert st.running == {"pid": other, "host": host} and st.died is None
    assert f"running: pid {other} on {host}" in format_status(c, out, st)
    with pytest.raises(CampaignError, match=f"running already \\(pid {other}"):
        _claim(out)
    gone = 2 ** 22 + 12345  # above the kernel's default pid_max: no such process
    (out / LOCK).write_text(json.dumps({"pid": gone, "host": host}))
    st = status(c, out)
    assert st.running is None and st.died["pid"] == gone
    text = format_status(c, out, st)
    assert f"stopped: the process that ran it (pid {gone} on {host}) is gone, 4 runs to go" \
        in text and not _says_running(text)
    assert _claim(out).is_file()  # a dead holder's lock is taken over
    assert json.loads((out / LOCK).read_text())["pid"] == os.getpid()
    (out / LOCK).unlink()
    assert not _says_running(format_status(c, out, status(c, out)))


def test_campaign_file_errors_are_one_line(tmp_path, capsys):
    bad = _file(tmp_path, TWIN.replace('runner = "twin"', 'runner = "cloud"'))
    assert main(["campaign", str(bad)]) == 2
    assert "campaign.runner must be one of" in capsys.readouterr().err
    bad = _file(tmp_path, TWIN.replace('"network.rounds" = [1, 2]',
                                       '"network.rounds" = [1, 0]'), "b.toml")
    assert main(["campaign", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "cell 'network.rounds=0'" in err and len(err.strip().splitlines()) == 1
    assert main(["campaign", str(tmp_path / "none.toml")]) == 2
    assert "no such campaign file" in capsys.readouterr().err
    assert main(["report", str(tmp_path)]) == 2
    assert "no manifest.json" in capsys.readouterr().err
    assert main(["report", str(tmp_path / "runs" / "campaign-nope")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"{tmp_path / 'runs' / 'campaign-nope'}: no such folder" in err[0]
    assert "manifest" not in err[0] and not (tmp_path / "runs").exists()
    assert main(["report", str(bad)]) == 2  # a file
    assert "not a folder" in capsys.readouterr().err


def test_results_of_other_code_are_not_reused(tmp_path, monkeypatch, capsys):
    path = _file(tmp_path, TWIN.replace("runs = 6", "runs = 2"))
    out = tmp_path / "v"
    assert run_campaign(load_campaign(path), out, jobs=1, progress=False).ran == 4
    monkeypatch.setenv("SENSORNET_CODE_VERSION", "test-other")
    c = load_campaign(path)
    st = status(c, out)
    assert (st.done, st.stale) == (0, 4)
    assert main(["campaign", str(path), "--out", str(out), "--status"]) == 0
    assert "4 stored runs belong to other code versions or cells" in capsys.readouterr().out
    assert run_campaign(c, out, jobs=1, progress=False).ran == 4
    monkeypatch.delenv("SENSORNET_CODE_VERSION")
    from sensornet.sim.campaign.runners import code_version

    assert len(code_version()) == 16 and code_version() != "test-other"


def test_seed001_runner_reproduces_the_table1_rows(tmp_path, capsys):
    from sensornet.sim.studies.seed001.montecarlo import (
        ExperimentConfig,
        Seed001Scenario,
        run_experiment,
    )

    path = _file(tmp_path, """
[campaign]
runner = "seed001"
runs = 1
[set]
filters = ["IMM-EKF"]
[grid]
geometry = ["A"]
[[figures]]
kind = "seed001"
""")
    out = tmp_path / "s1"
    assert main(["campaign", str(path), "--out", str(out), "--jobs", "2", "--quiet"]) == 0
    assert main(["report", str(out)]) == 0
    assert "cell0-table1.png" in capsys.readouterr().out
    md = (out / "report" / "report.md").read_text()
    ref = run_experiment(Seed001Scenario(geometry="A"), ExperimentConfig(filters=("IMM-EKF",)),
                         1, progress=False)
    for r in ref.rows():
        p, v, a = r["rmse"]
        assert f"| IMM-EKF | {r['rule']} | {p:.3f} | {v:.4f} | {a:.4f} | {r['lost']}/1 |" in md
    assert "| IMM-PF (paper, 300 runs) | fusion | 12.29 |" in md
    bad = _file(tmp_path, "[campaign]\nrunner = \"seed001\"\n[set]\nparticle = 5\n", "b.toml")
    assert main(["campaign", str(bad)]) == 2
    assert "unknown key(s) ['particle']" in capsys.readouterr().err


def test_shipped_campaigns_load():
    for name in ("seed000-figures", "seed000-twin", "policy-sweep", "loss-sweep",
                 "latency-sweep", "seed001-table1"):
        c = load_campaign(name, runs=2)
        assert c.cells and all(len(cell.keys) == 2 for cell in c.cells)
    c = load_campaign("seed000-figures")
    assert [cell.label for cell in c.cells] == ["birth.model=truth", "birth.model=paper"]


@pytest.mark.network
def test_sigterm_is_an_interrupt_that_keeps_finished_runs(tmp_path):
    path = _file(tmp_path, TWIN.replace('"scenario.num_scans" = 8', '"scenario.num_scans" = 20'))
    out = tmp_path / "term"
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parent.parent)}
    proc = subprocess.Popen([sys.executable, "-m", "sensornet", "campaign", str(path), "--out",
                             str(out), "--jobs", "2", "--quiet"], env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    store = ResultStore(out / "results")
    deadline = time.monotonic() + 600  # a bound for failure only: the wait is on the files
    while time.monotonic() < deadline and proc.poll() is None and store.count_files() < 2:
        time.sleep(0.05)
    assert proc.poll() is None and store.count_files() >= 2, "no two finished runs to keep"
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err.decode()
    assert "interrupted" in err.decode()
    files = [p.name for p in (out / "results").iterdir()]
    assert len(files) == 1 and files[0].startswith("part-")  # compacted on the way out
    done = len(store.done_keys())
    assert 2 <= done < 12
    summary = run_campaign(load_campaign(path), out, jobs=2, progress=False)
    assert (summary.ran, summary.skipped) == (12 - done, done)


LATENCY = """
[campaign]
name = "t-lat"
scenario = "seed000"
runner = "twin"
runs = 2

[set]
"scenario.num_scans" = 8

[grid]
"faults.default.delay" = [0.0, 0.07]
"network.policy" = ["nale", "drop-late"]

[[figures]]
kind = "sweep"
x = "faults.default.delay"
lines = "network.policy"
baseline = "local_ospa"
paper = { value = 30.0, label = "a paper's number" }
"""


def test_latency_sweep_report_figure_and_its_numbers(tmp_path, capsys):
    """A latency sweep in this process (jobs 1): estimates past the 50 ms deadline reach the
    policy as late (NALE) or are dropped (drop-late); the report's numbers are the runs'."""
    import csv

    import numpy as np
    from scipy.stats import t

    c = load_campaign(_file(tmp_path, LATENCY))
    out = tmp_path / "lat"
    assert run_campaign(c, out, jobs=1, progress=False).ran == 8
    table = results_table(out, complete_only=True)
    rows = {(r["cell_label"], r["run"]): r for r in table.to_pylist()}
    on_time = [r for (lab, _), r in rows.items() if "delay=0.0," in lab]
    assert all(r["late"] == 0 and r["dropped_late"] == 0 for r in on_time)
    nale = [r for (lab, _), r in rows.items() if lab.endswith("0.07, network.policy=nale")]
    drop = [r for (lab, _), r in rows.items() if lab.endswith("0.07, network.policy=drop-late")]
    assert len(nale) == len(drop) == 2
    assert all(r["late"] > 0 and r["dropped_late"] == 0 for r in nale)
    assert all(r["dropped_late"] > 0 for r in drop)
    assert main(["report", str(out)]) == 0
    capsys.readouterr()
    md = (out / "report" / "report.md").read_text()
    assert "![fused_ospa against faults.default.delay, 95 % intervals; dashed: local_ospa; " \
           "red: a paper's number (30)](sweep-0.png)" in md
    assert (out / "report" / "sweep-0.png").stat().st_size > 10_000
    # the overview's mean and 95 % half-width of a cell, recomputed from per_run.csv
    with (out / "report" / "per_run.csv").open() as fh:
        per = [r for r in csv.DictReader(fh) if r["cell"] == "3"]
    v = np.array([float(r["fused_ospa"]) for r in per])
    half = t.ppf(0.975, len(v) - 1) * v.std(ddof=1) / np.sqrt(len(v))
    label = per[0]["cell_label"]
    row = next(line for line in md.splitlines() if line.startswith(f"| {label} | 2 |"))
    mean_text, half_text = row.split("|")[3].strip().split(" ± ")
    assert float(mean_text) == pytest.approx(v.mean(), rel=5e-3)
    assert float(half_text) == pytest.approx(half, rel=5e-3)


@pytest.mark.network
def test_real_process_campaign_runs_stores_and_resumes(tmp_path):
    """The ``real`` runner: each run is the world and three peers as processes over Zenoh;
    stopped after one run, the campaign resumes with only the other."""
    c = load_campaign(_file(tmp_path, """
[campaign]
name = "t-real"
scenario = "seed000"
runner = "real"
runs = 2

[set]
"scenario.num_scans" = 6
"birth.model" = "truth"
"""))
    out = tmp_path / "real"
    first = run_campaign(c, out, jobs=1, progress=False, stop_after=1)
    assert (first.ran, first.stopped) == (1, True)
    assert len(ResultStore(out / "results").done_keys()) == 1
    rest = run_campaign(c, out, jobs=1, progress=False)
    assert (rest.ran, rest.skipped) == (1, 1)
    assert run_campaign(c, out, jobs=1, progress=False).ran == 0
    table = results_table(out, complete_only=True)
    assert table.column("run").to_pylist() == [0, 1]
    for r in table.to_pylist():
        assert r["runner"] == "real"
        assert 0 < r["fused_ospa"] <= 200 and 0 < r["local_ospa"] <= 200  # OSPA cut-off c
        assert all(0 < r[f"fused_ospa.{n}"] <= 200 for n in ("s1", "s2", "s3"))
        assert r["ms_latency_median.s1"] > 0


def test_html_report_is_one_self_contained_file(tmp_path, capsys):
    """``report --html``: report.html beside report.md, every table of the markdown as a table,
    every PNG embedded byte for byte, the per-run CSV as a data link; nothing fetched."""
    import base64
    import re
    from html.parser import HTMLParser

    path = _file(tmp_path, EXPERIMENT.replace("runs = 4", "runs = 2"))
    out = tmp_path / "exp"
    assert main(["campaign", str(path), "--out", str(out), "--jobs", "1", "--quiet"]) == 0
    assert main(["report", str(out), "--html"]) == 0
    written = [line.split(" ", 1)[1] for line in capsys.readouterr().out.splitlines()
               if line.startswith("wrote ")]
    page = out / "report" / "report.html"
    assert str(page) in written
    md = (out / "report" / "report.md").read_text()

    class Collect(HTMLParser):
        def __init__(self):
            super().__init__()
            self.srcs, self.hrefs, self.tables, self.rows = [], [], 0, 0
            self.tags = set()

        def handle_starttag(self, tag, attrs):
            a = dict(attrs)
            self.tags.add(tag)
            if tag == "img":
                self.srcs.append(a["src"])
            elif tag == "a":
                self.hrefs.append(a["href"])
            elif tag == "table":
                self.tables += 1
            elif tag == "tr":
                self.rows += 1

    c = Collect()
    c.feed(page.read_text())
    assert not {"script", "link", "iframe"} & c.tags
    pngs = re.findall(r"!\[[^\]]*\]\(([^)]+\.png)\)", md)
    assert len(pngs) == 9  # 4 seed-000 figures x 2 cells + the sweep
    assert len(c.srcs) == len(pngs)
    for name, src in zip(pngs, c.srcs, strict=True):
        prefix = "data:image/png;base64,"
        assert src.startswith(prefix)
        assert base64.b64decode(src[len(prefix):]) == (out / "report" / name).read_bytes()
    md_lines = md.splitlines()
    tables = sum(1 for i, line in enumerate(md_lines) if line.startswith("|")
                 and (i == 0 or not md_lines[i - 1].startswith("|")))
    rows = sum(1 for line in md_lines if line.startswith("|") and not line.startswith("|---"))
    assert (c.tables, c.rows) == (tables, rows)
    csv_links = [h for h in c.hrefs if h.startswith("data:text/csv;base64,")]
    assert len(csv_links) == 1 and all(h.startswith("data:") for h in c.hrefs)
    assert base64.b64decode(csv_links[0].split(",", 1)[1]) == \
        (out / "report" / "per_run.csv").read_bytes()
    assert "<td class=r>2</td>" in page.read_text()  # runs, right-aligned as in the markdown


def test_compaction_from_memory_equals_reading_the_files_back(tmp_path, monkeypatch):
    """Compaction takes the rows a store wrote from memory (up to KEEP) and reads the rest
    (earlier, interrupted writers') back: the folded file is the same either way."""
    rows = [{"key": f"k{i}", "cell": i % 2, "cell_label": "c", "run": i, "runner": "twin",
             "code_version": "v", "seconds": 0.1, "cpu_seconds": 0.1, "worker": "w",
             "fused_ospa": 10.0 + i / 3, "ospa_k.fused": [float(i), 1 / 3],
             **({"links_drop-loss": 2} if i % 2 else {})} for i in range(6)]
    tables = []
    for keep in (0, 3, 100):
        monkeypatch.setattr(ResultStore, "KEEP", keep)
        folder = tmp_path / f"keep{keep}"
        ResultStore(folder).write(rows[0])  # a row from an earlier (interrupted) writer
        store = ResultStore(folder)
        for r in rows[1:]:
            store.write(r)
        assert len(store._written) == min(keep, 5)
        assert store.compact() is not None and store.count_files() == 1
        t = ResultStore(folder).read()
        tables.append(sorted(zip(*(t.column(c).to_pylist() for c in sorted(t.column_names)),
                                 strict=True)))
    assert tables[0] == tables[1] == tables[2] and len(tables[0]) == 6


def test_an_interrupted_write_leaves_no_temporary_file(tmp_path, monkeypatch):
    """SIGTERM during a row's write (the campaign's interrupt) removes the half-written file;
    compaction removes what a SIGKILLed writer left, so the folder holds only stored rows."""
    import pyarrow.parquet as pq

    row = {"key": "k0", "cell": 0, "run": 0, "fused_ospa": 1.0}
    store = ResultStore(tmp_path)
    store.write(row)
    real = pq.write_table

    def interrupted(table, where, **kw):
        real(table, where, **kw)
        raise KeyboardInterrupt

    monkeypatch.setattr(pq, "write_table", interrupted)
    with pytest.raises(KeyboardInterrupt):
        store.write({**row, "key": "k1"})
    monkeypatch.setattr(pq, "write_table", real)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["k0.parquet"]
    (tmp_path / ".k2.dead.tmp").write_bytes(b"half")  # a killed writer's leftover
    store.write({**row, "key": "k3"})
    assert store.compact() is not None
    files = [p.name for p in tmp_path.iterdir()]
    assert len(files) == 1 and files[0].startswith("part-"), files
    assert store.done_keys() == {"k0", "k3"}
