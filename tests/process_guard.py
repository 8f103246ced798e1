"""One process test at a time, checked: an exclusive, non-blocking ``flock`` per session.

The tests marked ``network`` start OS processes and Zenoh sessions; pyproject's ``-n 2 --dist
loadgroup`` with the ``xdist_group("processes")`` mark that ``tests/conftest.py`` gives them
sends them all to one worker, one after another, so two process runs never compete for a
2-core machine. :func:`process_slot` holds a lock file shared by the session's workers while
such a test runs; a second one that starts meanwhile (the grouping broken) fails at once,
naming the test that holds the slot, instead of passing or failing by luck under load.
"""

from __future__ import annotations

import fcntl
import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest

LOCK_NAME = "sensornet-process-tests.lock"


class SlotTaken(RuntimeError):
    """Another process test holds the slot (its node id in the message)."""


def lock_path(config: pytest.Config) -> Path:
    """The slot's lock file in the session's base temporary folder, shared by its xdist workers
    (a worker's base folder is ``<session's>/popen-gwN``) and by no other pytest session."""
    base = config._tmp_path_factory.getbasetemp()  # noqa: SLF001 (pytest's own factory)
    if hasattr(config, "workerinput"):  # an xdist worker: the controller's folder
        base = base.parent
    return base / LOCK_NAME


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
            raise SlotTaken(f"{who} started while {holder} was running: two process tests at "
                            f"one moment (they must share one xdist group, 'processes', and "
                            f"run one after another; see tests/conftest.py)") from None
        try:
            os.ftruncate(fd, 0)
            os.pwrite(fd, who.encode(), 0)
            yield
        finally:
            os.ftruncate(fd, 0)
            fcntl.flock(fd, fcntl.LOCK_UN)
    finally:
        os.close(fd)
