"""``sensornet play`` of a part of a bag (issue 35 item 3): the world's part (``--only world``)
selected, played after the peers are ready (``--peers``), and fresh peers fed only from it
compute the recorded run's fused tracks: bit for bit on the twin (a twin run written as
``sensornet record`` would have, :mod:`sensornet.bag_twin`)."""

from __future__ import annotations

import json
import threading
from dataclasses import replace

import numpy as np
import pytest
import zenoh
from sensornet.protocol.bundle import pack_bundles, unpack_bundle
from sensornet.protocol.codec import decode
from sensornet.protocol.json_fields import fields
from sensornet.protocol.messages import Scan, Tracks
from sensornet.sim.scenario import load_scenario, parse_overrides, scenario_text
from sensornet.sim.world import generate_run

from sensornet.bag import Bag, Item, await_peers, is_world, play, read_bag, select
from sensornet.bag_play import restamp
from sensornet.bag_twin import EPOCH, bag_events, bag_scenario, play_twin, twin_bag
from sensornet.cli import main

SETS = ["scenario.num_scans=15"]


@pytest.fixture(scope="module")
def twin_recording(tmp_path_factory):
    """A 15-scan seed-000 twin run and the bag of everything its network carried."""
    scn = load_scenario("seed000", overrides=parse_overrides(SETS))
    path = tmp_path_factory.mktemp("bag") / "twin.mcap"
    result = twin_bag(path, scn)
    meta, items = read_bag(path)
    return scn, result, meta, items


def _recorded_tracks(items: list[Item], peer: str) -> dict[int, np.ndarray]:
    """A peer's fused tracks as the bag holds them (its ``tracks/<peer>`` messages)."""
    out = {}
    for it in items:
        if it.alive is None and it.key.endswith(f"/tracks/{peer}"):
            msg = decode(it.payload)
            assert isinstance(msg, Tracks)
            out[msg.k] = msg.states
    return out


def test_the_world_part_is_what_the_world_published(twin_recording):
    _, _, _, items = twin_recording
    world, peers = select(items, "world"), select(items, "peers")
    assert len(world) + len(peers) == len(items)
    chans = {it.key.split("/")[2] for it in world if it.alive is None}
    assert chans == {"scan", "truth", "ctl"}
    assert {it.key for it in world if it.alive is not None} == {"sensornet/twin/alive/world"}
    assert {it.key.split("/")[2] for it in peers} == {"estimate", "tracks", "alive", "ready"}
    assert not any(is_world(it) for it in peers)
    scans = select(items, keys=["sensornet/*/scan/**"])
    assert len(scans) == 3 * 15 and all(isinstance(decode(it.payload), Scan) for it in scans)
    assert select(items, "peers", ["sensornet/twin/scan/*"]) == []
    with pytest.raises(ValueError, match="one of world, peers"):
        select(items, "truths")
    with pytest.raises(ValueError, match="not a Zenoh key expression"):
        select(items, keys=["sensornet//scan"])


def test_fresh_peers_fed_the_bags_world_give_its_fused_tracks_bit_for_bit(twin_recording):
    scn, result, _, items = twin_recording
    played = play_twin(select(items, "world"), scn)
    for n in scn.sensor_names:
        recorded = _recorded_tracks(items, n)
        assert sorted(recorded) == list(range(1, scn.num_scans + 1)), n
        assert sorted(played.tracks[n]) == sorted(recorded), n
        for k, x in recorded.items():
            assert np.array_equal(played.tracks[n][k], x), (n, k)
            assert np.array_equal(result.tracks[n][k], x), (n, k)
        assert played.peers[n].snapshot()["scans"] == scn.num_scans
        assert played.peers[n].mean_ospa("fused") == result.peers[n].mean_ospa("fused")
        assert played.stops[n] == result.stops[n]


def test_a_scan_missing_from_the_bag_changes_the_tracks(twin_recording):
    """The check can fail: without s1's scan 5 the played peers' tracks differ."""
    scn, _, _, items = twin_recording
    world = [it for it in select(items, "world") if not it.key.endswith("/scan/s1")
             or decode(it.payload).k != 5]
    played = play_twin(world, scn)
    for n in scn.sensor_names:  # s1 misses scan 5; its neighbours fuse without its estimate
        recorded = _recorded_tracks(items, n)
        differ = [k for k, x in recorded.items()
                  if k in played.tracks[n] and not np.array_equal(played.tracks[n][k], x)]
        assert differ and min(differ) <= 6, n
    assert 5 not in played.tracks["s1"]
    assert played.peers["s1"].snapshot()["scans"] == scn.num_scans - 1


