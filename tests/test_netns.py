"""Hosts on separate machines, for real: two peer hosts in network namespaces of their own,
each linked by a veth pair to a third namespace where a Zenoh router runs (``ip netns``, as
root). The hosts cannot reach each other (no route between their namespaces), so every
estimate between them crosses the router process; the run must still compute the twin's
tracks. Only addresses inside the namespaces this test creates (10.213.1.0/24, 10.213.2.0/24).
Skipped, with the reason, where ``ip netns add`` is not permitted.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest
from sensornet.sim.run.launcher import read_summaries
from sensornet.sim.run.twin import run_twin
from sensornet.sim.scenario import load_scenario

from tests.processes import stop_all
from tests.test_hosts import SIX, _six
from tests.test_network_faults import _assert_tracks_equal_the_twin

pytestmark = pytest.mark.network

ROUTER_PORT = 7447  # a namespace of our own: nothing else listens there


def _ip(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(["ip", *args], check=True, capture_output=True, text=True,
                          timeout=30)


@pytest.fixture
def namespaces():
    """Namespaces ``a``, ``b`` (the hosts) and ``r`` (the router): a 10.213.1.2 <-> .1.1 and
    b 10.213.2.2 <-> .2.1 over veth pairs; deleted (with their links) afterwards."""
    tag = f"sn{os.getpid() % 100000}"
    ns = {k: f"{tag}{k}" for k in ("a", "b", "r")}
    made: list[str] = []
    links: list[str] = []
    try:
        try:
            _ip("netns", "add", ns["r"])
        except FileNotFoundError:
            pytest.skip("no 'ip' command here")
        except subprocess.CalledProcessError as exc:
            pytest.skip(f"'ip netns add' is not permitted here: {exc.stderr.strip()}")
        made.append(ns["r"])
        _ip("-n", ns["r"], "link", "set", "lo", "up")
        for side, net in (("a", 1), ("b", 2)):
            _ip("netns", "add", ns[side])
            made.append(ns[side])
            inner, outer = f"{tag}{side}0", f"{tag}{side}1"
            _ip("link", "add", inner, "type", "veth", "peer", "name", outer)
            links.append(inner)  # in the root namespace until moved
            _ip("link", "set", inner, "netns", ns[side])
            _ip("link", "set", outer, "netns", ns["r"])
            links.remove(inner)
            _ip("-n", ns[side], "addr", "add", f"10.213.{net}.2/24", "dev", inner)
            _ip("-n", ns["r"], "addr", "add", f"10.213.{net}.1/24", "dev", outer)
            for where, dev in ((ns[side], inner), (ns[side], "lo"), (ns["r"], outer)):
                _ip("-n", where, "link", "set", dev, "up")
        yield ns
    finally:
        for dev in links:
            subprocess.run(["ip", "link", "del", dev], capture_output=True, timeout=30)
        for name in made:  # deleting a namespace deletes the veth ends in it
            subprocess.run(["ip", "netns", "del", name], capture_output=True, timeout=30)


def _start(ns: str, args: list[str], log: Path) -> subprocess.Popen:
    with log.open("w") as fh:
        return subprocess.Popen(["ip", "netns", "exec", ns, sys.executable, "-m", *args],
                                stdout=fh, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL)


def _wait_line(proc: subprocess.Popen, log: Path, text: str, timeout: float = 60.0) -> None:
    end = time.monotonic() + timeout
    while text not in log.read_text(errors="replace"):
        assert proc.poll() is None, f"exited {proc.returncode}: {log.read_text()[-2000:]}"
        assert time.monotonic() < end, f"no {text!r} in {timeout:g} s: {log.read_text()}"
        time.sleep(0.05)  # polling the process's log for its one ready line


@contextmanager
def _routed_hosts(tmp_path: Path, ns: dict[str, str], source: str, out: Path, network: str,
                  host_flags: list[str]) -> Iterator[dict[str, subprocess.Popen]]:
    """The run both tests make: a router in namespace ``r`` listening on both veth links, the
    world and host h1 (SIX[:3]) in ``a``, host h2 (SIX[3:]) in ``b``, every process a client
    of the router (each log in ``tmp_path``); stopped on the way out, whatever happened."""
    config = tmp_path / "client.json5"  # what a routed run's processes use (sim.run.launcher)
    config.write_text(json.dumps({"mode": "client",
                                  "scouting": {"multicast": {"enabled": False}}}))
    common = ["--network", network, "--out", str(out), "--run-id", network, "--no-rerun",
              "--run", "0", "--config", str(config)]
    via = {"a": f"tcp/10.213.1.1:{ROUTER_PORT}", "b": f"tcp/10.213.2.1:{ROUTER_PORT}"}
    procs: dict[str, subprocess.Popen] = {}
    try:
        log = tmp_path / "router.log"
        procs["router"] = _start(ns["r"], ["sensornet.sim.run.router", "--listen", via["a"],
        "--listen",
                                           via["b"], "--network", network], log)
        _wait_line(procs["router"], log, "router: listening")
        procs["world"] = _start(ns["a"], ["sensornet", "world", source, *common, "--connect",
                                          via["a"], "--peers", ",".join(SIX), "--wait", "90"],
                                tmp_path / "world.log")
        for name, side, peers in (("h1", "a", SIX[:3]), ("h2", "b", SIX[3:])):
            procs[name] = _start(ns[side], ["sensornet", "host", source, "--peers",
                                            ",".join(peers), "--name", name, *common,
                                            "--connect", via[side], *host_flags],
                                 tmp_path / f"{name}.log")
        yield procs
    finally:
        stop_all(procs.values())


def test_hosts_in_separate_namespaces_through_a_router_equal_the_twin(tmp_path, namespaces):
    ns = namespaces
    # the namespaces of the two hosts have no route to each other: only through the router
    for side, router, other in (("a", "10.213.1.1", "10.213.2.2"),
                                ("b", "10.213.2.1", "10.213.1.2")):
        _ip("-n", ns[side], "route", "get", router)  # its own link to the router: there
        unreachable = subprocess.run(["ip", "-n", ns[side], "route", "get", other],
                                     capture_output=True, text=True, timeout=30)
        assert unreachable.returncode != 0 and "unreachable" in unreachable.stderr, (
            unreachable.stdout, unreachable.stderr)
    source = _six(tmp_path / "six.toml", scans=20)
    scn = load_scenario(source)
    out, network = tmp_path / "run", f"netns{os.getpid()}"
    out.mkdir()
    with _routed_hosts(tmp_path, ns, source, out, network, ["--save-tracks"]) as procs:
        codes = {n: procs[n].wait(timeout=180) for n in ("world", "h1", "h2")}
    logs = {n: (tmp_path / f"{n}.log").read_text()[-1500:] for n in ("world", "h1", "h2")}
    assert codes == {"world": 0, "h1": 0, "h2": 0}, (codes, logs)
    summaries = read_summaries(out, SIX)
    assert set(summaries) == set(SIX)
    for name, s in summaries.items():
        assert s["host"]["name"] == ("h1" if name in SIX[:3] else "h2")
        assert s["scans"] == scn.num_scans and s["internal_errors"] == {}
    assert len({s["pid"] for s in summaries.values()}) == 2
    _assert_tracks_equal_the_twin(out, scn, summaries, run_twin(scn, 0))


def test_a_host_cut_off_from_the_world_for_5s_rejoins_and_finishes(tmp_path, namespaces):
    """A real partition (issue 25): host h2's link to the router goes down for 5 s, five
    times the 1 s lease, so its three peers lose the world, their neighbours and the router;
    within the grace (--world-grace 10) they ride it out, relink when the link comes back and
    fuse every scan after their return to the end of the run. h1 keeps going throughout."""
    ns = namespaces
    source = _six(tmp_path / "six.toml", scans=100)  # 5 scans/s: 20 s of scans
    scn = load_scenario(source)
    out, network = tmp_path / "run", f"part{os.getpid()}"
    out.mkdir()
    peer_flags = ["--lease-ms", "1000", "--world-grace", "10", "--save-tracks"]
    link_b = f"{ns['r'][:-1]}b0"  # h2's end of its veth pair (the fixture's naming)
    with _routed_hosts(tmp_path, ns, source, out, network, peer_flags) as procs:
        _wait_line(procs["world"], tmp_path / "world.log", "scan 20/", timeout=120)
        _ip("-n", ns["b"], "link", "set", link_b, "down")
        try:
            time.sleep(5.0)  # the fault itself: 5 s without a link
        finally:
            _ip("-n", ns["b"], "link", "set", link_b, "up")
        codes = {n: procs[n].wait(timeout=180) for n in ("world", "h1", "h2")}
    logs = {n: (tmp_path / f"{n}.log").read_text()[-1500:] for n in ("world", "h1", "h2")}
    assert codes == {"world": 0, "h1": 0, "h2": 0}, (codes, logs)
    summaries = read_summaries(out, SIX)
    n = scn.num_scans
    for name in SIX[3:]:
        s = summaries[name]
        assert s["stop_reason"] == "end of run", (name, s["stop_reason"], logs["h2"])
        assert s["last_k"] == n and s["internal_errors"] == {}, (name, s["last_k"])
        assert len(s["world_outages"]) >= 1, (name, s["world_outages"])
        saved = np.load(out / f"tracks-{name}.npz")
        ks = sorted(int(k[1:]) for k in saved.files)
        i = max(range(1, len(ks)), key=lambda j: ks[j] - ks[j - 1])
        assert ks[i] - ks[i - 1] >= 15, ks  # 5 s cut off at 5 scans/s: about 25 scans
        assert ks[i:] == list(range(ks[i], n + 1)), ks  # back, then every scan to the end
        assert s["ospa_scored"]["fused"] + s["ospa_misses"]["fused"] == n, s
    for name in SIX[:3]:
        assert summaries[name]["stop_reason"] == "end of run"
        assert summaries[name]["last_k"] == n
