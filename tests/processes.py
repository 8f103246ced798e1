"""What the process tests share: the environment of a child, the processes a launcher
started, waiting on an event, and stopping everything a test started whatever happened."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

from sensornet.protocol.codec import decode

ROOT = Path(__file__).resolve().parents[1]


def env() -> dict:
    """The environment of a child process: this checkout importable, no Rerun analytics."""
    return {**os.environ, "PYTHONPATH": str(ROOT), "RERUN_ANALYTICS": "0"}


def children(pid: int) -> list[int]:
    """Processes whose parent is ``pid`` (from /proc)."""
    found = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
        except OSError:
            continue
        if int(stat.rsplit(")", 1)[1].split()[1]) == pid:
            found.append(int(entry.name))
    return found


def alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    try:  # a zombie is gone for our purposes
        return (Path("/proc") / str(pid) / "stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


def wait_for(predicate, timeout: float, what: str) -> None:
    """Poll ``predicate`` (an event: a file, a line, a process gone) until true or timeout."""
    end = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > end:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.05)


def when_view_drew(log: Path, peers: Iterable[str], running: Callable[[], bool],
                   timeout: float) -> dict[str, int]:
    """Until a view's log says it has drawn the first reports of every one of ``peers`` into
    its recording (``view: drew the first reports of s1 (scan 3), ...``,
    :meth:`sensornet.view.LiveView.reporting`): an event, where a view that starts late on a
    busy machine (its imports) links after a short run's scans. Returns each peer's first scan
    drawn; fails at once if ``running()`` turns false first (the view ended), else after
    ``timeout`` seconds, with the log's end."""
    want = set(peers)
    end = time.monotonic() + timeout
    while True:
        up = running()  # before reading: a line written just before the view ended is seen
        text = log.read_text(errors="replace") if log.is_file() else ""
        drew = {n: int(k) for line in text.splitlines()
                if line.startswith("view: drew the first reports of ")
                for n, k in re.findall(r"(\S+) \(scan (\d+)\)", line)}
        if want <= set(drew):
            return drew
        assert up, f"the view ended before it drew {sorted(want - set(drew))}: {text[-2000:]}"
        assert time.monotonic() < end, (f"the view never drew {sorted(want - set(drew))} in "
                                         f"{timeout:g} s: {text[-2000:]}")
        time.sleep(0.05)


def argv(pid: int) -> list[str]:
    """A process's command line ([] once it has gone)."""
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().decode().split("\0")
    except OSError:
        return []


def end_once_view_drew(launch: Launch, out: Path, peers: Iterable[str],
                       timeout: float = 240.0) -> dict[str, int]:
    """End a ``sensornet run`` (``launch``, its output folder ``out``) once its view says it
    drew every one of ``peers`` (:func:`when_view_drew`): SIGTERM to the run's world, whose
    end message ends the run as its last scan does. A test of what a run's view recorded plays
    more scans than any wait can take and ends the run so: the view imports for seconds longer
    than the peers (20.7 against 12.5 s at load 15) and linked after short runs' ends.
    Returns each peer's first scan drawn."""
    drew = when_view_drew(out / "logs" / "view.log", peers, lambda: launch.proc.poll() is None,
                          timeout)
    world = [p for p in launch.find_children() if argv(p)[2:4] == ["sensornet", "world"]]
    assert len(world) == 1, [argv(p) for p in launch.children]
    os.kill(world[0], signal.SIGTERM)
    return drew


def when_tracks_reach(session, keys, peer: str, k0: int, timeout: float = 60.0) -> int:
    """Wait until ``peer`` has published the tracks of scan ``k0`` (heard on ``session``, a
    Zenoh session linked to the network of ``keys``); the newest scan seen."""
    seen = {"k": 0}
    reached = threading.Event()

    def on_tracks(sample) -> None:
        seen["k"] = max(seen["k"], decode(sample.payload.to_bytes()).k)
        if seen["k"] >= k0:
            reached.set()

    sub = session.declare_subscriber(keys.tracks(peer), on_tracks)
    try:
        assert reached.wait(timeout), f"{peer} never published the tracks of scan {k0} ({seen})"
    finally:
        sub.undeclare()
    return seen["k"]


def rerun_exe() -> str:
    return str(Path(sys.executable).with_name("rerun"))


@dataclass
class Launch:
    """A ``sensornet`` launcher process and the children it was seen to have."""

    proc: subprocess.Popen
    children: list[int] = field(default_factory=list)

    def find_children(self) -> list[int]:
        """Its children now (remembered: :meth:`stop` kills them if they outlive the test)."""
        self.children = children(self.proc.pid)
        return self.children

    def stop(self) -> None:
        """Kill the launcher and every child of it still alive: those remembered and those it
        has now, found before it is killed (its children outlive a killed launcher: a test that
        failed before it looked for them left a run's world and peers running)."""
        if self.proc.poll() is None:
            self.children = sorted(set(self.children) | set(children(self.proc.pid)))
            self.proc.kill()
            self.proc.wait()
        for p in self.children:
            if alive(p):
                os.kill(p, signal.SIGKILL)


@contextmanager
def sensornet(args: list[str], cwd: Path) -> Iterator[Launch]:
    """``python -m sensornet ARGS`` in ``cwd`` (stdout and stderr piped, text); on the way out
    the launcher and its children are stopped, whatever the test did."""
    launch = Launch(subprocess.Popen([sys.executable, "-m", "sensornet", *args], cwd=cwd,
                                     env=env(), stdout=subprocess.PIPE,
                                     stderr=subprocess.PIPE, text=True))
    try:
        yield launch
    finally:
        launch.stop()


def stop_all(procs: Iterable[subprocess.Popen], grace: float = 10.0) -> None:
    """Terminate every process still running, then kill those that outlive ``grace``."""
    for p in procs:
        if p.poll() is None:
            p.terminate()
            try:
                p.wait(timeout=grace)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()
