"""Flooding as a peer mode (seed 004): the Forward message, the core's checks, the twin, the
communication cost against its closed form, and 5 real processes over Zenoh."""

from __future__ import annotations

import msgpack
import numpy as np
import pytest
from scipy.sparse.csgraph import shortest_path
from sensornet.peers.contracts import FusionInput
from sensornet.peers.flooding import FloodFuser, flooding_tuples
from sensornet.protocol.codec import VERSION, Limits, Rejected, decode, encode
from sensornet.protocol.keys import Keys
from sensornet.protocol.messages import Estimate, Forward, ScanSet
from sensornet.sim.run.launcher import format_summary, read_summaries, wait_run
from sensornet.sim.run.peers import make_peer
from sensornet.sim.run.twin import run_twin
from sensornet.sim.scenario import load_scenario
from sensornet.sim.world import generate_run
from sensornet.sim.world.build import adjacency
from sensornet.tracking.mixture import GaussianMixture

from tests.paced_world import SCAN_TIMEOUT, start_paced_run

# five sensors on a line 450 m apart, linked within 500 m: diameter 4, four iterations
LINE = {"sensors.positions": [[-900, 0], [-450, 0], [0, 0], [450, 0], [900, 0]],
        "sensors.radius": 500.0}
SCANS = 8


def _line(**more):
    return load_scenario("seed004", {**LINE, "scenario.num_scans": SCANS, **more})


def _fwd(scans: dict, sender="s1", k=1, r=0) -> Forward:
    return Forward(sender, k, ScanSet({o: np.asarray(z, float).reshape(-1, 2)
                                       for o, z in scans.items()}), round=r, seq=1,
                   send_time=1.0)


# -- the wire message -------------------------------------------------------------------------
def test_forward_round_trips():
    m = _fwd({"s1": [[1.0, 2.0], [3.0, 4.0]], "s7": np.zeros((0, 2)), "s3": [[5.0, 6.0]]},
             k=9, r=3)
    back = decode(encode(m))
    assert isinstance(back, Forward) and (back.sender, back.k, back.round) == ("s1", 9, 3)
    assert list(back.scans.scans) == ["s1", "s7", "s3"]
    for o, z in m.scans.scans.items():
        np.testing.assert_array_equal(back.scans.scans[o], z)
    assert back.scans.tuples() == 6 == m.scans.tuples()


def _raw(**fields) -> bytes:
    body = {"s": "s1", "k": 1, "r": 0, "q": 1, "ts": 1.0, "o": ["s1"], "n": [1],
            "x": np.zeros(2).tobytes()}
    body.update(fields)
    return msgpack.packb([VERSION, "F", *(body[f] for f in
                                          ("s", "k", "r", "q", "ts", "o", "n", "x"))],
                         use_bin_type=True)


@pytest.mark.parametrize("fields, reason", [
    ({"o": ["s1", "s1"], "n": [1, 0]}, "field"),                       # origin twice
    ({"n": [2]}, "shape"),                                              # counts != points
    ({"n": [1, 1]}, "shape"),                                           # counts != origins
    ({"n": [-1]}, "too-many"),                                          # negative count
    ({"n": ["1"]}, "field"),                                            # not an int
    ({"o": [""]}, "field"),                                             # empty name
    ({"o": ["x" * 65]}, "field"),                                       # name too long
    ({"o": [3]}, "field"),                                              # not a name
    ({"o": "s1"}, "field"),                                             # not a list
    ({"x": np.array([np.nan, 0.0]).tobytes()}, "nonfinite"),
    ({"x": b"\0" * 15}, "shape"),                                       # not whole points
    ({"o": [f"s{i}" for i in range(300)], "n": [0] * 300, "x": b""}, "too-many"),
    ({"k": -1}, "field"),
    ({"r": 2.5}, "field"),
])
def test_hostile_forwards_are_rejected_with_a_reason(fields, reason):
    with pytest.raises(Rejected) as exc:
        decode(_raw(**fields))
    assert exc.value.reason == reason


def test_forward_points_are_bounded_before_they_cost_memory():
    big = _raw(n=[30], x=np.zeros(60).tobytes())
    with pytest.raises(Rejected) as exc:
        decode(big, Limits(max_measurements=20))
    assert exc.value.reason == "too-many"


# -- the core's checks ------------------------------------------------------------------------
def _receive(core, msg, sender="s2"):
    core.receive(Keys("twin").estimate(sender), encode(msg), 0.1)
    return dict(core.rejected)


