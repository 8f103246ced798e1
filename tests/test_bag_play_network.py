"""``record`` + ``play`` round trip with real processes (issue 35 item 3): a short seed-000 run
(world and peers started by hand) recorded by ``sensornet record``, then fresh peers fed only
by ``sensornet play --only world --peers ...`` (the world's scans, truth, control and token;
the peers compute their own estimates): every scan processed, each peer's fused OSPA within
the recorded run's 95 % interval, and the fused tracks of each scan compared (with the
recorded run's, and with the twin's fed the same bag); the played peers' latency counts from
play's put. Two layouts: a process per peer, and peer hosts (:data:`HOSTS`)."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import t as student
from sensornet.peers.session import endpoint, free_port
from sensornet.sim.scenario import load_scenario, parse_overrides

from sensornet.api import load_run
from sensornet.bag import read_bag, select
from sensornet.bag_twin import bag_scenario, play_twin
from tests.processes import env, stop_all, wait_for

pytestmark = pytest.mark.network

SETS = ["scenario.num_scans=12", "network.speed=5", "network.deadline=0.9"]
NAMES = ["s1", "s2", "s3"]
HOSTS = {"h1": ["s1", "s2"], "h2": ["s3"]}
"""The peer hosts of the ``hosts`` layout (``sensornet run --per-process 2`` packs seed 000 so):
h1's two peers hand estimates over in the process, h2's one peer gets them over Zenoh."""
TIMEOUT = 90.0


def _cli(*args: str, log: Path) -> subprocess.Popen:
    """``python -m sensornet ARGS``, stdout and stderr to ``log`` (stdin empty: a host reads
    its commands there)."""
    fh = log.open("w")
    try:
        return subprocess.Popen([sys.executable, "-m", "sensornet", *args], env=env(),
                                stdin=subprocess.DEVNULL, stdout=fh, stderr=subprocess.STDOUT,
                                text=True)
    finally:
        fh.close()


def _peers(network: str, upstream: str, out: Path, procs: list, hosts: bool = False) -> None:
    """Peers s1-s3 by hand, as ``sensornet run`` starts them: each dials ``upstream`` (the
    world, or ``play``) and the peers before it; ``hosts``: as ``run --per-process 2`` does,
    peer hosts (:data:`HOSTS`, ``sensornet host``), each dialling the hosts before it."""
    groups = HOSTS if hosts else {n: [n] for n in NAMES}
    eps = {g: endpoint(free_port()) for g in groups}
    sets = [a for s in SETS for a in ("--set", s)]
    for i, (g, members) in enumerate(groups.items()):
        links = [upstream, *(eps[h] for h in list(groups)[:i])]
        what = (["host", "seed000", "--peers", ",".join(members), "--name", g] if hosts
                else ["peer", g, "--scenario", "seed000", "--color", str(i)])
        procs.append(_cli(*what, "--network", network, "--out", str(out), *sets,
                          "--no-rerun", "--listen", eps[g],
                          *[a for c in links for a in ("--connect", c)],
                          "--no-autoconnect", log=out / f"{g}.log"))


def _finished(procs: list[subprocess.Popen], timeout: float) -> list[int]:
    """Every process's exit code (an AssertionError naming them if any is still running)."""
    wait_for(lambda: all(p.poll() is not None for p in procs), timeout, "the processes to end")
    return [p.returncode for p in procs]


