"""A run's outputs as processes (issues 33 item 5 and 35 item 6): the network line at start
and the command it gives, Ctrl-C, a killed peer's row, the track numbers in the summary files;
the world stopped while it waits for its peers says it was interrupted."""

from __future__ import annotations

import json
import re
import signal
import subprocess
import sys
import threading

import pytest
from sensornet.peers.session import endpoint, free_port

from tests.processes import env, sensornet, wait_for

pytestmark = pytest.mark.network


class Lines:
    """A process's output read line by line on a thread, so a test waits on a line (an
    event) and not on time."""

    def __init__(self, stream) -> None:
        self.lines: list[str] = []
        self.done = threading.Event()
        self._t = threading.Thread(target=self._read, args=(stream,), daemon=True)
        self._t.start()

    def _read(self, stream) -> None:
        for line in stream:
            self.lines.append(line.rstrip("\n"))
        self.done.set()

    def first(self, pattern: str) -> str | None:
        return next((ln for ln in self.lines if re.search(pattern, ln)), None)


def test_run_prints_how_to_watch_it_and_the_command_works(tmp_path):
    """The start line names the network and the world's endpoint; the `sensornet echo`
    command it prints hears the run's messages; Ctrl-C then stops the run with its table."""
    out = tmp_path / "run"
    args = ["run", "seed000", "--no-rerun", "--out", str(out), "--speed", "2",
            "--set", "scenario.num_scans=400"]
    with sensornet(args, tmp_path) as launch:
        lines = Lines(launch.proc.stdout)
        wait_for(lambda: lines.first(r"^network run-") or launch.proc.poll() is not None, 120,
                 "the network line")
        line = lines.first(r"^network run-")
        assert line, lines.lines
        m = re.fullmatch(r"network (run-\w+), world at (tcp/127\.0\.0\.1:\d+) \(watch it: "
                         r"(sensornet echo \1 --connect \2)\)", line)
        assert m, line
        commands = json.loads((out / "commands.json").read_text())
        assert m.group(1) in json.dumps(commands) and m.group(2) in json.dumps(commands)
        launch.find_children()
        echo = subprocess.run([sys.executable, "-m", *m.group(3).split(), "--count", "3",
                               "--duration", "60"], capture_output=True, text=True,
                              timeout=120, env=env(), cwd=tmp_path)
        assert echo.returncode == 0, echo.stderr
        assert len([ln for ln in echo.stdout.splitlines() if ln.strip()]) >= 3, echo.stdout
        launch.proc.send_signal(signal.SIGINT)
        assert launch.proc.wait(timeout=120) == 0
        lines.done.wait(timeout=30)
        err = launch.proc.stderr.read()
    assert "stopped by SIGINT" in err
    assert lines.first(r"^\| s1 \| \d+ \|") and lines.first(r"^columns: ")


def test_a_killed_peer_has_a_row_and_the_summaries_have_track_numbers(tmp_path):
    out = tmp_path / "run"
    args = ["run", "seed000", "--no-rerun", "--out", str(out), "--fault", "kill:s3@10",
            "--set", "scenario.num_scans=40"]
    with sensornet(args, tmp_path) as launch:
        launch.find_children()
        stdout, stderr = launch.proc.communicate(timeout=240)
    assert launch.proc.returncode == 0, stderr
    rows: dict[str, str] = {}
    for ln in stdout.splitlines():  # the run's table first (the latency table repeats names)
        if ln.startswith("| s"):
            rows.setdefault(ln.split("|")[1].strip(), ln)
    killed = rows["s3 (killed at scan 10: no summary, every scan scored a miss)"]
    assert killed.count("| 200.0 ") == 4
    for n in ("s1", "s2"):
        cells = [c.strip() for c in rows[n].split("|")[1:-1]]
        assert cells[1] == "40"
        assert all(re.fullmatch(r"\d+\.\d", c) for c in cells[2:7]), cells  # OSPA .. switches
        assert re.fullmatch(r"\d+\.\d %", cells[7]), cells  # label agreement
        tracks = json.loads((out / f"peer-{n}.json").read_text())["tracks"]
        assert tracks["fused"]["truth_scans"] > 50
        assert f"{tracks['fused']['ospa2']:.1f}" == cells[5]
    assert any(ln.startswith("verdict: ") and "no verdict for s3" in ln
               for ln in stdout.splitlines())


def test_the_world_stopped_while_waiting_for_its_peers_says_interrupted(tmp_path):
    ep = endpoint(free_port())
    cmd = [sys.executable, "-m", "sensornet", "world", "seed000", "--network",
           f"wait-{free_port()}", "--listen", ep, "--peers", "s1,s2,s3", "--wait", "60",
           "--no-rerun", "--out", str(tmp_path)]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            env=env(), cwd=tmp_path)
    try:
        lines = Lines(proc.stdout)
        wait_for(lambda: lines.first("waiting up to 60 s for peers") or proc.poll() is not None,
                 60, "the world waiting for its peers")
        assert lines.first("waiting up to"), lines.lines
        proc.send_signal(signal.SIGINT)
        proc.wait(timeout=60)
        lines.done.wait(timeout=10)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    text = "\n".join(lines.lines)
    assert "interrupted while waiting for peers ['s1', 's2', 's3']" in text, text
    assert "did not come up" not in text
