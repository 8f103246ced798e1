"""A member padding its estimates to the codec's limit, as real processes (issue 36 target 1).

World + 3 peers (seed 000, 40 scans at 10 scans/s) on loopback, the neighbour defence on
(``fusion.trust``: before the budget, its divergence over 2,000 components stalled every
neighbour); s2 is a padding member (``tests/padding_member.py``): every estimate it sends is
its real one plus weight-1e-4 components up to 2,000 (240 kB), one a scan, inside its message
rate. The honest peers must handle and fuse every scan, cut every padded estimate on arrival
(``budget.reduced``), refuse none for its size (one estimate a scan at the codec's limit is
within the byte budget), and fuse as well as the clean network's twin (within 10 %: the
padding is cut to s2's real estimate). The timings are ``benchmarks/bench_member_costs.py``'s.
"""

from __future__ import annotations

import pytest
from sensornet.sim.run.launcher import read_summaries, wait_run
from sensornet.sim.run.twin import run_twin
from sensornet.sim.scenario import load_scenario, parse_overrides

from tests.attacks import SETS
from tests.padding_member import PAD, start_padded_run

pytestmark = pytest.mark.network

HONEST = ("s1", "s3")


def test_a_member_padding_to_the_codec_limit_costs_its_neighbours_no_scan(tmp_path):
    sets = [*SETS, "fusion.trust=true"]
    scn = load_scenario("seed000", overrides=parse_overrides(sets))
    clean = run_twin(scn, 0)  # the reference: the same network with no padding member
    out = tmp_path / "run"
    handle = start_padded_run(scn, "seed000", out, {"s2": (PAD, 1)}, network="padnet",
                              overrides=sets, rerun=False)
    try:
        codes = wait_run(handle, timeout=120)
    finally:
        handle.stop_all()
    assert all(c == 0 for c in codes.values()), codes
    summaries = read_summaries(out, scn.sensor_names)
    # s2 really padded: every estimate it sent was 240 kB
    s2 = summaries["s2"]
    assert s2["estimate_bytes_sent"] >= 0.9 * scn.num_scans * 240_000, s2["estimate_bytes_sent"]
    for name in HONEST:
        s = summaries[name]
        assert s["internal_errors"] == {}, (name, s["internal_errors"])
        assert s["scans"] == scn.num_scans and s["stop_reason"] == "end of run", name
        assert s["stats"]["tracks_out"] == scn.num_scans, (name, s["stats"])
        budget = s["budget"]
        assert budget["refused"] == {}, (name, budget)  # one a scan is within the budget
        assert budget["largest"]["s2"] == PAD, (name, budget)
        assert budget["reduced"]["s2"] >= scn.num_scans - 2, (name, budget)  # every one cut
        # s2's estimate, cut to its real one, is still fused at the end (not shut out)
        assert s["stats"]["last_fused_from"].get("s2", 0) >= scn.num_scans - 2, (name, s)
        assert s["mean_ospa_fused"] <= 1.1 * clean.mean_ospa(name), (
            name, s["mean_ospa_fused"], clean.mean_ospa(name))
