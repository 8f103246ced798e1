"""The live view yields every core to the peers and falls behind alone (issue 38): its threads
in SCHED_IDLE, the run asks for it, a refusal falls back to nice and says so; a view whose
drawing lags its peers by seconds decimates its map frames, and at its end draws what it heard
(what it cannot is counted); the ``--discard`` diagnostic drops everything but the control."""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
import rerun as rr
import zenoh
from sensornet.peers.session import endpoint, free_port, zenoh_config
from sensornet.protocol.codec import encode
from sensornet.protocol.messages import Tracks
from sensornet.sim.run.launcher import _view_command

import sensornet.cli.commands.view as view_cmd
import sensornet.view as view_mod
from sensornet.view import (
    BEHIND_S,
    MAP_KEEP,
    SERIES_EVERY,
    LiveView,
    ViewState,
    idle_process,
    normal_process,
)
from tests.processes import env, stop_all, wait_for

linux = pytest.mark.skipif(not hasattr(os, "SCHED_IDLE"), reason="SCHED_IDLE: Linux")


@linux
def test_a_thread_put_idle_and_the_threads_it_starts_are_sched_idle():
    """The thread given is SCHED_IDLE and a thread it starts after inherits the class (the
    view's Rerun threads start after it is lowered); the test's own thread stays normal."""
    seen: dict[str, int] = {}
    go, stop = threading.Event(), threading.Event()

    def child() -> None:
        seen["child"] = os.sched_getscheduler(0)
        stop.wait(5)

    def parent() -> None:
        go.wait(5)
        seen["parent"] = os.sched_getscheduler(0)
        t = threading.Thread(target=child)
        t.start()
        t.join()

    t = threading.Thread(target=parent)
    t.start()
    try:
        assert idle_process(3, tids=[t.native_id]) == ("idle", 1)
        go.set()
        while "child" not in seen and t.is_alive():
            t.join(0.01)
    finally:
        go.set()
        stop.set()
        t.join()
    assert seen == {"parent": os.SCHED_IDLE, "child": os.SCHED_IDLE}
    assert os.sched_getscheduler(0) != os.SCHED_IDLE


@linux
def test_a_refused_sched_idle_falls_back_to_nice(monkeypatch):
    """Where SCHED_IDLE is refused (EPERM), the whole process is niced instead."""
    niced = []

    def refuse(*a):
        raise PermissionError(1, "Operation not permitted")

    monkeypatch.setattr(view_mod.os, "sched_setscheduler", refuse)
    monkeypatch.setattr(view_mod, "nice_process", lambda n: niced.append(n) or 4)
    assert idle_process(7) == ("nice", 4) and niced == [7]


def test_the_view_says_how_it_lowered_itself(monkeypatch, capsys):
    """``--idle``: one line, SCHED_IDLE or the nice fallback; ``--nice`` alone: nice only."""
    calls = []
    monkeypatch.setattr(view_cmd, "nice_process", lambda n: calls.append(("nice", n)))
    for how in ("idle", "nice"):
        monkeypatch.setattr(view_cmd, "idle_process",
                            lambda n, how=how: calls.append(("idle", n)) or (how, 5))
        view_cmd._lower_priority(argparse.Namespace(idle=True, nice=0))
    view_cmd._lower_priority(argparse.Namespace(idle=False, nice=3))
    err = capsys.readouterr().err.splitlines()
    assert err == ["view: 5 threads in SCHED_IDLE (CPU time no peer wants)",
                   "view: SCHED_IDLE not permitted here: nice +10 instead"]
    assert calls == [("idle", 10), ("idle", 10), ("nice", 3)]


def test_the_run_starts_its_view_idle():
    """``sensornet run``'s view command asks for SCHED_IDLE (nice 10 its fallback)."""
    cmd = _view_command("net", "tcp/127.0.0.1:1", [], "seed004", [], "rid", [], Path("out"),
                        True, None)
    assert "--idle" in cmd and cmd[cmd.index("--nice") + 1] == "10"


class _Sample:
    def __init__(self, key: str, payload: bytes) -> None:
        self.key_expr, self._p = key, payload

    @property
    def payload(self):
        return self

    def to_bytes(self) -> bytes:
        return self._p


