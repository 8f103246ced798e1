"""Track identities over real Zenoh on loopback: the world and 3 GM-PHD peer processes of
seed 000. Every peer publishes Tracks protocol 2 with ids, the peers agree on the ids of the
targets, and results.parquet carries the track_ids, track_status and truth_ids columns."""

from __future__ import annotations

import threading

import numpy as np
import pytest
from sensornet.peers.labelling import origin_of
from sensornet.peers.scan_results import merge_parts, read_table
from sensornet.peers.session import DIAL_SOON, open_session
from sensornet.protocol.codec import decode
from sensornet.protocol.keys import Keys
from sensornet.protocol.messages import Tracks
from sensornet.sim.run.launcher import start_run, wait_run
from sensornet.sim.scenario import load_scenario
from sensornet.tracking.label_keys import SHARED_ORIGIN

pytestmark = pytest.mark.network

SCANS = 40


@pytest.fixture(scope="module")
def labelled_run(tmp_path_factory):
    """One short seed-000 run; every Tracks payload the peers publish is kept."""
    out = tmp_path_factory.mktemp("labelled")
    sets = [f"scenario.num_scans={SCANS}"]
    scn = load_scenario("seed000", overrides={"scenario.num_scans": SCANS})
    handle = start_run(scn, "seed000", out, overrides=sets, rerun=False)
    got: list[bytes] = []
    lock = threading.Lock()
    try:
        # dial as the view does (every 0.1-0.5 s): with Zenoh's default back-off (1 s doubling
        # to 4 s) a session opened before the world listens links seconds into a 4 s run
        session = open_session(connect=list(handle.endpoints.values()), retry=DIAL_SOON)
        try:
            def on_tracks(sample) -> None:
                with lock:
                    got.append(sample.payload.to_bytes())

            sub = session.declare_subscriber(Keys(handle.network).tracks("*"), on_tracks)
            codes = wait_run(handle, timeout=SCANS / 10 + 120)
            sub.undeclare()
        finally:
            session.close()
    finally:
        handle.stop_all()
    merge_parts(sorted(out.glob("*.scans.msgpack")), out / "results.parquet")  # as `run` does
    yield scn, out, codes, got


def test_published_tracks_are_protocol_2_with_ids(labelled_run):
    scn, out, codes, payloads = labelled_run
    assert codes == {"world": 0, "s1": 0, "s2": 0, "s3": 0}, codes
    msgs = [decode(p) for p in payloads]
    # every peer's tracks of every scan from the first one the subscriber heard (it may link
    # a few scans into the run on a loaded machine), and it heard most of the run
    k0 = min(m.k for m in msgs)
    assert k0 <= SCANS // 2, k0
    assert len(msgs) >= 3 * (SCANS - k0) - 3, (len(msgs), k0)
    assert all(p[1] == 2 for p in payloads)
    assert all(isinstance(m, Tracks) and m.ids is not None and m.status is not None
               and m.covs is not None and m.existence is not None for m in msgs)
    assert sum(len(m.ids) for m in msgs) > SCANS
    # one id per target everywhere: a scan's confirmed id sets agree between the peers nearly
    # always (tentative tracks are each peer's own until confirmed: a clutter birth at one
    # peer, a young track stamped a scan apart; on a loaded machine 5 of 40 scans differed so)
    by = {}
    for m in msgs:
        confirmed = m.status == Tracks.CONFIRMED
        by.setdefault(m.k, {})[m.sender] = {tuple(i) for i in m.ids[confirmed].tolist()}
    full = [v for v in by.values() if len(v) == 3]
    same = sum(1 for v in full if v["s1"] == v["s2"] == v["s3"])
    assert len(full) >= SCANS // 2 and same >= 0.9 * len(full), (same, len(full))
    assert sum(1 for v in full if v["s1"]) >= 0.75 * len(full), full  # not agreeing on nothing


def test_results_table_has_the_id_columns(labelled_run):
    scn, out, codes, _ = labelled_run
    cols, _meta = read_table(out / "results.parquet")
    fused = [i for i, e in enumerate(cols["estimate"]) if e == "fused" and cols["scored"][i]]
    assert fused
    for i in fused:
        assert len(cols["track_ids"][i]) == len(cols["tracks"][i])
        assert len(cols["track_status"][i]) == len(cols["tracks"][i])
        assert len(cols["truth_ids"][i]) == len(cols["truth"][i])
    ids = np.array([r for i in fused for r in cols["track_ids"][i]])
    # every id's origin is a peer of this network (shared births: SHARED_ORIGIN and the
    # peers' 1 + index; else the index): a split or a fusion's fresh label may be any peer's
    names = [s.name for s in scn.sensors]
    shared = scn.network.birth_ids == "shared" and scn.birth.model != "measurements"
    origins = ({SHARED_ORIGIN} | {SHARED_ORIGIN + 1 + origin_of(names, n) for n in names}
               if shared else {origin_of(names, n) for n in names})
    assert ids.shape[1] == 3 and set(ids[:, 0].tolist()) <= origins, set(ids[:, 0].tolist())
    assert {t for i in fused for t in cols["truth_ids"][i]} == {1, 2, 3, 4}
