"""The ``network`` marker, enforced: with ``-m "not network"`` nothing may start a process.

Tests that start OS processes or open Zenoh sessions carry ``@pytest.mark.network`` (or a
module-level ``pytestmark``). When the marker is deselected (``python -m pytest -m "not
network"``, the fast tests), a test that still starts a subprocess, a multiprocessing worker or
a Zenoh session fails at once with a message naming the missing marker, so the fast run stays
free of processes and sessions (and fast) as tests are added.
"""

from __future__ import annotations

import multiprocessing.process
import subprocess

import pytest


def _network_deselected(config: pytest.Config) -> bool:
    expr = (config.getoption("markexpr", "") or "").replace(" ", "")
    return "notnetwork" in expr


@pytest.fixture(autouse=True)
def _no_processes_unless_marked(request, monkeypatch):
    if request.node.get_closest_marker("network") is not None:
        yield
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



def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Under pytest-xdist (``-n 2 --dist loadgroup``, pyproject's default options) the tests
    that start processes form one group, run one after another on one worker, so two process
    runs never compete for the machine's two cores; the fast tests go to whichever worker is
    free, and their CPU work overlaps the process tests' waiting (scans come at 10 a second)."""
    for item in items:
        if item.get_closest_marker("network") is not None:
            item.add_marker(pytest.mark.xdist_group("processes"))
