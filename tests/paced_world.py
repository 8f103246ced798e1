"""A world paced by the peers, not by the clock (process tests that check a twin's every
number): scan ``k + 1`` goes out once every peer has published its tracks of scan ``k`` (each
peer closed the scan, so every copy of it arrived) and the truth of ``k`` has gone. The peers' own
deadlines stay a fallback that a test sets far off (their ``--speed``): at any load the rounds
run on arrivals, as in the twin, however long a process waits for a core.

Used by ``tests/test_flooding_peers.py``: :func:`start_paced_run` is
:func:`sim.run.launcher.start_run` with the world's command replaced by this file's entry
point, which swaps :class:`sim.run.world_process._World`'s play for :func:`paced_play` and runs
the ``sensornet world`` command unchanged (plain runs: it decodes the peers' tracks)::

    python tests/paced_world.py TIMEOUT -- world seed004 --network ... --peers s1,s2 ...
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

if __name__ == "__main__":  # run as a file by the launcher: the checkout's tests package
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import sensornet.sim.run.launcher as launcher
import sensornet.sim.run.world_process as world_process
from sensornet.protocol.codec import decode, encode
from sensornet.protocol.keys import Keys
from sensornet.protocol.messages import Control
from sensornet.sim.run.run_handle import WORLD_STARTED

from sensornet.cli import main as cli_main

SCAN_TIMEOUT = 120.0
"""Seconds the world waits at most for every peer's tracks of one scan (a failure, not a
pace: the run ends with a one-line error)."""


def start_paced_run(scn, source: str, out: Path, timeout: float = SCAN_TIMEOUT, **kw):
    """:func:`sim.run.launcher.start_run` (``kw`` its arguments) with the world started by
    this file's entry point: each scan once the peers closed the one before."""
    original = launcher._world_command
    prefix = launcher._cli()

    def command(*a, **k):
        cmd = original(*a, **k)
        assert cmd[:len(prefix)] == prefix, cmd
        return [sys.executable, str(Path(__file__).resolve()), f"{timeout:g}", "--",
                *cmd[len(prefix):]]

    launcher._world_command = command
    try:
        return launcher.start_run(scn, source, out, **kw)
    finally:
        launcher._world_command = original


def paced_play(self, timeout: float) -> None:
    """:meth:`_World.play` paced by the peers: the start message, then per scan ``k`` its
    scans, a wait until every peer published its tracks of ``k``
    (:class:`sim.run.world_process.WorldError` after ``timeout`` s), its truth and logging."""
    names = set(self.scn.sensor_names)
    n = self.scn.num_scans
    self.say(f"{WORLD_STARTED}{n} scans, each once every peer has the last one's tracks")
    self.ctl_pub.put(encode(Control("start", self.name, {"speed": self.speed},
                                    send_time=time.time())))
    for k in range(1, n + 1):
        if self.stop.is_set():
            break
        self.publish_scans(k)
        self.sent["scans_published"] = k
        end = time.monotonic() + timeout
        with self.cond:
            while not names <= self.closed.get(k, set()):
                left = end - time.monotonic()
                if left <= 0 or self.stop.is_set():
                    raise world_process.WorldError(
                        f"paced world: peers {sorted(names - self.closed.get(k, set()))} "
                        f"published no tracks of scan {k} within {timeout:g} s")
                self.cond.wait(timeout=min(left, 0.5))
        self.after_burst(k)
        if self.progress is not None:
            self.progress(k)


def pace(timeout: float) -> None:
    """Make every world of this process a paced one (:func:`paced_play`): its ``declare``
    also subscribes to the peers' tracks, counting which peer closed which scan."""
    World = world_process._World
    declare = World.declare

    def on_tracks(self, sample) -> None:
        k = decode(sample.payload.to_bytes()).k
        with self.cond:
            self.closed.setdefault(k, set()).add(Keys.last(str(sample.key_expr)))
            self.cond.notify_all()

    def paced_declare(self, session, signer, recover: bool) -> None:
        declare(self, session, signer, recover)
        self.closed = {}
        self.tracks_sub = session.declare_subscriber(self.keys.tracks("*"),
                                                     lambda s: on_tracks(self, s))

    World.declare = paced_declare
    World.play = lambda self: paced_play(self, timeout)


def main(argv: list[str]) -> int:
    """``TIMEOUT -- <sensornet arguments>``: run ``sensornet`` with its world paced."""
    if len(argv) < 2 or argv[1] != "--":
        raise ValueError(f"expected TIMEOUT -- <sensornet arguments>, got {argv[:2]!r}")
    pace(float(argv[0]))
    return cli_main(argv[2:])


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