def _bundled(items: list[Item], hosts: dict[str, list[str]]) -> list[Item]:
    """``items`` with each scan index's scans packed, as the world does for peer hosts, into
    one bundle per host (``scans/<host>``) at the time of the host's first scan."""
    out, scans = [], {}
    for it in items:
        if it.alive is None and "/scan/" in it.key:
            msg = decode(it.payload)
            scans.setdefault(msg.k, []).append((it, msg.sensor))
        else:
            out.append(it)
    for k, group in scans.items():
        for h, members in hosts.items():
            mine = [(it, s) for it, s in group if s in members]
            (payload,) = pack_bundles(k, [(s, it.payload) for it, s in mine])
            out.append(Item(mine[0][0].t, f"sensornet/twin/scans/{h}", payload))
    return sorted(out, key=lambda it: it.t)


def test_scan_bundles_give_the_twins_peers_the_same_tracks(twin_recording):
    """A bag of a peer-hosts run holds a bundle per host and scan (``scans/<host>``): the
    twin hands each entry to its sensor's peer, as a host does, and the tracks stay bit for
    bit; a bundle that does not unpack is a one-line error."""
    scn, _, _, items = twin_recording
    world = _bundled(select(items, "world"), {"h1": ["s1", "s2"], "h2": ["s3"]})
    assert not any("/scan/" in it.key for it in world)
    assert len([it for it in world if "/scans/" in it.key]) == 2 * scn.num_scans
    played = play_twin(world, scn)
    for n in scn.sensor_names:
        recorded = _recorded_tracks(items, n)
        assert sorted(played.tracks[n]) == sorted(recorded), n
        assert all(np.array_equal(played.tracks[n][k], x) for k, x in recorded.items()), n
    with pytest.raises(ValueError, match="scans/h1: not a scan bundle"):
        bag_events([Item(EPOCH, "sensornet/twin/scans/h1", b"\x93")], scn.sensor_names)


def test_the_twin_refuses_the_peers_part(twin_recording):
    scn, _, _, items = twin_recording
    with pytest.raises(ValueError, match="not the world's"):
        bag_events(items, scn.sensor_names)


class _Session:
    """A session that notes what ``play`` does: ``log`` of (what, key)."""

    def __init__(self) -> None:
        self.log: list[tuple[str, str]] = []
        self.puts: list[bytes] = []
        session = self

        class Pub:
            def __init__(self, key):
                self.key = key

            def put(self, payload):
                session.log.append(("put", self.key))
                session.puts.append(payload)

            def undeclare(self):
                pass

        class Tok:
            def __init__(self, key):
                self.key = key

            def undeclare(self):
                session.log.append(("undeclare", self.key))

        self._pub, self._tok = Pub, Tok

    def declare_publisher(self, key, **kw):
        self.log.append(("publisher", key))
        return self._pub(key)

    def liveliness(self):
        session = self

        class L:
            def declare_token(self, key):
                session.log.append(("token", key))
                return session._tok(key)

        return L()


def test_the_gate_runs_before_the_first_message_and_the_pace_counts_from_it():
    items = [Item(100.0, "sensornet/n/alive/world", alive=True),
             Item(130.0, "sensornet/n/ctl", b"start"),
             Item(131.0, "sensornet/n/scan/s1", b"k1"),
             Item(133.0, "sensornet/n/scan/s1", b"k2"),
             Item(134.0, "sensornet/n/alive/world", alive=False)]
    session, now, slept = _Session(), [0.0], []

    def sleep(dt):
        slept.append(dt)
        now[0] += dt

    def gate(pubs):
        assert session.log == [("token", "sensornet/n/alive/world"),
                               ("publisher", "sensornet/n/ctl"),
                               ("publisher", "sensornet/n/scan/s1")]
        assert sorted(pubs) == [("sensornet/n/ctl", ""), ("sensornet/n/scan/s1", "")]
        now[0] += 50.0  # the peers took their time

    n = play(items, session, rate=2.0, clock=lambda: now[0], sleep=sleep, gate=gate,
             stop=threading.Event())
    assert n == 3
    assert [w for w in session.log if w[0] != "publisher"] == [
        ("token", "sensornet/n/alive/world"), ("put", "sensornet/n/ctl"),
        ("put", "sensornet/n/scan/s1"), ("put", "sensornet/n/scan/s1"),
        ("undeclare", "sensornet/n/alive/world")]
    assert sum(slept) == pytest.approx((134.0 - 130.0) / 2.0)  # not the 30 s before the gate