def test_core_refuses_foreign_origins_and_the_other_payload():
    scn = _line()
    flood = make_peer(scn, "s1")
    flood.receive(Keys("twin").scan("s1"), encode_scan("s1", 1), 0.0)
    assert _receive(flood, _fwd({"s99": [[0, 0]]}, sender="s2")) == {"spoofed": 1}
    gm = Estimate("s2", 1, GaussianMixture(np.ones(1), np.zeros((1, 4)), np.eye(4)[None]))
    assert _receive(flood, gm) == {"spoofed": 1, "incompatible": 1}
    phd = make_peer(load_scenario("seed004", {**LINE, "network.filter": "gmphd"}), "s1")
    assert _receive(phd, _fwd({"s2": [[0, 0]]}, sender="s2")) == {"incompatible": 1}


def encode_scan(name, k):
    from sensornet.protocol.messages import Scan

    return encode(Scan(name, k, np.zeros((0, 2)), seq=k, send_time=0.0))


# -- the flooding state in the consensus rounds -----------------------------------------------
def test_fuser_deduplicates_forwards_only_new_scans_and_counts_late_ones():
    f = FloodFuser("a", ["a", "b", "c", "d"], rounds=2)
    own = ScanSet({"a": np.ones((2, 2))})

    def fuse(r, nb):
        return f.fuse(FusionInput(1, r, own, {s: {"posterior": ScanSet(v)} for s, v in
                                               nb.items()}, [0.5, 0.5], np.zeros((0, 2))))

    pooled = fuse(0, {"b": {"b": np.zeros((1, 2)), "a": np.ones((2, 2))}})
    assert sorted(pooled.scans) == ["a", "b"] and f.counts["duplicates"] == 1
    assert list(f.outgoing(pooled).scans) == ["b"]  # "a" went out in iteration 1
    f.late("c", ScanSet({"c": np.zeros((3, 2))}), 1)  # after round 1, before the close
    assert f.counts["late_absorbed"] == 1
    pooled = fuse(1, {"b": {"c": np.zeros((3, 2))}})  # round 2 = the last: the scan closes
    assert sorted(pooled.scans) == ["a", "b", "c"]
    assert f.counts["duplicates"] == 2
    assert (f.counts["scans_closed"], f.counts["scans_complete"], f.counts["missing"]) == \
        (1, 0, 1)  # "d" never came
    f.late("b", ScanSet({"d": np.zeros((1, 2))}), 1)
    assert f.counts["late"] == 1


# -- the twin ---------------------------------------------------------------------------------
def _closed_form(scn, run: int) -> dict[str, int]:
    """Tuples each peer sends to its neighbours over the run, loss-free (peers.flooding)."""
    names, A = adjacency(scn)
    hops = shortest_path(A.astype(float), unweighted=True)
    _, scans = generate_run(scn, run)
    total = sum(flooding_tuples(hops, np.array([len(scans[i][k]) for i in range(len(names))]),
                                scn.network.rounds) for k in range(scn.num_scans))
    return dict(zip(names, (int(t) for t in total), strict=True))


def test_twin_every_peer_holds_every_scan_and_the_tuples_are_the_closed_form():
    scn = _line()
    res = run_twin(scn, 0)
    closed = _closed_form(scn, 0)
    for n in scn.sensor_names:
        s = res.summary(n)
        assert s["stop_reason"] == "end of run" and s["internal_errors"] == {}, n
        assert s["rejected_total"] == 0
        assert s["fuser"]["scans_closed"] == s["fuser"]["scans_complete"] == SCANS, n
        assert s["fuser"]["missing"] == 0 and s["fuser"].get("late", 0) == 0
        assert s["stats"]["tuples_to_neighbours"] == closed[n], n
        assert s["cost"]["tuples_per_scan"] == pytest.approx(closed[n] / SCANS)
        assert s["cost"]["estimate_bytes_per_scan"] > 8 * s["cost"]["tuples_published_per_scan"]
        assert s["mean_ospa_fused"] < 15.0, n  # 3 targets, every scan clustered
    # every peer pooled the same scans: the same estimate everywhere
    tracks = [res.tracks[n] for n in scn.sensor_names]
    for k in range(1, SCANS + 1):
        for t in tracks[1:]:
            np.testing.assert_allclose(t[k], tracks[0][k])
    # the middle peer (degree 2) sends every other peer's scan once to each neighbour, except
    # those arriving in the last iteration (none: it is 2 hops from either end)
    assert closed["s3"] > closed["s1"]
    assert "tuples / scan" in format_summary({n: res.summary(n) for n in scn.sensor_names})