def test_discard_drops_all_but_the_worlds_control():
    """The diagnostic view hears everything and keeps only the control (the run's end)."""
    v = LiveView("net", None, None, None, discard=True, say=lambda s: None)
    for key in ("scan/s1", "scans/h1", "truth", "telemetries/h1", "telemetry/s2", "ctl"):
        v._on_sample(_Sample(f"sensornet/net/{key}", b"x"))
    assert v.discarded == 5 and v.q.qsize() == 1
    assert v.q.get_nowait() == ("sensornet/net/ctl", b"x")
    keep = LiveView("net", None, None, None, say=lambda s: None)
    keep._on_sample(_Sample("sensornet/net/truth", b"y"))
    assert keep.discarded == 0 and keep.q.qsize() == 1


class _Rec:
    def __init__(self) -> None:
        self.paths: list[str] = []

    def send_columns(self, path, indexes, columns):
        self.paths.append(path)


def _view(said: list[str] | None = None) -> LiveView:
    return LiveView("net", lambda b: ViewState(b, ["s1"]), rr, _Rec(),
                    say=(said.append if said is not None else lambda s: None))


def test_a_view_whose_queue_stays_full_for_seconds_decimates_its_map_frames():
    """Few messages waiting, but the queue not empty for :data:`BEHIND_S`: behind (map frames
    beyond the newest :data:`MAP_KEEP` decimated, counted and said); a view that emptied its
    queue just now: not, though its messages' send times are old (a replay's, another
    machine's clock: the view measures on its own)."""
    said: list[str] = []
    v = _view(said)
    for k in range(1, MAP_KEEP + 6):
        v.state.receive("sensornet/net/telemetry/s1", encode(Tracks("s1", k, np.zeros((1, 4)))))
    v.q.put(("sensornet/net/telemetry/s1", encode(Tracks("s1", 99, np.zeros((1, 4))))))
    v._empty_at = time.monotonic() - BEHIND_S - 0.5
    assert v.behind()
    v.flush()
    assert v.batcher.map_keep == MAP_KEEP and v.batcher.decimated > 0
    assert said and "map frames decimated" in said[-1]
    prompt = _view()
    for k in range(1, MAP_KEEP + 6):
        prompt.state.receive("sensornet/net/telemetry/s1", encode(Tracks(
            "s1", k, np.zeros((1, 4)), send_time=time.time() - 3600.0)))
    prompt.q.put(("sensornet/net/telemetry/s1", encode(Tracks("s1", 99, np.zeros((1, 4))))))
    prompt.drain(0.1)  # emptied: keeps up
    assert not prompt.behind()
    prompt.flush()
    assert prompt.batcher.map_keep is None and prompt.batcher.decimated == 0


@pytest.mark.parametrize("every", [SERIES_EVERY, 4])
def test_the_health_series_go_every_few_flushes_the_map_every_flush(monkeypatch, every):
    """Series rows go at the first flush, then every ``SERIES_EVERY``-th (their rows waiting
    meanwhile, one call for all of them); map rows go at each; nothing is lost, and the end's
    flush sends what waits."""
    monkeypatch.setattr(view_mod, "SERIES_EVERY", every)
    rec = _Rec()
    v = LiveView("net", lambda b: ViewState(b, ["s1"]), rr, rec, say=lambda s: None)
    n = 2 * every + 1
    for k in range(1, n + 1):
        v.batcher.scalar("metrics/latency_ms/s1", k, 0.1 * k, float(k))
        v.batcher.points("peers/s1/tracks", k, 0.1 * k, np.zeros((1, 2)), (1, 2, 3), 5.0)
        v._empty_at = time.monotonic()
        v.flush()
    assert rec.paths.count("peers/s1/tracks") == n
    assert rec.paths.count("metrics/latency_ms/s1") == 3  # flushes 1, every + 1, 2 every + 1
    v.batcher.flush()
    assert rec.paths.count("metrics/latency_ms/s1") == 3 and v.batcher.rows_sent == 2 * n
    v.batcher.scalar("metrics/latency_ms/s1", n + 1, 0.1, 1.0)
    v.flush()  # flush 2 every + 2: held unless every series goes every flush
    assert rec.paths.count("metrics/latency_ms/s1") == (4 if every == 1 else 3)


