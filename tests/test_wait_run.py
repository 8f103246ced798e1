"""``launcher.wait_run``'s deadline counts from the world's first scan, not from the launch:
a slow start-up (processes importing on a busy machine) must not turn a finished run into a
timed-out one. A scripted clock and scripted processes: no sleeps, no real processes."""

from __future__ import annotations

from pathlib import Path

from sensornet.sim.run import launcher
from sensornet.sim.run.run_handle import RunHandle


class Clock:
    """``monotonic`` and ``sleep`` of a scripted time: each sleep advances it and runs the
    events that fall due."""

    def __init__(self, events):
        self.t = 0.0
        self.events = sorted(events, key=lambda e: e[0])

    def monotonic(self) -> float:
        return self.t

    def sleep(self, dt: float) -> None:
        self.t += dt
        while self.events and self.events[0][0] <= self.t:
            self.events.pop(0)[1]()


class Proc:
    """A process that exits with 0 when told to."""

    def __init__(self):
        self.returncode = None

    def poll(self):
        return self.returncode

    def send_signal(self, sig):
        self.returncode = -sig

    def wait(self, timeout=None):
        return self.returncode

    def kill(self):
        self.returncode = -9


def _run(tmp_path: Path, monkeypatch, start_up: float, length: float, timeout: float):
    """A world that logs its start line after ``start_up`` s and exits ``length`` s later;
    ``wait_run(timeout)``: (timed_out, the scripted time at return)."""
    log = tmp_path / "world.log"
    log.write_text("world: waiting up to 60 s for peers a\n")
    world, peer = Proc(), Proc()

    def starts():
        with open(log, "a") as f:
            f.write(f"{launcher.WORLD_STARTED}10 scans, one every 0.1 s\n")

    def ends():
        world.returncode = peer.returncode = 0

    clock = Clock([(start_up, starts), (start_up + length, ends)])
    monkeypatch.setattr(launcher.time, "monotonic", clock.monotonic)
    monkeypatch.setattr(launcher.time, "sleep", clock.sleep)
    handle = RunHandle(out=tmp_path, procs={"world": world, "a": peer}, logs={"world": log})
    codes = launcher.wait_run(handle, timeout=timeout)
    return handle.timed_out, clock.t, codes


def test_a_slow_start_up_does_not_eat_the_runs_slack(tmp_path, monkeypatch):
    # 40 s to start, a 100 s run, timeout 100 + 10: ends at 140 s, in time (from its start)
    timed_out, t, codes = _run(tmp_path, monkeypatch, start_up=40.0, length=100.0,
                               timeout=110.0)
    assert not timed_out and codes == {"world": 0, "a": 0}
    assert 140.0 <= t < 141.0


def test_a_run_longer_than_its_timeout_after_its_start_is_still_stopped(tmp_path, monkeypatch):
    timed_out, t, codes = _run(tmp_path, monkeypatch, start_up=40.0, length=200.0,
                               timeout=110.0)
    assert timed_out and codes["world"] < 0
    assert 150.0 <= t < 151.0  # 40 s start-up (seen within 0.5 s) + 110 s


def test_a_world_that_never_starts_is_stopped_at_the_timeout(tmp_path, monkeypatch):
    timed_out, t, _ = _run(tmp_path, monkeypatch, start_up=1e9, length=1.0, timeout=110.0)
    assert timed_out and 110.0 <= t < 111.0


def test_world_started_reads_the_log(tmp_path):
    log = tmp_path / "w.log"
    handle = RunHandle(out=tmp_path, logs={"world": log})
    assert not launcher.world_started(handle)  # no log yet
    log.write_text("world: waiting up to 60 s for peers a\n")
    assert not launcher.world_started(handle)
    log.write_text(log.read_text() + launcher.WORLD_STARTED + "5 scans\n")
    assert launcher.world_started(handle)
    assert not launcher.world_started(RunHandle(out=tmp_path))  # no world log at all
