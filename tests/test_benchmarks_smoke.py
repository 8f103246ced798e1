"""The benchmark scripts import and run (they are not timed here: speed is their own output)."""

from __future__ import annotations

import importlib
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest

SCRIPTS = sorted(p.stem for p in (Path(__file__).resolve().parents[1] / "benchmarks").glob("*.py")
                 if p.stem.startswith("bench_") or p.stem == "soak")
"""Every benchmark script (``bench_*.py`` and ``soak.py``; the others are baselines they
import), found on disk so a new one cannot be left out of this check."""


@pytest.mark.parametrize("name", SCRIPTS)
def test_benchmark_scripts_import_and_have_main(name):
    module = importlib.import_module(f"benchmarks.{name}")
    assert callable(module.main)
    assert module.__doc__ and "python benchmarks/" in module.__doc__.replace("PYTHONPATH=. ", "")


def test_idle_penalty_prints_one_row_per_pause(capsys):
    from benchmarks import bench_idle_penalty

    assert bench_idle_penalty.main(["--scans", "2"]) == 0
    rows = [line for line in capsys.readouterr().out.splitlines() if line.startswith("| ")]
    assert rows[0].startswith("| pause before each step")
    body = rows[1:]
    assert [r.split("|")[1].strip() for r in body] == ["none", "0.5 ms", "2 ms", "10 ms",
                                                       "30 ms", "100 ms"]
    assert body[0].split("|")[3].strip() == "1.00"
    assert all(float(r.split("|")[3]) > 0 for r in body)


def test_circulant_graphs_have_the_degree_asked():
    from benchmarks.bench_network import circulant

    for n, degree in ((20, 4), (20, 3), (50, 4), (6, 2)):
        A = circulant(n, degree)
        assert (A == A.T).all() and not A.diagonal().any()
        assert (A.sum(axis=1) == degree).all(), (n, degree)


@pytest.mark.network
def test_transport_floor_delivers_every_message_with_each_handler(tmp_path, capsys):
    """Three bare processes on a ring, every receive path: all messages arrive, rows print."""
    from benchmarks import bench_transport_floor

    assert bench_transport_floor.main(["--peers", "3", "--degree", "2", "--scans", "5",
                                       "--handler", "all", "--dir", str(tmp_path)]) == 0
    rows = [r for r in capsys.readouterr().out.splitlines() if r.startswith("| circulant")]
    assert [r.split("|")[2].strip() for r in rows] == ["callback", "wildcard", "fifo"]
    for r in rows:
        cells = [c.strip() for c in r.split("|")]
        assert cells[5] == "6.0"  # 2 neighbours x 3 messages a scan
        assert cells[8] == "100.0 %"


@pytest.mark.network  # starts each script as a process
def test_benchmark_commands_run_as_the_readmes_write_them():
    """Every ``python benchmarks/NAME.py`` the READMEs and docs write runs from the repository
    root as written, with no ``PYTHONPATH`` (three of them failed to import ``benchmarks.``)."""
    import os
    import re
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    texts = [root / "README.md", root / "benchmarks" / "README.md", *root.glob("docs/*.md")]
    scripts = sorted({m for t in texts
                      for m in re.findall(r"python benchmarks/(\w+\.py)", t.read_text())})
    assert {"bench_immpf.py", "bench_pda.py", "bench_transport_floor.py",
            "bench_gci.py"} <= set(scripts), scripts
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}

    def help_of(script: str) -> subprocess.CompletedProcess:
        return subprocess.run([sys.executable, f"benchmarks/{script}", "--help"], cwd=root,
                              env=env, capture_output=True, text=True, timeout=240)

    # a few at a time: each start is mostly imports (CPU and disk), one after another they
    # were the slowest part of this test; each still runs alone in its own interpreter
    with ThreadPoolExecutor(max_workers=4) as pool:
        done = dict(zip(scripts, pool.map(help_of, scripts), strict=True))
    for script, p in done.items():
        assert p.returncode == 0 and "usage:" in p.stdout, (script, p.stderr[-500:])
