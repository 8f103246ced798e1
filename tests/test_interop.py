"""Formats other tools read (issue 35 items 2-4): recordings that the ``mcap`` reader and
``json.loads`` decode (with a Foxglove scene), bags recorded from and played onto a live
network, ``echo --json``, ``load_run``, the results table's JSON metadata, Stone Soup export."""

from __future__ import annotations

import base64
import json
import subprocess
import sys
import threading
from types import SimpleNamespace

import jsonschema
import msgpack
import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer
from sensornet.peers.recording import Recorder, read
from sensornet.peers.scan_results import COLUMNS, LIST_COLUMNS, UNITS, read_table
from sensornet.peers.session import endpoint, free_port, open_session
from sensornet.protocol.codec import encode
from sensornet.protocol.messages import Scan, Tracks
from sensornet.sim.run.launcher import start_run, wait_run
from sensornet.sim.scenario import load_scenario, parse_overrides
from sensornet.sim.scenario.loader import scenario_text
from stonesoup.metricgenerator.ospametric import GOSPAMetric, OSPAMetric

from sensornet.api import load_run, scenario, simulate
from sensornet.bag import play, read_bag
from sensornet.cli import main
from tests.processes import env, wait_for


def _generic_read(path):
    """Every message of an MCAP file with the ``mcap`` reader and ``json.loads`` alone:
    ``[(topic, schema name, schema (dict), body (dict))]``."""
    out = []
    with open(path, "rb") as fh:
        for schema, channel, message in make_reader(fh).iter_messages(log_time_order=True):
            assert channel.message_encoding == "json" and schema.encoding == "jsonschema"
            out.append((channel.topic, schema.name, json.loads(schema.data),
                        json.loads(message.data)))
    return out


def _record_one(path):
    """A recording of one peer's scan and labelled tracks, the truth and scene attached."""
    rec = Recorder(path, {"peer": "s1", "network": "net",
                          "scenario_text": scenario_text("seed000")})
    truth = np.array([[10.0, 1.0, 20.0, -1.0], [300.0, 0.0, -50.0, 2.0]])
    rec.attach(SimpleNamespace(scorer=SimpleNamespace(
        pos=[0, 2], truth=lambda k: truth, truth_ids=lambda k: np.array([7, 9]))))
    scan = encode(Scan("s1", 3, np.array([[1.5, 2.5], [3.0, -4.0]]), seq=4, send_time=5.25))
    covs = np.stack([np.diag([400.0, 1, 100, 1]), np.array(
        [[300.0, 0, 120, 0], [0, 1, 0, 0], [120, 0, 200, 0], [0, 0, 0, 1]])])
    tracks = Tracks("s1", 3, np.array([[12.0, 1, 18, -1], [290, 0, -45, 2]]),
                    ids=np.array([[1, 2, 0], [2, 3, 1]]), covs=covs,
                    existence=np.array([0.9, 0.5]), status=np.array([1, 0], np.int8))
    rec.receive(10.0, "sensornet/net/scan/s1", scan)
    rec.liveliness(10.1, "s2", True)
    rec.tick(10.2)
    rec.tracks(10.3, 3, encode(tracks))
    rec.finish(10.4)
    rec.close()
    return scan, tracks, covs, truth