def test_twin_gmphd_cost_is_fifteen_tuples_a_component_per_neighbour():
    scn = load_scenario("seed004", {**LINE, "scenario.num_scans": 5, "network.filter": "gmphd",
                                    "network.rounds": 2})
    res = run_twin(scn, 0)
    core = res.peers["s3"]
    st = core.consensus.stats
    assert st.tuples_to_neighbours == 2 * st.tuples_out and st.tuples_out % 15 == 0
    assert st.estimates_out == 2 * 5


def test_twin_flooding_survives_link_loss_and_counts_what_is_missing():
    scn = _line(**{"scenario.num_scans": 20, "faults.default.loss": 0.3})
    res = run_twin(scn, 0)
    fuser = [res.summary(n)["fuser"] for n in scn.sensor_names]
    assert all(f["scans_closed"] == 20 for f in fuser)
    missing = sum(f["missing"] for f in fuser)
    assert missing > 0  # a line has no redundancy: 30 % loss must cost scans
    assert all(f["scans_complete"] + min(f["missing"], 20) >= 20 for f in fuser)
    assert res.faults.counts()["drop-loss"] > 0


def test_twin_round_deadlines_let_a_slow_link_catch_up():
    # s2 -> s3 is slow (30 % of a scan interval): its forwards miss their round at s3 and are
    # pooled late (absorbed, then forwarded) within the scan's 0.8 deadline
    scn = _line()
    interval = scn.scan_period / scn.network.speed

    def delay(sender, receiver, msg):
        return 0.3 * interval if (sender, receiver) == ("s2", "s3") else 0.0

    res = run_twin(scn, 0, delay=delay)
    f = res.summary("s3")["fuser"]
    assert f["late_absorbed"] > 0
    assert res.summary("s3")["stats"]["deadline_fusions"] > 0
    assert f["scans_closed"] == SCANS


# -- real processes ---------------------------------------------------------------------------
PEER_SPEED = 0.02
"""The processes' ``--speed``: a 50 s scan interval, so their deadlines (0.9 of it, a round
11 s) are a fallback no process waits that long for: the world is paced by the peers
(tests/paced_world.py), the rounds run on arrivals as in the twin. Their rate buckets hold
a burst of 8 scans' estimates, truths and scans (:mod:`peers.admission`): enough for
:data:`SCANS` scans at any pace."""


def run_line_processes(out, **more):
    """The line of 5 flooding peers as real processes, every process exiting 0, and the twin
    of the same run. The world sends scan ``k + 1`` once every peer published its tracks of
    ``k`` (every copy of ``k`` arrived), not on the clock: at 1 s a scan and 225 ms rounds one
    copy of 8 scans came after its close at load 5 (CI of f9d3d1e), and a 2 s scan only moved
    the load at which that happens. ``more``: scenario settings on top (e.g.
    ``{"flooding.estimator": "ic"}``)."""
    settings = {**LINE, "scenario.num_scans": SCANS, "network.deadline": 0.9, **more}
    scn = load_scenario("seed004", settings)
    sets = [f"{key}={value}" for key, value in settings.items()]
    speed = {n: ["--speed", f"{PEER_SPEED:g}"] for n in scn.sensor_names}
    handle = start_paced_run(scn, "seed004", out, overrides=sets, rerun=False, peer_args=speed)
    try:
        codes = wait_run(handle, timeout=SCANS * 30 + SCAN_TIMEOUT)  # 30 s a scan: a failure
    finally:
        handle.stop_all()
    assert codes == {"world": 0, **{n: 0 for n in scn.sensor_names}}, codes
    return scn, read_summaries(out, scn.sensor_names), run_twin(scn, 0)


