"""``sensornet run`` as a user drives it (issue 16): flags reach the processes, signals stop
the run cleanly and leave a merged recording. Real processes over Zenoh on 127.0.0.1."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from sensornet.peers.session import free_port

from tests.processes import alive, children, env, rerun_exe, sensornet, wait_for

ROOT = Path(__file__).resolve().parents[1]
pytestmark = pytest.mark.network


def test_run_flags_reach_every_process(tmp_path):
    """--listen, --connect, --config, --run-id, --network reach the world and the peers; an
    unreachable --viewer is one warning and is not passed on (no stall at exit)."""
    port = free_port()
    world = f"tcp/127.0.0.1:{port}"
    config = tmp_path / "zenoh.json5"
    config.write_text('{mode: "peer", scouting: {multicast: {enabled: false}}}\n')
    dead_viewer = f"rerun+http://127.0.0.1:{free_port()}/proxy"
    out = tmp_path / "run"
    proc = subprocess.run(
        [sys.executable, "-m", "sensornet", "run", "--listen", world, "--connect", world,
         "--config", str(config), "--run-id", "rid-16", "--network", "net16",
         "--viewer", dead_viewer, "--set", "scenario.num_scans=12", "--no-rerun",
         "--out", str(out)], capture_output=True, text=True, timeout=180, cwd=tmp_path,
        env=env())
    assert proc.returncode == 0, proc.stderr + proc.stdout
    err = proc.stderr.strip().splitlines()
    assert len(err) == 1 and "warning" in err[0] and dead_viewer in err[0], proc.stderr
    commands = json.loads((out / "commands.json").read_text())
    assert set(commands) == {"world", "s1", "s2", "s3"}
    for cmd in commands.values():
        text = " ".join(cmd)
        assert "--run-id rid-16" in text and "--network net16" in text
        assert f"--config {config}" in text
        assert f"--connect {world}" in text
        assert "--viewer" not in text
    for n in ("s1", "s2", "s3"):  # each link has one configured dialler (peers.session.ANNOUNCE)
        assert "--no-autoconnect" in commands[n] and "--no-gossip" not in commands[n]
    assert commands["world"][commands["world"].index("--listen") + 1] == world
    world_log = (out / "logs" / "world.log").read_text()
    assert "world: scan 10/12 published" in world_log and "world: scan 12/12" in world_log
    for n in ("s1", "s2", "s3"):
        assert json.loads((out / f"peer-{n}.json").read_text())["scans"] == 12


def test_a_peer_with_no_world_says_so_and_prints_no_nan(tmp_path):
    """A peer whose world never appears waited out its idle timeout and printed "mean OSPA
    local nan fused nan": it says in one line that no world came, exit code 1."""
    config = tmp_path / "zenoh.json5"  # alone: no scouting, nobody to meet
    config.write_text('{mode: "peer", scouting: {multicast: {enabled: false}}}\n')
    network = f"noworld{os.getpid()}"
    proc = subprocess.run(
        [sys.executable, "-m", "sensornet", "peer", "s1", "--network", network,
         "--listen", f"tcp/127.0.0.1:{free_port()}", "--config", str(config),
         "--idle-timeout", "2", "--no-rerun", "--out", str(tmp_path / "out")],
        capture_output=True, text=True, timeout=120, cwd=tmp_path, env=env())
    assert proc.returncode == 1, proc.stderr + proc.stdout
    last = proc.stdout.strip().splitlines()[-1]
    assert last == (f"peer s1: no world on network {network} within 2 s: nothing was "
                    "tracked"), proc.stdout
    assert "nan" not in proc.stdout and proc.stderr.strip() == "", proc.stderr
    # --out of a folder not made yet, no Rerun: the summary is still written (it crashed)
    summary = json.loads((tmp_path / "out" / "peer-s1.json").read_text())
    assert summary["scans"] == 0 and summary["stop_reason"] == "no input for 2 s"


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT], ids=["SIGTERM", "SIGINT"])
def test_signal_to_the_launcher_stops_every_child_and_merges_the_recording(tmp_path, sig):
    out = tmp_path / "run"
    # 3000 scans: the signal comes mid-run however long the view takes to start
    with sensornet(["run", "--viewer", "none", "--speed", "5", "--out", str(out),
                    "--set", "scenario.num_scans=3000"], tmp_path) as launch:
        launcher = launch.proc
        world_log = out / "logs" / "world.log"
        wait_for(lambda: world_log.is_file() and "scan 10/" in world_log.read_text(), 90,
                 "the world's scan 10")
        # and the view has opened its recording (it imports for seconds longer than the
        # peers on a busy machine: a view stopped in its imports leaves no .rrd to merge)
        view_log = out / "logs" / "view.log"
        wait_for(lambda: view_log.is_file() and "view: network " in view_log.read_text(), 240,
                 "the view's recording to open")
        kids = launch.find_children()
        assert len(kids) == 5, kids  # the world, three peers and the view (sensornet view)
        launcher.send_signal(sig)
        stdout, stderr = launcher.communicate(timeout=60)
        ended = time.monotonic()
        wait_for(lambda: not any(alive(p) for p in kids), 5.0,
                 "the children to end (at most 5 s after the launcher)")
        assert time.monotonic() - ended < 5.0
        assert launcher.returncode == 0, stderr
        assert "Traceback" not in stderr
        assert sig.name in stderr, stderr
        assert "| s1 |" in stdout and "recording:" in stdout
        rec = out / "recording.rrd"
        assert rec.is_file()
        check = subprocess.run([rerun_exe(), "rrd", "verify", str(rec)], capture_output=True,
                               text=True, timeout=120, env=env())
        assert check.returncode == 0, check.stderr