@pytest.fixture(scope="module", params=["processes", "hosts"])
def round_trip(request, tmp_path_factory):
    """(recorded run folder, its bag, played run folder, play's log, layout): a run of a
    process per peer, or of peer hosts (the world sends each host its scans in one bundle per
    scan), recorded, then its world part played onto fresh peers of the same layout."""
    hosts = request.param == "hosts"
    base = tmp_path_factory.mktemp(f"bagplay-{request.param}")
    rec_dir, play_dir = base / "recorded", base / "played"
    rec_dir.mkdir()
    play_dir.mkdir()
    bag = base / "net.mcap"
    network = f"bagrt{free_port()}"
    procs: list[subprocess.Popen] = []
    n_procs = len(HOSTS) if hosts else len(NAMES)
    try:
        world_ep = endpoint(free_port())
        sets = [a for s in SETS for a in ("--set", s)]
        bundles = [a for h, m in HOSTS.items() for a in ("--bundle", f"{h}={','.join(m)}")]
        rec = _cli("record", network, "--connect", world_ep, "-o", str(bag), "--until-end",
                   "--wait", str(TIMEOUT), "--scenario", "seed000", *sets,
                   log=base / "record.log")  # dials until the world is up
        procs.append(rec)
        world = _cli("world", "seed000", "--network", network, "--listen", world_ep,
                     "--peers", ",".join(NAMES), "--out", str(rec_dir), *sets, "--no-rerun",
                     *(bundles if hosts else []), log=rec_dir / "world.log")
        procs.append(world)
        # the recorder heard the world (its token) before any peer exists: it hears every scan
        wait_for(lambda: f"-> {bag}" in (base / "record.log").read_text()
                 or rec.poll() is not None, TIMEOUT, "the recorder to hear the world")
        assert rec.poll() is None, (base / "record.log").read_text()
        peers: list[subprocess.Popen] = []
        _peers(network, world_ep, rec_dir, peers, hosts)
        procs += peers
        codes = _finished([world, *peers, rec], TIMEOUT)
        assert codes == [0] * (n_procs + 2), [(base / "record.log").read_text(), codes]

        play_ep = endpoint(free_port())
        player = _cli("play", str(bag), "--only", "world", "--listen", play_ep,
                      "--peers", ",".join(NAMES), "--wait", str(TIMEOUT),
                      log=base / "play.log")
        procs.append(player)
        peers = []
        _peers(network, play_ep, play_dir, peers, hosts)
        procs += peers
        codes = _finished([player, *peers], TIMEOUT)
        assert codes == [0] * (n_procs + 1), [(base / "play.log").read_text(), codes]
    finally:
        stop_all(procs)
    return rec_dir, bag, play_dir, (base / "play.log").read_text(), request.param


def _interval95(values: np.ndarray) -> tuple[float, float]:
    """The 95 % interval of a mean over scans (Student t, n - 1 degrees of freedom)."""
    n = len(values)
    half = student.ppf(0.975, n - 1) * values.std(ddof=1) / math.sqrt(n)
    return values.mean() - half, values.mean() + half


def test_play_puts_back_only_the_worlds_part(round_trip):
    _, bag, _, log, layout = round_trip
    meta, items = read_bag(bag)
    assert meta["scenario_file"] == "seed000.toml" and json.loads(meta["overrides"]) == SETS
    assert f"play: recorded with scenario seed000.toml --set {SETS[0]}" in log, log
    world = select(items, "world")
    samples = [it for it in world if it.alive is None]
    scans = "scans" if layout == "hosts" else "scan"  # a bundle per host and scan, or a scan
    assert {it.key.split("/")[2] for it in samples} == {scans, "truth", "ctl"}
    per_scan = len(HOSTS) if layout == "hosts" else len(NAMES)
    assert len([it for it in samples if f"/{scans}/" in it.key]) == per_scan * 12
    assert f"play: {len(samples)} messages put" in log, log
    assert len(select(items, "peers")) > 0  # the recorded peers' estimates: not played


def _complete(summary: dict) -> bool:
    """Whether the peer fused every neighbour's estimate of every scan before its deadline (the
    fused tracks are then a function of the scans alone)."""
    st = summary["stats"]
    return (st["deadline_fusions"] == 0 and summary["nale"]["late"] == 0
            and st["fused_inputs"] == st["scans"] * (len(NAMES) - 1))