def test_a_recording_decodes_with_mcap_and_json_alone(tmp_path):
    """Every message is JSON valid under its channel's JSON schema (checked by the
    ``jsonschema`` package), the payload's fields are all there, and the Foxglove scene draws
    the tracks by id, their 2-sigma ellipses, the truth and the sensors."""
    scan, tracks, covs, truth = _record_one(tmp_path / "p.mcap")
    msgs = _generic_read(tmp_path / "p.mcap")
    for _, _, schema, body in msgs:
        jsonschema.validate(body, schema)
    by = {topic: (name, body) for topic, name, _, body in msgs}
    assert set(by) == {"receive", "liveliness", "tick", "tracks", "finish", "truth", "/scene"}
    got = by["receive"][1]["message"]
    assert got == {"type": "scan", "sensor": "s1", "k": 3, "z": [[1.5, 2.5], [3.0, -4.0]],
                   "seq": 4, "send_time": 5.25, "ages": None}
    assert base64.b64decode(by["receive"][1]["payload"]) == scan
    t = by["tracks"][1]["message"]
    assert t["ids"] == tracks.ids.tolist() and t["covs"] == covs.tolist()
    assert t["existence"] == [0.9, 0.5] and t["status"] == [1, 0]
    assert by["truth"][1]["states"] == truth.tolist() and by["truth"][1]["ids"] == [7, 9]
    name, scene = by["/scene"]
    assert name == "foxglove.SceneUpdate" and scene["deletions"][0]["type"] == 1
    ids = {e["id"] for e in scene["entities"]}
    assert {"s1/track/1.2.0", "s1/track/2.3.1", "truth/7", "truth/9",
            "sensor/s1", "sensor/s2", "sensor/s3"} <= ids
    for e, x, P in zip([e for e in scene["entities"] if "/track/" in e["id"]],
                       tracks.states, covs, strict=True):
        pts = np.array([[p["x"], p["y"]] for p in e["lines"][0]["points"]])
        d = pts - x[[0, 2]]
        maha = np.einsum("ni,ij,nj->n", d, np.linalg.inv(P[np.ix_([0, 2], [0, 2])]), d)
        np.testing.assert_allclose(maha, 4.0, rtol=1e-9)  # 2 sigma: distance^2 = 4
    # a scan without tracks (nor truth) is a scene of the sensors alone
    rec = Recorder(tmp_path / "empty.mcap", {"peer": "s1", "network": "net"})
    rec.attach(SimpleNamespace(scorer=SimpleNamespace(
        pos=[0, 2], truth=lambda k: np.zeros((0, 4)), truth_ids=lambda k: None)))
    rec.tracks(1.0, 1, encode(Tracks("s1", 1, np.zeros((0, 4)))))
    rec.close()
    empty = {t: b for t, _, _, b in _generic_read(tmp_path / "empty.mcap")}
    assert empty["/scene"]["entities"] == [] and empty["tracks"]["message"]["states"] == []
    # the replay still gets its records, the readers' topics aside
    _, records = read(tmp_path / "p.mcap")
    assert [t for t, _ in records] == ["receive", "liveliness", "tick", "tracks", "finish"]
    assert records[0][1] == [10.0, "sensornet/net/scan/s1", scan]


def test_a_recording_in_the_old_msgpack_format_still_reads(tmp_path):
    path = tmp_path / "old.mcap"
    records = [("receive", [1.0, "sensornet/n/scan/s1", b"\x01\x02"]), ("tick", [1.5]),
               ("tracks", [2.0, 4, b"\x03"]), ("finish", [3.0])]
    with path.open("wb") as fh:
        w = Writer(fh, compression=CompressionType.ZSTD)
        w.start(profile="", library="sensornet")
        sid = w.register_schema("sensornet.record", "", b"")
        ch = {t: w.register_channel(t, "msgpack", sid) for t, _ in records}
        w.add_metadata("sensornet", {"peer": "s1", "network": "n"})
        for seq, (topic, r) in enumerate(records, 1):
            w.add_message(ch[topic], int(r[0] * 1e9), msgpack.packb(r, use_bin_type=True),
                          int(r[0] * 1e9), sequence=seq)
        w.finish()
    meta, got = read(path)
    assert meta == {"peer": "s1", "network": "n"} and got == records


SMALL = {"scenario.num_scans": 8}


@pytest.fixture(scope="module")
def twin_folder(tmp_path_factory):
    """``sensornet run --sim`` of a short seed000: its folder."""
    out = tmp_path_factory.mktemp("twin") / "run"
    code = main(["run", "seed000", "--sim", "--set", "scenario.num_scans=8", "--out",
                 str(out)])
    assert code == 0
    return out