def test_play_refuses_a_bad_selection_in_one_line(tmp_path, capsys):
    """Refused before any session opens: exit code 2, one line naming the flag."""
    scn = load_scenario("seed000", overrides=parse_overrides(SETS))
    bag = tmp_path / "twin.mcap"
    twin_bag(bag, scn)
    cases = [(["--keys", "sensornet//scan"], "not a Zenoh key expression"),
             (["--keys", "sensornet/other/**"], "no messages of the selected keys"),
             (["--peers", "s1,world"], "reserved"),
             (["--wait", "0"], "--wait must be positive")]
    for flags, what in cases:
        assert main(["play", str(bag), *flags]) == 2, flags
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and what in err[0], (flags, err)


@pytest.mark.network  # a Zenoh session (no endpoint: nothing answers)
def test_play_says_which_peers_never_came(tmp_path, capsys):
    scn = load_scenario("seed000", overrides=parse_overrides(SETS))
    bag = tmp_path / "twin.mcap"
    twin_bag(bag, scn, network="nobodyhere")
    assert main(["play", str(bag), "--only", "world", "--peers", "s1,s2", "--wait", "1"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and "once s1, s2 are ready" in err[0], err  # what it would play
    assert err[1] == "play: peers s1, s2 not ready on network 'nobodyhere' (not within 1 s)"


def _same_but_time(a: bytes, b: bytes, t: float) -> bool:
    """Whether ``b`` decodes to ``a``'s message with send time ``t`` (every field compared)."""
    return fields(decode(b)) == fields(replace(decode(a), send_time=t))


def test_restamp_changes_the_send_time_and_no_other_byte(twin_recording):
    """Every message a network carries (the world's and the peers'): re-stamped, it is the
    same message sent at the new time; re-stamped with its own time, the same bytes."""
    _, _, _, items = twin_recording
    samples = [it for it in items if it.alive is None]
    assert {it.key.split("/")[2] for it in samples} == {"scan", "truth", "ctl", "estimate",
                                                        "tracks"}
    for it in samples:
        again = restamp(it.key, it.payload, 1.7e9 + 0.25)
        assert again is not None and _same_but_time(it.payload, again, 1.7e9 + 0.25), it.key
        assert restamp(it.key, it.payload, decode(it.payload).send_time) == it.payload, it.key


def test_restamp_stamps_every_scan_of_a_bundle_and_leaves_what_it_cannot_read(twin_recording):
    _, _, _, items = twin_recording
    scans = [it.payload for it in items if it.alive is None and "/scan/" in it.key
             and decode(it.payload).k == 3]
    assert len(scans) == 3
    (bundle,) = pack_bundles(3, [(decode(p).sensor, p) for p in scans])
    for key in ("sensornet/twin/scans/h1", "sensornet/twin/telemetries/h1"):  # a host's
        again = unpack_bundle(restamp(key, bundle, 42.0))
        assert again.k == 3 and [s for s, _ in again.entries] == ["s1", "s2", "s3"]
        assert all(_same_but_time(p, q, 42.0) for p, (_, q) in zip(scans, again.entries,
                                                                   strict=True))
    sealed = scans[0] + bytes(76)  # a signed message: payload | stamp | signature | tag
    for key, payload in [("sensornet/twin/scan/s1", sealed), ("sensornet/twin/ctl", b"start"),
                         ("sensornet/twin/scans/h1", scans[0]),  # a scan is no bundle
                         ("sensornet/twin/scans/h1", pack_bundles(3, [("s1", sealed)])[0])]:
        assert restamp(key, payload, 42.0) is None, key


def test_play_stamps_each_message_as_it_puts_it(twin_recording):
    """What a played world's peers measure latency from: the time of the put (``stamp``),
    not the recording's; ``stamp=None`` (``--keep-stamps``) puts the recorded bytes."""
    _, _, _, items = twin_recording
    world = [it for it in select(items, "world") if it.alive is None][:8]
    assert len({decode(it.payload).send_time for it in world}) > 1
    session, clock = _Session(), iter(range(1000, 2000))
    play(world, session, rate=1e6, stamp=lambda: float(next(clock)))
    assert len(session.puts) == len(world)
    for i, (it, put) in enumerate(zip(world, session.puts, strict=True)):
        assert _same_but_time(it.payload, put, 1000.0 + i), it.key
    session = _Session()
    play(world, session, rate=1e6, stamp=None)
    assert session.puts == [it.payload for it in world]


def test_a_bag_holds_the_runs_scenario_when_record_is_given_it(tmp_path, capsys):
    """``record --scenario SRC --set ...`` writes the scenario to the bag's metadata; loaded
    back (bag_scenario) it makes the same world as the scenario loaded from its name; a bad
    one is refused in one line before anything is recorded."""
    sets = ["scenario.num_scans=7", "sensors.s2.clutter_rate=3"]
    want = load_scenario("seed000", overrides=parse_overrides(sets))
    meta = {"scenario_text": scenario_text("seed000"),
            "scenario_file": "seed000.toml", "overrides": json.dumps(sets)}
    bag = Bag(tmp_path / "b.mcap", "net", scenario=meta)
    bag.open()
    bag.close()
    got_meta, _ = read_bag(tmp_path / "b.mcap")
    assert {k: got_meta[k] for k in meta} == meta
    got = bag_scenario(got_meta)
    assert got.num_scans == 7 and got.sensors[1].clutter_rate == 3
    for a, b in zip(generate_run(got, 0)[1], generate_run(want, 0)[1], strict=True):
        assert all(np.array_equal(x, y) for x, y in zip(a, b, strict=True))
    assert bag_scenario({"network": "net"}) is None
    out = tmp_path / "r.mcap"
    for flags, what in [(["--scenario", "nosuch"], "nosuch"),
                        (["--scenario", "seed000", "--set", "nosuch.key=1"], "nosuch"),
                        (["--set", "scenario.num_scans=3"], "--set changes the --scenario")]:
        assert main(["record", "net", "-o", str(out), *flags]) == 2, flags
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and what in err[0], (flags, err)
    assert not out.exists()


class _Matching:
    """A publisher whose subscriber reaches it at its ``after``-th look (None: never)."""

    def __init__(self, after: int | None) -> None:
        self.after, self.looks = after, 0

    @property
    def matching_status(self):
        self.looks += 1
        return type("Status", (), {"matching": self.after is not None
                                   and self.looks >= self.after})()


def test_the_gate_waits_for_the_scan_bundles_subscribers_as_the_world_does():
    """A run of peer hosts gets its scans in bundles (``scans/<host>``): once the peers are
    ready, ``play``'s gate still waits until every bundle publisher has its host's subscriber
    (as the world does), and not for scans of peers it does not wait for."""
    subs = []

    class Liveliness:
        def declare_subscriber(self, expr, cb, history):
            subs.append(cb)
            return type("Sub", (), {"undeclare": lambda self: None})()

    session = type("S", (), {"liveliness": lambda self: Liveliness()})()
    gate = await_peers(session, "n", ["s1", "s2"], timeout=30.0)
    for name in ("s1", "s2"):
        subs[0](type("Sample", (), {"key_expr": f"sensornet/n/ready/{name}",
                                    "kind": zenoh.SampleKind.PUT})())
    pubs = {("sensornet/n/scans/h1", ""): _Matching(3), ("sensornet/n/scans/h2", ""):
            _Matching(5), ("sensornet/n/scan/s9", ""): _Matching(None),
            ("sensornet/n/ctl", ""): _Matching(None)}
    gate(pubs)
    assert pubs[("sensornet/n/scans/h2", "")].looks >= 5  # waited for h2's host
    assert pubs[("sensornet/n/scans/h1", "")].looks >= 3
    assert pubs[("sensornet/n/scan/s9", "")].looks == pubs[("sensornet/n/ctl", "")].looks == 0
