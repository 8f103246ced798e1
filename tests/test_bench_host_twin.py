"""benchmarks/bench_host_twin.py: the hosts' code without Zenoh on virtual time handles every
scan without a deadline fusion, publishes what the peers owe (two rounds' estimates and the
tracks, a peer-scan) and is deterministic: two runs of one tree publish the same bytes."""

from __future__ import annotations

from benchmarks import bench_host_twin


def test_host_twin_runs_every_scan_and_repeats_itself(capsys):
    assert bench_host_twin.main(["--revs", ".,.", "--pairs", "1", "--peers", "6",
                                 "--degree", "2", "--scans", "3"]) == 0
    out = capsys.readouterr().out
    rows = [r.split("|") for r in out.splitlines() if r.startswith("| . |")]
    assert len(rows) == 2
    for r in rows:
        cells = [c.strip() for c in r]
        assert float(cells[3]) > 0
        assert cells[5] == str(6 * 3 * 3)  # 2 rounds' estimates and the tracks, a peer-scan
        assert cells[8] == "3" and cells[9] == "0"  # every scan, no deadline fusion
    assert rows[0][6] == rows[1][6]
    assert "the same bytes and OSPA: yes" in out
