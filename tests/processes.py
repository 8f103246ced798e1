"""What the process tests share: the environment of a child, the processes a launcher
started, waiting on an event, and stopping everything a test started whatever happened."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

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
        """Kill the launcher and every remembered child still alive."""
        if self.proc.poll() is None:
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
