"""What a live view hears, and what a watched peer sends for it (issue 38): the view
subscribes to no key the peers publish for each other (each put there would fan out to the
view too), so each scan's tracks go to it with the peer's report, the very bytes published."""

from __future__ import annotations

import subprocess
import sys
import threading

import numpy as np
import pytest
import rerun as rr
import zenoh
from sensornet.peers.core import Publish, Record
from sensornet.peers.observer import KINDS, HostReports, Observer, _heaviest
from sensornet.peers.runtime import PeerRuntime, RuntimeOptions
from sensornet.peers.session import DIAL_SOON, endpoint, free_port, zenoh_config
from sensornet.protocol.bundle import pack_bundles, unpack_bundle
from sensornet.protocol.codec import decode, encode
from sensornet.protocol.keys import Keys
from sensornet.protocol.messages import Telemetry, Tracks
from sensornet.protocol.report_bundle import unpack_reports
from sensornet.sim.run.peers import make_peer
from sensornet.sim.scenario import load_scenario
from sensornet.tracking.mixture import GaussianMixture

from sensornet import view as view_module
from sensornet.bag_play import restamp
from sensornet.view import Batcher, LiveView, ViewState
from tests.processes import env


class _Rec:
    """A recording stream that keeps what it is sent: entity -> (scan indexes, columns)."""

    def __init__(self) -> None:
        self.calls: dict[str, tuple[list[int], list]] = {}

    def send_columns(self, path, indexes, columns):
        self.calls[path] = (indexes[0].as_arrow_array().to_pylist(),
                            [c.as_arrow_array().to_pylist() for c in columns])


class _Session:
    """A Zenoh session that keeps the key expressions subscribed to."""

    def __init__(self) -> None:
        self.keys: list[str] = []

    def declare_subscriber(self, key, callback):
        self.keys.append(key)
        return self

    def undeclare(self) -> None:
        pass

    def close(self) -> None:
        pass


def _subscribed(monkeypatch, **kwargs) -> list[str]:
    session = _Session()
    monkeypatch.setattr(view_module.zenoh, "open", lambda conf: session)
    lv = LiveView("net", None, None, None, **kwargs)
    lv.open()
    lv.close()
    return session.keys


def test_the_view_hears_no_key_a_peer_publishes_for_others(monkeypatch):
    """Nothing a peer puts for its neighbours (estimates) or for nobody in particular
    (tracks) reaches a view; its reports and the world's messages do. ``--estimates``
    asks for the estimates, knowingly."""
    k = Keys("net")
    keys = _subscribed(monkeypatch)

    def heard(key: str, exprs: list[str]) -> bool:
        return any(zenoh.KeyExpr(e).intersects(zenoh.KeyExpr(key)) for e in exprs)

    assert not heard(k.tracks("s1"), keys) and not heard(k.estimate("s1"), keys)
    for key in (k.telemetry("s1"), k.telemetries("h1"), k.scan("s1"), k.scans("h1"),
                k.truth(), k.ctl()):
        assert heard(key, keys), key
    assert heard(k.estimate("s1"), _subscribed(monkeypatch, estimates=True))


def _scan(obs: Observer, k: int, n: int) -> bytes:
    """Scan ``k`` of a peer that scores nothing: a local step and ``n`` tracks published;
    returns the tracks' bytes as published."""
    obs.record(Record("local", k, {"n_components": n + 3, "n_published": n}), 1.5)
    tracks = Tracks(obs.name, k, np.full((n, 4), float(n)), send_time=1.0)
    payload = encode(tracks)
    obs.published(Publish("tracks", k, payload, tracks), 10.0)
    return payload


def test_a_scans_tracks_go_with_its_report_and_are_drawn_from_it():
    """A hosted peer's tracks ride in its host's message beside its report, the very bytes
    published (no copy, no encoding); a peer of its own process sends them with its report
    in one bundle on its own telemetry key: one put a scan, not two. The view draws both the
    same, as tracks of that peer."""
    scn = load_scenario("seed000", {"scenario.num_scans": 3})
    name = scn.sensor_names[0]
    bundles: list[bytes] = []
    reports = HostReports(bundles.append)
    hosted = reports.add(Observer(make_peer(scn, name, score_truth=False)))
    own: list[bytes] = []
    alone = Observer(make_peer(scn, name, score_truth=False)).attach(own.append)
    published = {}
    for obs in (hosted, alone):
        obs.core.wants_truth = False
        published[id(obs)] = _scan(obs, 4, 2)
        obs.flush(idle=True, host=True)
    reports.send()
    (msg,) = [unpack_reports(b) for b in bundles]
    assert [n for n, _ in msg.entries] == [r.sender for r in msg.reports] == [name]
    assert msg.entries[0][1] == published[id(hosted)] and len(own) == 1  # one put
    (alone_entries,) = [unpack_bundle(b).entries for b in own]
    assert [n for n, _ in alone_entries] == [name, name]
    assert alone_entries[0][1] == published[id(alone)]  # the bytes as published
    assert isinstance(decode(alone_entries[1][1]), Telemetry) and hosted.sent == alone.sent == 1
    drawn = []
    for heard in ([("sensornet/net/telemetries/h1", bundles[0])],
                  [(f"sensornet/net/telemetry/{name}", b) for b in own]):
        rec = _Rec()
        state = ViewState(Batcher(rr, rec), [name])
        for key, payload in heard:
            state.receive(key, payload)
        state.b.flush()
        assert state.rejected == 0 and state.handled == 2
        scans, columns = rec.calls[f"peers/{name}/tracks"]
        assert scans == [4] and len(state.lag_ms) == 1
        drawn.append(columns)
    assert drawn[0] == drawn[1]
    assert np.allclose(np.asarray(drawn[0][0][0]), [[2.0, -2.0], [2.0, -2.0]])  # north up