def test_at_its_end_the_view_draws_what_it_heard_and_counts_what_it_cannot(monkeypatch):
    """Messages still waiting when the view stops are drawn (a view that ran behind has
    seconds of them); with no time left for them they are counted as dropped."""
    v = _view()
    for k in range(1, 41):
        v.q.put(("sensornet/net/telemetry/s1", encode(Tracks("s1", k, np.zeros((1, 4))))))
    v.stop.set()
    v.run()
    assert v.state.handled == 40 and v.dropped == 0 and v.q.empty()
    monkeypatch.setattr(view_mod, "END_DRAIN_S", 0.0)
    late = _view()
    for k in range(1, 41):
        late.q.put(("sensornet/net/telemetry/s1", encode(Tracks("s1", k, np.zeros((1, 4))))))
    late.finish()
    assert late.state.handled == 0 and late.dropped == 40 and late.q.empty()


@pytest.mark.network  # a view process joining a Zenoh session of the test's
@linux
def test_every_thread_of_a_view_process_started_idle_is_sched_idle(tmp_path):
    """``sensornet view --idle``, joined and recording: each of its threads (Python's, Zenoh's,
    Rerun's) is SCHED_IDLE, read from outside the process."""
    ep = endpoint(free_port())
    session = zenoh.open(zenoh_config([ep], []))
    err = tmp_path / "view.err"
    with err.open("w") as fh:
        view = subprocess.Popen(
            [sys.executable, "-m", "sensornet", "view", "idlenet", "--connect", ep, "--idle",
             "--duration", "60", "--out", str(tmp_path / "v.rrd")], cwd=tmp_path, env=env(),
            stdout=subprocess.DEVNULL, stderr=fh)
    try:
        wait_for(lambda: "Ctrl-C to detach" in err.read_text() or view.poll() is not None,
                 120, "the view's recording open")
        assert view.poll() is None, err.read_text()[-2000:]
        assert "threads in SCHED_IDLE" in err.read_text()
        policies = {}
        for tid in os.listdir(f"/proc/{view.pid}/task"):
            try:
                policies[int(tid)] = os.sched_getscheduler(int(tid))
            except ProcessLookupError:  # ended meanwhile
                pass
        assert len(policies) >= 3 and set(policies.values()) == {os.SCHED_IDLE}, policies
    finally:
        stop_all([view])
        session.close()


if __name__ == "__main__":
    sys.exit(pytest.main([__file__, "-q", "-n", "0"]))


@linux
def test_a_view_put_idle_is_back_in_the_normal_class_at_its_end():
    """A view left no CPU while the network ran must still draw its last messages and write
    its recording within the run's grace: at the loop's end ``at_end`` (``normal_process``
    for ``--idle``) puts its threads back in SCHED_OTHER (here one thread of the test's)."""
    seen: dict[str, int] = {}
    lowered, raised, stop = threading.Event(), threading.Event(), threading.Event()

    def worker() -> None:
        lowered.wait(5)
        seen["idle"] = os.sched_getscheduler(0)
        raised.wait(5)
        seen["normal"] = os.sched_getscheduler(0)
        stop.wait(5)

    t = threading.Thread(target=worker)
    t.start()
    try:
        assert idle_process(3, tids=[t.native_id]) == ("idle", 1)
        lowered.set()
        while "idle" not in seen and t.is_alive():
            t.join(0.01)
        assert normal_process(tids=[t.native_id]) == 1
        raised.set()
        while "normal" not in seen and t.is_alive():
            t.join(0.01)
    finally:
        lowered.set()
        raised.set()
        stop.set()
        t.join(5)
    assert seen == {"idle": os.SCHED_IDLE, "normal": os.SCHED_OTHER}
    assert os.sched_getscheduler(0) == os.SCHED_OTHER  # the test's own thread untouched


def test_the_loop_calls_at_end_before_its_last_drawing():
    """``LiveView.run`` calls ``at_end`` once when it stops, before the final drain."""
    view = LiveView("net", None, None, None, say=lambda s: None)
    order = []
    view.at_end = lambda: order.append("at_end")
    view.drain = lambda timeout: order.append("drain")
    view.finish = lambda: order.append("finish")
    view.stop.set()
    view.batcher = type("B", (), {"flush": lambda self: None})()
    view.note = lambda final=False: None
    view.run()
    assert order == ["at_end", "drain", "finish"]