def test_peers_fed_from_play_give_the_recorded_runs_fused_tracks(round_trip):
    rec_dir, _, play_dir, _, _ = round_trip
    recorded, played = load_run(rec_dir), load_run(play_dir)
    scn = load_scenario("seed000", overrides=parse_overrides(SETS))
    compared = 0
    for n in NAMES:
        assert recorded.summary(n)["scans"] == scn.num_scans, n
        assert played.summary(n)["scans"] == scn.num_scans, n  # every scan processed
        a, b = recorded.tracks(n), played.tracks(n)
        assert sorted(a) == sorted(b) == list(range(1, scn.num_scans + 1)), n
        same = [k for k in a if a[k].shape == b[k].shape
                and np.allclose(a[k], b[k], rtol=1e-9, atol=1e-9)]
        ospa_rec = np.asarray(recorded.metric(n, "ospa")[1], float)
        lo, hi = _interval95(ospa_rec)
        mean_played = played.mean_ospa(n)
        complete = _complete(recorded.summary(n)) and _complete(played.summary(n))
        print(f"{n}: fused OSPA recorded {ospa_rec.mean():.3f} (95 % [{lo:.3f}, {hi:.3f}]) "
              f"played {mean_played:.3f}; {len(same)}/{len(a)} scans' tracks equal; every "
              f"estimate fused in time in both runs: {complete}")
        assert lo <= mean_played <= hi, (n, lo, mean_played, hi)
        if complete:  # the same inputs fused: the same tracks, scan by scan
            assert len(same) == len(a), (n, sorted(set(a) - set(same)))
            assert mean_played == pytest.approx(recorded.mean_ospa(n), abs=1e-9)
            compared += 1
    print(f"tracks compared scan by scan for {compared} of {len(NAMES)} peers")


def test_the_twin_fed_the_same_bag_gives_the_same_tracks(round_trip):
    """The bag's world part on the twin (sensornet.bag_twin.play_twin): where the recorded
    peer fused every estimate in time, its fused tracks, scan by scan."""
    rec_dir, bag, _, _, _ = round_trip
    recorded = load_run(rec_dir)
    meta, items = read_bag(bag)
    scn = bag_scenario(meta)  # the scenario record was given
    assert scn.num_scans == 12
    twin = play_twin(select(items, "world"), scn)
    for n in NAMES:
        assert sorted(twin.tracks[n]) == list(range(1, scn.num_scans + 1)), n
        if _complete(recorded.summary(n)):
            a = recorded.tracks(n)
            assert all(np.allclose(a[k], twin.tracks[n][k], rtol=1e-9, atol=1e-9)
                       and a[k].shape == twin.tracks[n][k].shape for k in a), n
            assert twin.peers[n].mean_ospa("fused") == pytest.approx(recorded.mean_ospa(n),
                                                                      abs=1e-9)


def test_a_played_runs_latency_counts_from_plays_put(round_trip):
    """``play`` stamps each message as it puts it (sensornet.bag_play.restamp): the played
    peers' scan -> tracks latency is under 5 scan intervals, where the recorded stamps would
    give at least the recording's length (the check below that this bound tells them apart)."""
    rec_dir, bag, play_dir, log, _ = round_trip
    scn = load_scenario("seed000", overrides=parse_overrides(SETS))
    interval_ms = 1e3 * scn.scan_period / scn.network.speed
    _, items = read_bag(bag)
    first_scan = min(it.t for it in select(items, "world") if "/scan" in it.key)
    recorded_floor_ms = 1e3 * (items[-1].t - first_scan)  # played after the recording ended
    assert recorded_floor_ms > 5 * interval_ms
    assert "send times set as each message is put" in log, log
    recorded, played = load_run(rec_dir), load_run(play_dir)
    for n in NAMES:
        lat = played.summary(n)["latency_ms_median"]
        print(f"{n}: latency median recorded {recorded.summary(n)['latency_ms_median']:.1f} ms, "
              f"played {lat:.1f} ms (recorded stamps: >= {recorded_floor_ms:.0f} ms)")
        assert lat is not None and 0 < lat < 5 * interval_ms, (n, lat)


def test_load_run_of_each_run_equals_its_summaries(round_trip):
    """``load_run`` on a run of processes (or of peer hosts), recorded or played: every peer's
    summary as its process wrote it, and the per-scan table's mean OSPA (local and fused) and
    scan count equal to the summary's, which the peer's scorer computed on its own."""
    for folder in round_trip[0], round_trip[2]:
        run = load_run(folder)
        assert run.peers == NAMES
        for n in NAMES:
            written = json.loads((folder / f"peer-{n}.json").read_text())
            loaded = dict(run.summary(n))
            for s in (written, loaded):  # which files hold it (a run's launcher drops it)
                s.pop("summary_files", None)
            assert loaded == written, n
            for which in ("local", "fused"):
                ospa = np.asarray(run.metric(n, "ospa", which)[1], float)
                assert len(ospa) == written["scans"], (n, which)
                assert ospa.mean() == pytest.approx(written[f"mean_ospa_{which}"], rel=1e-12)