def test_load_run_gives_simulates_tables(twin_folder):
    loaded, ran = load_run(twin_folder), simulate(scenario("seed000", SMALL))
    order = np.lexsort((ran.columns["estimate"], ran.columns["scan"], ran.columns["peer"]))
    assert set(loaded.columns) == set(COLUMNS) and len(loaded.columns["peer"]) == len(order)
    for c in COLUMNS:
        want = [ran.columns[c][i] for i in order]
        if c in LIST_COLUMNS:
            assert loaded.columns[c] == want, c
        else:
            assert isinstance(loaded.columns[c], np.ndarray)
            np.testing.assert_array_equal(loaded.columns[c], np.asarray(want), err_msg=c)
    assert {k: loaded.meta[k] for k in ran.meta} == ran.meta
    assert loaded.peers == ["s1", "s2", "s3"]
    for p in loaded.peers:
        assert loaded.tracks_by_id(p).keys() == ran.tracks_by_id(p).keys()
    with pytest.raises(ValueError, match="no results.parquet"):
        load_run(twin_folder / "logs") if (twin_folder / "logs").is_dir() else load_run(
            twin_folder.parent)


def test_results_metadata_is_json_with_metric_parameters_and_units(twin_folder, tmp_path):
    raw = pq.read_schema(twin_folder / "results.parquet").metadata[b"sensornet"]
    meta = json.loads(raw)
    assert meta["gospa_alpha"] == 2.0 and meta["cutoff"] > 0 and meta["order"] >= 1
    assert set(meta["units"]) == set(COLUMNS) and "lower is better" in meta["units"]["ospa"]
    # a table written before (msgpack hex) still reads
    table = pq.read_table(twin_folder / "results.parquet")
    old = table.replace_schema_metadata(
        {"sensornet": msgpack.packb({"cutoff": 100.0, "order": 2.0,
                                     "position_index": [0, 2]}).hex()})
    pq.write_table(old, tmp_path / "old.parquet")
    cols, m = read_table(tmp_path / "old.parquet")
    assert m["cutoff"] == 100.0 and len(cols["peer"]) == table.num_rows
    assert isinstance(pa.table(cols), pa.Table) and set(UNITS) == set(COLUMNS)


def test_stone_soups_ospa_and_gospa_on_the_export_equal_ours():
    from sensornet.export.stonesoup import measure, to_stonesoup

    run = simulate(scenario("seed000", SMALL))
    c, p = run.meta["cutoff"], run.meta["order"]
    for peer in ("s1", "s2"):
        ex = to_stonesoup(run, peer)
        ms = [s for t in ex.tracks for s in t.states]
        mids = [t.id for t in ex.tracks for _ in t.states]
        ts = [s for t in ex.truths for s in t.states]
        tids = [t.id for t in ex.truths for _ in t.states]
        o = OSPAMetric(c=c, p=p, measure=measure(run)).compute_over_time(ms, mids, ts, tids)
        g = GOSPAMetric(c=c, p=p, measure=measure(run)).compute_over_time(ms, mids, ts, tids)
        theirs_o = {m.timestamp: m.value for m in o.value}
        theirs_g = {m.timestamp: m.value["distance"] for m in g.value}
        rows = run.select(peer)
        assert len(theirs_o) == len(rows) > 0
        for i in rows:
            when = ex.times[int(run.columns["scan"][i])]
            assert theirs_o[when] == pytest.approx(run.columns["ospa"][i], rel=1e-9, abs=1e-9)
            assert theirs_g[when] == pytest.approx(run.columns["gospa"][i], rel=1e-9,
                                                   abs=1e-9)