def test_a_watched_runtime_hands_the_observer_only_what_it_reads():
    """The runtime passes the observer the tracks it published and the records of the
    kinds it reads (:data:`peers.observer.KINDS`), none of the rest (most records are
    estimates': a call each for nothing); the report then carries the tracks' bytes."""
    scn = load_scenario("seed000", {"scenario.num_scans": 3})
    rt = PeerRuntime(make_peer(scn, scn.sensor_names[0], network="net", score_truth=False),
                     RuntimeOptions(rerun=False))
    rt.core.wants_truth = False
    put: list[tuple[str, bytes]] = []
    rt.transport.publish = lambda channel, payload: put.append((channel, payload))
    sent: list[bytes] = []
    rt.observer.attach(sent.append)
    seen: list[str] = []
    record = rt.observer.record
    rt.observer.record = lambda r, ms=None: (seen.append(r.kind), record(r, ms))
    tracks = Tracks(rt.name, 3, np.zeros((1, 4)))
    est = Publish("estimate", 3, b"estimate bytes", None)
    outputs = [est, Publish("tracks", 3, encode(tracks), tracks),
               Record("estimate", 3, {"sender": "x"}), Record("local", 3, {"n_components": 2}),
               Record("fusion-input", 3, {})]
    rt._carry_out("tick", lambda now: outputs, 100.0)
    assert [c for c, _ in put] == ["estimate", "tracks"]
    assert seen == ["local"] and set(seen) <= KINDS
    rt.observer.flush(idle=True)
    ((_, tracks_bytes), (_, report)) = unpack_bundle(sent[0]).entries
    assert len(sent) == 1 and tracks_bytes == put[1][1] and decode(report).k == 3


def test_the_fused_marks_are_the_heaviest_position_blocks_that_can_be_drawn():
    """``_heaviest``: the ``n`` heaviest components, heaviest first, as 4-D position
    marginals (a 6-D IMM state's px, py in columns 0 and 3), each block symmetrised and
    floored; a block that is not positive definite even then is left out."""
    cov = np.tile(np.eye(6), (5, 1, 1))
    cov[0][np.ix_([0, 3], [0, 3])] = [[4.0, 1.0], [3.0, 9.0]]  # asymmetric: b = 2
    cov[1][np.ix_([0, 3], [0, 3])] = [[-1.0, 0.0], [0.0, 1.0]]  # indefinite: out
    cov[2][np.ix_([0, 3], [0, 3])] = [[1.0, 5.0], [5.0, 1.0]]  # det < 0: out
    cov[3][np.ix_([0, 3], [0, 3])] = 0.0  # floored at 1e-9 of its trace: kept
    means = np.arange(30, dtype=float).reshape(5, 6)
    mix = GaussianMixture.trusted(np.array([0.9, 0.8, 0.7, 0.6, 0.1]), means, cov)
    got = _heaviest(mix, 4)  # the lightest (0.1) is not among the 4 heaviest
    assert got.weights.tolist() == [0.9, 0.6]
    assert got.means[:, [0, 2]].tolist() == [[0.0, 3.0], [18.0, 21.0]]
    assert got.means[:, [1, 3]].tolist() == [[0.0, 0.0], [0.0, 0.0]]
    assert np.allclose(got.covs[0][np.ix_([0, 2], [0, 2])], [[4.0, 2.0], [2.0, 9.0]], rtol=1e-8)
    assert np.allclose(got.covs[:, [1, 3], [1, 3]], 1.0)
    assert 0.0 < got.covs[1, 0, 0] < 1e-12 and got.covs[1, 0, 2] == 0.0


