"""One process test per lane at a time, checked: an exclusive, non-blocking ``flock`` per lane.

The tests marked ``network`` start OS processes and Zenoh sessions. They are split by module
into :data:`LANES` lanes (:func:`lane_of`); pyproject's ``-n 2 --dist loadgroup`` with the
``xdist_group("processesK")`` mark that ``tests/conftest.py`` gives them sends each lane to
one worker, its tests one after another, so at most :data:`LANES` process runs share the
machine at a moment, as on any busy machine (the tests wait on events, not on time).
:func:`process_slot` holds a lane's lock file, shared by the session's workers, while such a
test runs; a second test of that lane that starts meanwhile (the grouping broken) fails at
once, naming the test that holds the slot, instead of passing or failing by luck.
"""

from __future__ import annotations

import fcntl
import os
import zlib
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest

LOCK_NAME = "sensornet-process-tests-{lane}.lock"

LANES = 2
"""Process tests that may run at one moment, one per lane: with one lane the process tests
(about 200, some 10-20 s each) ran one after another on one worker for most of the suite's 14
minutes while the other worker sat idle after the fast tests; with two, each worker takes a
lane. Measured (5 Dec, clean clones): ``python -m pytest -m network`` 916 s in one lane, 519 s
in two with every process test passing at load 8-14 from other work; the whole suite 10:34 on
an idle machine (14:05 with one lane)."""


def lane_of(nodeid: str) -> int:
    """A process test's lane, by its module (a module's tests share module fixtures, so one
    lane): crc32 of the module's path, the same split on every machine and run."""
    return zlib.crc32(nodeid.split("::", 1)[0].encode()) % LANES


def group_of(nodeid: str) -> str:
    """The xdist group of a process test: ``processes`` and its lane."""
    return f"processes{lane_of(nodeid)}"


class SlotTaken(RuntimeError):
    """Another process test holds the slot (its node id in the message)."""


def lock_path(config: pytest.Config, nodeid: str) -> Path:
    """The lock file of ``nodeid``'s lane in the session's base temporary folder, shared by its
    xdist workers (a worker's base folder is ``<session's>/popen-gwN``) and by no other pytest
    session."""
    base = config._tmp_path_factory.getbasetemp()  # noqa: SLF001 (pytest's own factory)
    if hasattr(config, "workerinput"):  # an xdist worker: the controller's folder
        base = base.parent
    return base / LOCK_NAME.format(lane=lane_of(nodeid))


@contextmanager
def process_slot(path: Path, who: str) -> Iterator[None]:
    """Hold the process slot at ``path`` for ``who`` (a test's node id); :class:`SlotTaken` if
    another holder has it. ``flock`` belongs to the open file, so two holders in one process
    (threads) exclude each other as two processes do, and a crashed holder frees it."""
    fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(fd, 4096, 0).decode(errors="replace").strip() or "another test"
            raise SlotTaken(f"{who} started while {holder} was running: two process tests of "
                            f"one lane at one moment (a lane's tests share one xdist group, "
                            f"'processesK', and run one after another; see tests/conftest.py)"
                            ) from None
        try:
            os.ftruncate(fd, 0)
            os.pwrite(fd, who.encode(), 0)
            yield
        finally:
            os.ftruncate(fd, 0)
            fcntl.flock(fd, fcntl.LOCK_UN)
    finally:
        os.close(fd)
