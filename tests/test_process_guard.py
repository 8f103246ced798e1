"""The suite's own rule, checked: process tests (marked ``network``) run one per lane at a time.

``tests/process_guard.py`` holds a lane's lock while a process test of the lane runs; a second
holder at the same moment fails. Tested here with two threads racing for it (fast), and with
inner pytest sessions using this repository's ``tests/conftest.py``: under ``-n 2 --dist
loadgroup`` every process test carries its lane's ``@processesK`` group in its node id, a
module's tests run on one worker, and a process test that starts while its lane's slot is held
fails, naming the holder.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
import threading
from pathlib import Path

import pytest

from tests.process_guard import LANES, SlotTaken, group_of, lane_of, process_slot

ROOT = Path(__file__).resolve().parents[1]


def test_a_second_holder_fails_while_the_first_holds_the_slot(tmp_path):
    lock = tmp_path / "slot.lock"
    held, release = threading.Event(), threading.Event()
    errors: list[BaseException] = []

    def first():
        try:
            with process_slot(lock, "tests/a.py::test_first"):
                held.set()
                release.wait(30)
        except BaseException as exc:  # noqa: BLE001 (reported below)
            errors.append(exc)
            held.set()

    t = threading.Thread(target=first)
    t.start()
    try:
        assert held.wait(30) and not errors, errors
        with pytest.raises(SlotTaken, match=r"tests/b\.py::test_second started while "
                                             r"tests/a\.py::test_first was running"):
            with process_slot(lock, "tests/b.py::test_second"):
                pass
    finally:
        release.set()
        t.join(30)
    assert not t.is_alive() and not errors, errors
    with process_slot(lock, "tests/b.py::test_second"):  # free again once the first let go
        assert lock.read_text() == "tests/b.py::test_second"
    assert lock.read_text() == ""


def test_lanes_split_the_suites_process_modules_and_hold_apart(tmp_path):
    """Every lane gets some of this suite's process modules (by name: the same split on every
    machine), a module's tests one lane; two lanes' slots are held at once, one lane's not."""
    modules = sorted(p.relative_to(ROOT).as_posix() for p in (ROOT / "tests").glob("test_*.py")
                     if "mark.network" in p.read_text())
    lanes = {m: lane_of(f"{m}::test_x") for m in modules}
    assert set(lanes.values()) == set(range(LANES)), lanes
    assert all(lane_of(f"{m}::test_y[p]@{group_of(m)}") == k for m, k in lanes.items())
    a, b = (next(m for m, k in lanes.items() if k == lane) for lane in (0, 1))
    with process_slot(tmp_path / f"{lane_of(a)}.lock", f"{a}::t"):
        with process_slot(tmp_path / f"{lane_of(b)}.lock", f"{b}::t"):  # the other lane: free
            pass
        with pytest.raises(SlotTaken):
            with process_slot(tmp_path / f"{lane_of(a)}.lock", f"{a}::u"):
                pass


def test_the_slot_is_free_after_a_holder_raised(tmp_path):
    lock = tmp_path / "slot.lock"
    with pytest.raises(KeyError):
        with process_slot(lock, "t1"):
            raise KeyError("boom")
    with process_slot(lock, "t2"):
        pass


INNER = '''
import fcntl, os
import pytest
from tests.process_guard import lock_path

@pytest.mark.network
def test_one(request):
    assert lock_path(request.config, request.node.nodeid).read_text() == request.node.nodeid

@pytest.mark.network
def test_two(request):
    assert lock_path(request.config, request.node.nodeid).read_text() == request.node.nodeid
'''

HELD = '''
import fcntl, os
import pytest
from tests.process_guard import lock_path

KEEP = []

def test_hold_the_slot_as_another_worker_would(request):
    fd = os.open(lock_path(request.config, request.node.nodeid), os.O_RDWR | os.O_CREAT)
    fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    os.write(fd, b"elsewhere::test_running")
    KEEP.append(fd)

@pytest.mark.network
def test_a_process_test_meanwhile():
    pass
'''


def _inner(tmp_path: Path, name: str, body: str, *args: str) -> subprocess.CompletedProcess:
    """``python -m pytest`` on one test file beside a copy of this suite's conftest."""
    d = tmp_path / name
    d.mkdir()
    (d / "conftest.py").write_text((ROOT / "tests" / "conftest.py").read_text())
    (d / "test_inner.py").write_text(body)
    (d / "pytest.ini").write_text('[pytest]\nmarkers =\n    network: starts processes\n')
    # no installed plugin but xdist: the others (hypothesis, dask's, ...) only cost each
    # session's and worker's start-up (about 2 s of imports apiece, on a busy machine more)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        [str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])]),
        "PYTEST_DISABLE_PLUGIN_AUTOLOAD": "1"}
    return subprocess.run([sys.executable, "-m", "pytest", "-v", "-p", "xdist.plugin",
                           "-p", "no:cacheprovider", "--basetemp", str(d / "tmp"), *args,
                           "test_inner.py"], cwd=d, env=env, capture_output=True, text=True,
                          timeout=300)


@pytest.mark.network  # inner pytest sessions (and xdist's workers) as processes
def test_process_tests_form_one_group_and_a_held_slot_fails_the_next(tmp_path):
    p = _inner(tmp_path, "grouped", INNER, "-n", "2", "--dist", "loadgroup")
    assert p.returncode == 0, p.stdout[-3000:] + p.stderr[-2000:]
    ran = re.findall(r"\[(gw\d)\][^\n]*?PASSED[^\n]*?test_inner\.py::(test_\w+)(@\w+)?", p.stdout)
    ran += [(w, t, g) for t, g, w in re.findall(
        r"test_inner\.py::(test_\w+)(@\w+)? *\n?\[(gw\d)\][^\n]*PASSED", p.stdout)]
    got = {t: (w, g) for w, t, g in ran}
    assert set(got) == {"test_one", "test_two"}, p.stdout[-3000:]
    assert {g for _, g in got.values()} == {"@" + group_of("test_inner.py::test_one")}, got
    assert len({w for w, _ in got.values()}) == 1, got  # one worker, one after another
    p = _inner(tmp_path, "held", HELD, "-n", "0")
    assert p.returncode == 1, p.stdout[-3000:]
    assert "1 passed, 1 error" in p.stdout, p.stdout[-3000:]  # fails at its setup
    assert re.search(r"test_a_process_test_meanwhile started while elsewhere::test_running was "
                     r"running: two process tests of one lane at one moment", p.stdout), \
        p.stdout[-3000:]