def test_a_report_key_carries_its_own_peers_messages_only():
    """Tracks (or a report) under another peer's name on ``telemetry/<peer>``, alone or in a
    host's bundle, are counted as refused, not drawn as that peer's: the view hears tracks
    there now, and a peer may put only its own telemetry key."""
    rec = _Rec()
    state = ViewState(Batcher(rr, rec), ["s1", "s2"])
    theirs = encode(Tracks("s2", 1, np.zeros((1, 4))))
    state.receive("sensornet/net/telemetry/s1", theirs)
    state.receive("sensornet/net/telemetries/h1",
                  pack_bundles(0, [("s1", theirs), ("s2", theirs)])[0])
    state.receive("sensornet/net/telemetry/s1", encode(Telemetry("s2", 1, {"age": 1.0})))
    state.b.flush()
    assert state.rejected == 3 and state.handled == 1  # the bundle's s2 entry drawn
    assert set(rec.calls) == {"peers/s2/tracks", "peers/s2/tail",
                              "metrics/cardinality/s2/fused"}
    # a peer's own bundle on its key (its tracks and reports, one put): its entries only,
    # and no bundle inside a bundle (refused, not unpacked again)
    mine = encode(Tracks("s1", 2, np.zeros((1, 4))))
    inside = pack_bundles(0, [("s1", mine)])[0]
    state.receive("sensornet/net/telemetry/s1",
                  pack_bundles(0, [("s1", mine), ("s2", theirs), ("s1", inside)])[0])
    state.receive("sensornet/net/telemetry/s1", b"\x92not a bundle")
    state.b.flush()
    assert state.rejected == 3 + 3 and state.handled == 2
    assert rec.calls["peers/s1/tracks"][0] == [2]


@pytest.mark.network
def test_a_watched_peer_of_its_own_process_makes_one_put_a_scan(tmp_path):
    """A real run over Zenoh on loopback (3 peers, a process each, no view of its own) with
    a session of this test subscribed to the report keys: each peer's puts there are bundles
    of its own tracks and reports, one put a scan (before, its tracks and its report were two
    puts a scan), the tracks beside their scan's report, and no host bundle (no host)."""
    ep = endpoint(free_port())
    k = Keys("oneput")
    heard: list[tuple[str, bytes]] = []
    lock = threading.Lock()

    def on_sample(sample) -> None:
        with lock:
            heard.append((str(sample.key_expr), sample.payload.to_bytes()))

    session = zenoh.open(zenoh_config((), [ep], retry=DIAL_SOON))
    subs = []
    try:
        subs = [session.declare_subscriber(e, on_sample)
                for e in (k.telemetry(), k.telemetries())]
        run = subprocess.run(
            [sys.executable, "-m", "sensornet", "run", "--network", "oneput", "--listen", ep,
             "--no-rerun", "--set", "scenario.num_scans=20", "--speed", "5",
             "--out", str(tmp_path / "run")], cwd=tmp_path, env=env(), capture_output=True,
            text=True, timeout=300)  # returns when the run has ended: the event waited for
        assert run.returncode == 0, run.stderr[-2000:]
    finally:
        for sub in subs:
            sub.undeclare()
        session.close()
    with lock:
        heard = list(heard)
    names = load_scenario("seed000").sensor_names
    assert {key.rsplit("/", 1)[-1] for key, _ in heard} == set(names)
    assert not any("/telemetries/" in key for key, _ in heard)
    for name in names:
        puts = [p for key, p in heard if key == k.telemetry(name)]
        reports, tracks = [], set()
        for put in puts:
            entries = unpack_bundle(put).entries  # a bundle, or Rejected: the test fails
            assert {n for n, _ in entries} == {name}
            msgs = [decode(p) for _, p in entries]
            tracks |= {m.k for m in msgs if isinstance(m, Tracks)}
            reports += [m.k for m in msgs if isinstance(m, Telemetry)]
        assert len(reports) >= 10, (name, reports)  # of 20 scans: the first may go unheard
        # at most one put a scan; the end's flush may add one (what came after a scan's
        # report was sent: a trust event as the neighbours leave)
        assert len(puts) <= len(set(reports)) + 1, (name, len(puts), reports)
        assert tracks <= set(reports) and len(tracks) >= len(reports) - 2, (name, tracks)


def test_a_peer_s_own_bundle_is_restamped_when_played():
    """``sensornet play`` sets each message's send time to when it puts it again (the view's
    lag is measured from it): in a peer's own bundle on its report key, every entry's, as in
    a host's bundle; a plain report as before."""
    tracks = encode(Tracks("s1", 3, np.zeros((1, 4)), send_time=5.0))
    report = encode(Telemetry("s1", 3, {"age": 1.0}, send_time=5.0))
    (own,) = pack_bundles(0, [("s1", tracks), ("s1", report)])
    again = restamp("sensornet/net/telemetry/s1", own, 99.0)
    assert [decode(p).send_time for _, p in unpack_bundle(again).entries] == [99.0, 99.0]
    assert decode(restamp("sensornet/net/telemetry/s1", report, 99.0)).send_time == 99.0