@pytest.mark.network
def test_five_flooding_processes_over_zenoh_hold_every_scan(tmp_path):
    # every round ran on its inputs' arrival (none at a deadline, no copy late): the twin's
    # every number, at any load (the real-time question is benchmarks/bench_flooding.py's)
    scn, summaries, twin = run_line_processes(tmp_path)
    closed = _closed_form(scn, 0)
    for n, s in summaries.items():
        assert s["stop_reason"] == "end of run" and s["scans"] == SCANS, n
        assert s["internal_errors"] == {} and s["rejected_total"] == 0, n
        assert s["fuser"]["scans_complete"] == SCANS and s["fuser"]["missing"] == 0, n
        assert s["fuser"].get("late_absorbed", 0) == s["fuser"].get("late", 0) == 0, n
        assert s["stats"]["deadline_fusions"] == 0, n
        assert s["stats"]["tuples_to_neighbours"] == closed[n], n
        assert s["estimate_bytes_sent"] == twin.summary(n)["estimate_bytes_sent"], n
        assert s["mean_ospa_fused"] == pytest.approx(twin.mean_ospa(n, "fused"), rel=1e-9), n
        assert s["cost"]["tuples_per_scan"] == pytest.approx(closed[n] / SCANS)


def test_offline_flooding_bytes_match_what_the_twin_peers_put_on_the_wire():
    from sensornet.peers.flooding import flooding_bytes

    scn = _line()
    res = run_twin(scn, 0)
    names, A = adjacency(scn)
    hops = shortest_path(A.astype(float), unweighted=True)
    _, scans = generate_run(scn, 0)
    offline = sum(flooding_bytes(hops, [scans[i][k] for i in range(len(names))],
                                 scn.network.rounds, names, k + 1).sum(axis=1)
                  for k in range(SCANS))
    deg = A.sum(axis=1)
    for i, n in enumerate(names):  # the same messages; only sequence numbers' sizes differ
        wire = res.peers[n].sent_bytes["estimate"] * deg[i]
        assert wire == pytest.approx(offline[i], rel=0.01), n


def test_rerun_view_of_a_flooding_peer_draws_scans_and_logs_the_cost():
    """A flooding peer's telemetry carries its cost, the scans it holds and a sample of the
    pooled points; the view draws them, and its own scan from its round-0 forward."""
    import rerun as rr
    from sensornet.peers.core import Publish, Record
    from sensornet.peers.observer import Observer
    from sensornet.protocol.bundle import unpack_bundle
    from sensornet.protocol.codec import decode, encode
    from sensornet.protocol.messages import Forward, ScanSet

    from sensornet.view import Batcher, ViewState

    scn = _line(**{"scenario.num_scans": 3})
    res = run_twin(scn, 0)
    core = res.peers["s3"]
    sent = []
    obs = Observer(core, 1.0).attach(sent.append)
    obs.record(Record("local", 3, {"n_points": 12}))
    obs.record(Record("fusion", 3, {"round": core.consensus.rounds, "n_inputs": 2,
                                    "n_fused": 5, "ages": {}}))
    obs.record(Record("cost", 3, {"tuples": 120, "tuples_published": 60, "bytes": 700}))
    obs.flush(idle=True, force=True)
    (msg,) = [decode(p) for b in sent for _, p in unpack_bundle(b).entries]  # one bundle
    assert msg.values["cost/tuples"] == 120 and msg.values["cost/bytes"] == 700
    assert msg.values["flooding/scans_held"] == 5
    assert msg.points["pooled"].shape[1] == 2 and len(msg.points["pooled"])  # in the plane
    assert msg.mixture is None  # raw scans: no mixture to draw
    assert msg.points["local"].shape[1] == 2 and "local/mixture" not in msg.points
    calls = {}

    class Rec:
        def send_columns(self, path, indexes, columns):
            calls[path] = list(columns)

    view = ViewState(Batcher(rr, Rec()), scn.sensor_names)
    view.message(msg)
    own = ScanSet({"s3": np.ones((4, 2)), "s2": np.zeros((2, 2))})
    view.receive("sensornet/n/estimate/s3", encode(Forward("s3", 3, own, round=0)))
    view.b.flush()
    for path in ("metrics/cost/s3/tuples", "metrics/cost/s3/bytes",
                 "metrics/flooding/s3/scans_held", "peers/s3/pooled", "peers/s3/local"):
        assert path in calls, path
    rows = calls["peers/s3/local"][0].as_arrow_array().to_pylist()
    assert len(rows[0]) == len(msg.points["local"])  # the own scan, from the telemetry
    assert len(rows[1]) == 4  # and from its round-0 forward (a view with --estimates)
    assert not any("means" in p for p in calls)
    out = [o for o in core.finish(99.0) if isinstance(o, Publish)]
    assert out == []  # nothing pending after the run
