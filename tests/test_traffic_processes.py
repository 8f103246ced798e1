"""``sensornet run paris`` as processes on the shipped excerpt (issue 34 item 2): every peer
handles every tick (at most one missed), fuses it, and ends with tracks that carry ids, stay
on one aircraft of the OpenSky truth and keep their ids from tick to tick. The real-time
measurement on paris-8 is in docs/real-traffic.md ("The peers as processes")."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest
from sensornet.sim.scenario import load_scenario

from tests.processes import env

SCANS = 30
"""60 s of traffic (2 s ticks) at the scenario's 10x: 6 s of scans, about 20 s in all."""
NEAR = 1000.0
"""A track this close (m, x-y) to an aircraft of the truth is on it (the OSPA cut-off)."""


def _ids(rows: pd.Series) -> list[set[tuple[int, ...]]]:
    return [{tuple(int(v) for v in i) for i in ids} for ids in rows]


@pytest.mark.network
def test_sensornet_run_paris_handles_every_tick_and_tracks_with_ids(tmp_path):
    out = tmp_path / "run"
    proc = subprocess.run(
        [sys.executable, "-m", "sensornet", "run", "paris", "--set",
         f"scenario.num_scans={SCANS}", "--no-rerun", "--viewer", "none", "--out", str(out)],
        capture_output=True, text=True, timeout=240, cwd=tmp_path, env=env())
    assert proc.returncode == 0, proc.stderr + proc.stdout
    names = [s.name for s in load_scenario("paris").sensors]
    results = pd.read_parquet(out / "results.parquet")
    for n in names:
        summary = json.loads((out / f"peer-{n}.json").read_text())
        assert summary["scans"] >= SCANS - 1 and summary["internal_errors"] == {}, n
        assert summary["stats"]["fusions"] >= SCANS - 1, n
        fused = results[(results.peer == n) & (results.estimate == "fused")].sort_values("scan")
        assert len(fused) >= SCANS - 1, n
        last = fused.iloc[-1]
        tracks, truth = np.stack(last.tracks), np.stack(last.truth)
        assert len(last.track_ids) == len(tracks) >= len(truth) // 2, n
        assert len(_ids([last.track_ids])[0]) == len(tracks), f"{n}: one id per track"
        gap = np.hypot(tracks[:, None, 0] - truth[None, :, 0],
                       tracks[:, None, 2] - truth[None, :, 2]).min(axis=1)
        assert np.mean(gap < NEAR) >= 0.8, f"{n}: tracks off the aircraft {np.sort(gap)}"
        # continuity: most of the last tick's ids were already there ten ticks earlier
        before, now = _ids(fused.track_ids.iloc[[-11, -1]])
        assert len(now & before) >= 0.5 * len(now), n