@pytest.mark.network  # a Zenoh session (with no endpoint: nothing is reached)
def test_echo_without_a_network_says_what_to_pass(capsys):
    assert main(["echo", "net", "--wait", "1"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--connect tcp/127.0.0.1:PORT" in err[0], err
    assert main(["topics", "net", "--wait", "1"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no network 'net' answered" in err[0], err


@pytest.mark.network
def test_record_then_play_onto_a_fresh_network(tmp_path):
    """A short run of real processes recorded by ``sensornet record`` (echo --json beside it),
    then played onto a fresh network: a subscriber there receives the recorded payloads."""
    sets = ["scenario.num_scans=15", "network.speed=10"]
    scn = load_scenario("seed000", overrides=parse_overrides(sets))
    handle = start_run(scn, "seed000", tmp_path / "run", network="bagnet", overrides=sets,
                       rerun=False)
    bag = tmp_path / "net.mcap"
    procs = []
    try:
        ep = handle.endpoints["world"]
        rec = subprocess.Popen(
            [sys.executable, "-m", "sensornet", "record", "bagnet", "--connect", ep,
             "-o", str(bag), "--until-end"], env=env(), stdout=subprocess.PIPE,
            stderr=subprocess.PIPE, text=True)
        procs.append(rec)
        echo = subprocess.run(
            [sys.executable, "-m", "sensornet", "echo", "bagnet", "--connect", ep, "--json",
             "--count", "10"], env=env(), capture_output=True, text=True, timeout=120)
        assert echo.returncode == 0, echo.stderr
        lines = [json.loads(ln) for ln in echo.stdout.strip().splitlines()]
        assert len(lines) == 10 and all(ln["key"].startswith("sensornet/bagnet/")
                                        for ln in lines)
        kinds = {ln["message"]["type"] for ln in lines if "message" in ln}
        assert kinds & {"scan", "estimate", "tracks", "truth", "control"}, lines[:2]
        codes = wait_run(handle, timeout=120)
        assert all(c == 0 for c in codes.values()), codes
        out, err = rec.communicate(timeout=60)
        assert rec.returncode == 0, err
    finally:
        handle.stop_all()
        for pr in procs:
            if pr.poll() is None:
                pr.kill()
                pr.wait()
    # the bag, read by the mcap reader and json.loads alone
    msgs = _generic_read(bag)
    samples = [b for topic, _, _, b in msgs if topic.startswith("sensornet/bagnet/")]
    kinds = {b["message"]["type"] for b in samples if b["message"] is not None}
    kinds |= {e["message"]["type"] for b in samples for e in b.get("entries", ())
              if e["message"] is not None}  # a peer's tracks ride in its report bundle
    assert kinds >= {"scan", "estimate", "tracks", "telemetry"}, kinds
    assert any(topic == "@liveliness" for topic, *_ in msgs)
    _, items = read_bag(bag)
    recorded = sorted((it.key.replace("bagnet", "fresh", 1), it.payload)
                      for it in items if it.alive is None)
    # play onto a fresh network (its own listener), renamed: a subscriber hears them all
    port = free_port()
    player = open_session([endpoint(port)], [])
    listener = open_session([], [endpoint(port)])
    heard, probe = [], threading.Event()
    lock = threading.Lock()

    def on(sample):
        key = str(sample.key_expr)
        if key.endswith("/probe"):
            probe.set()
            return
        with lock:
            heard.append((key, sample.payload.to_bytes()))

    sub = listener.declare_subscriber("sensornet/fresh/**", on)
    try:
        def linked() -> bool:
            player.put("sensornet/fresh/probe", b"")
            return probe.wait(0.2)

        wait_for(linked, 30, "the subscriber to hear the player")
        n = play(items, player, rate=5.0, network="fresh", stamp=None)  # the recorded bytes
        assert n == len(recorded)
        wait_for(lambda: len(heard) >= n, 30, "every played message")
        with lock:
            assert sorted(heard) == recorded
    finally:
        sub.undeclare()
        listener.close()
        player.close()
