"""The benchmark scripts import and run (they are not timed here: speed is their own output)."""

from __future__ import annotations

import importlib

import pytest

SCRIPTS = ["bench_gci", "bench_gmphd_stonesoup", "bench_idle_penalty", "bench_immpf",
           "bench_network", "soak", "bench_idpc", "bench_campaign", "bench_record", "bench_pda"]


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
