"""The ``network`` marker, enforced: with ``-m "not network"`` nothing may start a process,
and the tests that do start processes run one at a time.

Tests that start OS processes or open Zenoh sessions carry ``@pytest.mark.network`` (or a
module-level ``pytestmark``). When the marker is deselected (``python -m pytest -m "not
network"``, the fast tests), a test that still starts a subprocess, a multiprocessing worker or
a Zenoh session fails at once with a message naming the missing marker, so the fast run stays
free of processes and sessions (and fast) as tests are added. Under pytest-xdist the marked
tests form a group per lane, each on one worker (:func:`pytest_collection_modifyitems`), and
each holds its lane's process slot while it runs (``tests/process_guard.py``): a second one of
the lane starting at the same moment fails, saying which test holds it.
"""

from __future__ import annotations

import multiprocessing.process
import os
import subprocess
import tempfile
from pathlib import Path

import pytest

from tests.process_guard import SlotTaken, group_of, lock_path, process_slot


def pytest_configure(config: pytest.Config) -> None:
    """Children compile this checkout once, not at every start: with ``PYTHONDONTWRITEBYTECODE``
    set (the Dockerfile's, and this machine's) every ``python -m sensornet`` process the tests
    start (about a thousand) compiled its ~130 modules again, 0.1-0.2 s CPU a process. Their
    bytecode goes to a cache folder outside the checkout (``PYTHONPYCACHEPREFIX``), still
    nothing written next to the sources; checked against each source's mtime and size as
    ever. Only the children's environment: this process already started."""
    if os.environ.get("PYTHONDONTWRITEBYTECODE") and not os.environ.get("PYTHONPYCACHEPREFIX"):
        os.environ.pop("PYTHONDONTWRITEBYTECODE")
        os.environ["PYTHONPYCACHEPREFIX"] = str(
            Path(tempfile.gettempdir()) / f"sensornet-pycache-{os.getuid()}")


def _network_deselected(config: pytest.Config) -> bool:
    expr = (config.getoption("markexpr", "") or "").replace(" ", "")
    return "notnetwork" in expr


@pytest.fixture(autouse=True)
def _no_processes_unless_marked(request, monkeypatch):
    if request.node.get_closest_marker("network") is not None:
        taken = None
        try:  # one process test of a lane at a moment (SlotTaken only from taking the slot)
            with process_slot(lock_path(request.config, request.node.nodeid),
                              request.node.nodeid):
                yield
        except SlotTaken as exc:
            taken = str(exc)
        if taken is not None:
            pytest.fail(taken, pytrace=False)
        return
    if not _network_deselected(request.config):
        yield
        return

    def refuse(what: str):
        def start(*args, **kwargs):
            raise AssertionError(f"{request.node.nodeid} starts {what}: mark it "
                                 f"@pytest.mark.network (the -m 'not network' run starts none)")
        return start

    monkeypatch.setattr(subprocess.Popen, "__init__", refuse("a subprocess"))
    monkeypatch.setattr(multiprocessing.process.BaseProcess, "start",
                        refuse("a multiprocessing worker"))
    try:
        import zenoh
    except ImportError:
        pass
    else:
        monkeypatch.setattr(zenoh, "open", refuse("a Zenoh session"))
    yield


def _group_suffix(item: pytest.Item, group: str) -> None:
    """Add ``@group`` to a worker's node id, as xdist's loadgroup does: pytest 9.2 keeps node ids
    in ``item._id`` (a structured id), and xdist 3.8 still writes the old ``item._nodeid``, which
    nothing reads any more (pytest-xdist issue 1386, open: the group is lost silently)."""
    new = f"{item.nodeid}@{group}"
    if hasattr(item, "_id"):
        item._id = type(item._id).parse(new)  # noqa: SLF001
    else:
        item._nodeid = new  # noqa: SLF001


@pytest.hookimpl(wrapper=True)
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]):
    """Under pytest-xdist (``-n 2 --dist loadgroup``, pyproject's default options) the tests
    that start processes form a group per lane (``tests.process_guard.group_of``: by module),
    each run one after another on one worker, so at most two process runs share the machine's
    two cores; the fast tests go to whichever worker is free after, and their CPU work overlaps
    the process tests' waiting (scans come at 10 a second).

    A worker's xdist plugin turns each item's ``xdist_group`` marks into an ``@processesK``
    suffix of its node id in its own ``pytest_collection_modifyitems``, and the scheduler groups
    by that suffix: the marks are added before every plain implementation runs (this wrapper's
    first half), and the suffix checked after them all (its second half): added here where
    xdist's did not take (:func:`_group_suffix`). Before both, process tests ran on both workers
    in no order; a lane's slot (``tests/process_guard.py``) now fails two of one lane at once."""
    for item in items:
        if item.get_closest_marker("network") is not None:
            item.add_marker(pytest.mark.xdist_group(group_of(item.nodeid)))
    result = yield
    if getattr(config.option, "loadgroup", False):  # set on an xdist worker under loadgroup
        for item in items:
            if "@" in item.nodeid.rsplit("]", 1)[-1]:
                continue
            if item.get_closest_marker("network") is not None:
                _group_suffix(item, group_of(item.nodeid))
            elif marks := list(item.iter_markers("xdist_group")):
                # a fast module's own group, so its module fixture is computed on one worker,
                # not once on each (xdist's way of naming: the marks' names sorted, joined)
                _group_suffix(item, "_".join(sorted({str(m.args[0] if m.args else m.kwargs.get(
                    "name", "default")) for m in marks})))
    return result