def _summary(fusions: int, late: int, lat: list[float]) -> dict:
    return {"stats": {"fusions": fusions, "deadline_fusions": late}, "latency_ms_samples": lat}


def test_realtime_note_only_when_the_peers_fell_behind():
    from sensornet.sim.run.launcher import realtime_note

    kept = {"s1": _summary(100, 5, [4.0] * 99 + [90.0]), "s2": _summary(100, 0, [5.0] * 100)}
    assert realtime_note(kept, 0.1, 10.0, 2) is None  # 2.5 % at the deadline, p99 90 ms
    late = {"s1": _summary(100, 30, [120.0] * 100), "s2": _summary(100, 10, [50.0] * 100)}
    note = realtime_note(late, 0.1, 10.0, 2)
    assert note.startswith("note: these 2 peers did not keep real time at 10x")
    assert "20.0 % of fusion rounds ran at their deadline" in note
    assert "p99 scan -> tracks 120 ms against a 100 ms scan interval" in note
    assert "--speed 5" in note and "2 cores" in note
    slow_only = {"s1": _summary(100, 0, [30.0] * 98 + [150.0, 160.0])}  # p99: index 99
    note = realtime_note(slow_only, 0.1, 10.0, None)
    assert "deadline" not in note and "p99 scan -> tracks 160 ms" in note
    assert realtime_note({"s1": _summary(0, 0, [])}, 0.1, 10.0, 2) is None  # nothing ran


def test_signal_during_start_up_says_what_happened(tmp_path):
    """SIGTERM to the launcher as soon as it has started its processes (they are still
    importing): exit 0, every child stopped, and one honest line: nothing was tracked (not
    'the .rrd files could not be merged'); a peer that got as far as its run wrote a summary."""
    out = tmp_path / "run"
    with sensornet(["run", "--viewer", "none", "--out", str(out)], tmp_path) as launch:
        launcher = launch.proc
        wait_for(lambda: (out / "commands.json").is_file() and len(children(launcher.pid)) == 5,
                 90, "the launcher to start its five processes (world, 3 peers, view)")
        kids = launch.find_children()
        launcher.send_signal(signal.SIGTERM)
        stdout, stderr = launcher.communicate(timeout=120)
        wait_for(lambda: not any(alive(p) for p in kids), 60, "the children to end")
        assert launcher.returncode == 0, stderr
        assert "Traceback" not in stderr and "could not be merged" not in stdout, stdout
        summaries = list(out.glob("peer-*.json"))
        if summaries:  # a peer had begun: its summary says it was stopped
            assert "SIGTERM" in stderr
        else:
            lines = [ln for ln in stderr.splitlines() if ln.strip()]
            assert len(lines) == 1 and "during start-up" in lines[0], stderr
            assert "nothing was tracked" in lines[0]
