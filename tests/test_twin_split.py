"""The twin over worker processes (``run_twin(..., workers=2)``, sim/run/twin_split.py): the
same tracks, summaries, per-scan tables, OSPA and ages as the one-process twin, to the bit,
both computed here (seed 000 with GM-PHD and LMB peers, with link faults, and a minute of the
shipped paris-8 excerpt); the host batch per worker to 1e-12 (a batch's stacked fusion is
not bit-stable in its composition, as against no batch); the split's groups; a worker's
failure or death is a one-line error and leaves no process behind."""

from __future__ import annotations

import math
import multiprocessing
import os
import signal

import numpy as np
import pytest
from sensornet.sim.run.twin import run_twin
from sensornet.sim.run.twin_split import split_peers
from sensornet.sim.scenario import load_scenario

from tests.processes import children

pytestmark = pytest.mark.network  # forks worker processes


def _same(a, b, path: str = "", rtol: float = 0.0) -> None:
    """``a == b`` through dicts, lists and arrays (NaN equal to NaN; ``rtol`` for floats)."""
    if isinstance(a, dict):
        assert isinstance(b, dict) and a.keys() == b.keys(), f"{path}: {set(a) ^ set(b)}"
        for k in a:
            _same(a[k], b[k], f"{path}.{k}", rtol)
    elif isinstance(a, list | tuple):
        assert len(a) == len(b), f"{path}: {len(a)} vs {len(b)}"
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            _same(x, y, f"{path}[{i}]", rtol)
    elif isinstance(a, np.ndarray):
        assert isinstance(b, np.ndarray) and a.shape == b.shape and a.dtype == b.dtype, path
        if rtol and a.dtype.kind == "f":
            np.testing.assert_allclose(a, b, rtol=rtol, atol=0.0, err_msg=path)
        else:
            assert np.array_equal(a, b, equal_nan=a.dtype.kind in "fc"), path
    elif isinstance(a, float) and isinstance(b, float):
        if rtol:
            assert a == pytest.approx(b, rel=rtol, nan_ok=True), path
        else:
            assert a == b or (math.isnan(a) and math.isnan(b)), f"{path}: {a} vs {b}"
    else:
        assert a == b, f"{path}: {a!r} vs {b!r}"


def _compare(one, two, names: list[str], rtol: float = 0.0, skip: tuple = ()) -> None:
    """Everything the callers read of a twin result (study tables, ``sensornet run --sim``)."""
    _same(one.tracks, two.tracks, "tracks", rtol)
    for n in names:
        s1, s2 = one.summary(n), two.summary(n)
        for k in skip:
            s1.pop(k), s2.pop(k)
        _same(s1, s2, f"summary[{n}]", rtol)
        _same(one.peers[n].scorer.results.table(n), two.peers[n].scorer.results.table(n),
              f"table[{n}]", rtol)
        _same(one.mean_ospa(n, "fused"), two.mean_ospa(n, "fused"), f"ospa[{n}]", rtol)
    _same(one.ospa, two.ospa, "ospa", rtol)
    _same(one.ages, two.ages, "ages")
    _same(one.stops, two.stops, "stops")
    _same(one.transport_drops, two.transport_drops, "drops")


@pytest.mark.parametrize("kind", ["gmphd", "lmb"])
def test_seed000_split_equals_one_process_to_the_bit(kind):
    scn = load_scenario("seed000", overrides={"network.filter": kind, "scenario.num_scans": 30})
    one, two = run_twin(scn, 0), run_twin(scn, 0, workers=2)
    _compare(one, two, scn.sensor_names)
    assert len(one.tracks["s3"]) == 30 and one.peers["s3"].consensus.stats.fusions > 0
    with pytest.raises(RuntimeError, match="stayed in a twin worker"):
        two.peers["s1"].scorer.truth_fn(1)  # a closure: not copied back


def test_each_worker_runs_one_blas_thread_the_parent_keeps_its_own():
    """A forked worker limits its BLAS libraries to one thread each
    (:func:`sim.run.twin_split.one_blas_thread`: two workers with a thread per core each
    oversubscribe two cores); the parent's two stay two."""
    threadpoolctl = pytest.importorskip("threadpoolctl")

    def blas() -> list[int]:
        return [i["num_threads"] for i in threadpoolctl.threadpool_info()
                if i["user_api"] == "blas"]

    scn = load_scenario("seed000", overrides={"scenario.num_scans": 3})
    with threadpoolctl.threadpool_limits(2, user_api="blas"):  # what a worker inherits
        parent = blas()
        res = run_twin(scn, 0, workers=2)
        assert blas() == parent and parent
        assert set(parent) == {2} or (os.cpu_count() or 1) < 2  # OpenBLAS caps at the cores
    assert res.split["blas_threads"] == [[1] * len(parent)] * 2


@pytest.mark.parametrize("kind", ["gmphd", "lmb"])
def test_link_faults_split_equal_with_the_same_decisions(kind):
    scn = load_scenario("seed000", overrides={
        "network.filter": kind, "scenario.num_scans": 30, "network.rounds": 2,
        "faults.default.delay": {"kind": "scans", "low": 0, "high": 2},
        "faults.default.reorder": 0.5, "faults.default.loss": 0.2,
        "faults.default.duplicate": 0.2, "faults.peers.s3.partitions": [[1.0, 1.5]]})
    one, two = run_twin(scn, 3), run_twin(scn, 3, workers=2)
    _compare(one, two, scn.sensor_names)
    assert sorted(map(repr, one.faults.log)) == sorted(map(repr, two.faults.log))
    assert one.faults.counts() == two.faults.counts()
    assert one.faults.counts()["drop-loss"] > 0 and one.faults.counts()["duplicate"] > 0


def test_host_batch_per_worker_equal_to_rounding():
    """Each worker batches its own peers (its rounds fused together): the numbers of a
    batch's stacked fusion move in the last bits with its composition (as batch vs none)."""
    scn = load_scenario("seed000", overrides={"scenario.num_scans": 30})
    one, two = run_twin(scn, 0, batch=True), run_twin(scn, 0, batch=True, workers=2)
    _compare(one, two, scn.sensor_names, rtol=1e-12,
             skip=("prepared_steps",))


@pytest.mark.parametrize("kind", ["gmphd", "lmb"])
def test_paris8_excerpt_split_equals_one_process_to_the_bit(kind):
    """The traffic study's fused twin (8 radars, all neighbours; the second worker's peers
    get one instant's estimates in another order: the rounds wait for every input and fuse
    them sorted by sender)."""
    scn = load_scenario("paris-8", overrides={"network.filter": kind,
                                              "scenario.num_scans": 30})
    one, two = run_twin(scn, 0), run_twin(scn, 0, workers=2)
    _compare(one, two, scn.sensor_names)
    assert sum(len(t) for t in one.tracks["west"].values()) > 0


def test_split_is_balanced_and_cuts_fewest_links():
    names = [f"p{i}" for i in range(6)]
    line = {n: [m for m in names if abs(int(m[1]) - int(n[1])) == 1] for n in names}
    assert split_peers(names, line, 2) == [names[:3], names[3:]]
    odd = {"a": ["c"], "b": ["d"], "c": ["a"], "d": ["b"]}  # two pairs: a-c, b-d
    assert split_peers(list("abcd"), odd, 2) == [["a", "c"], ["b", "d"]]
    full = {n: [m for m in names if m != n] for n in names}
    assert split_peers(names, full, 2) == [names[:3], names[3:]]
    assert [len(g) for g in split_peers(names, full, 4)] == [2, 2, 1, 1]
    assert split_peers(names[:1], {"p0": []}, 2) == [["p0"]]


def test_workers_below_one_is_an_error():
    scn = load_scenario("seed000", overrides={"scenario.num_scans": 2})
    with pytest.raises(ValueError, match="workers must be >= 1"):
        run_twin(scn, 0, workers=0)


@pytest.mark.parametrize("how", ["raise", "die"])
def test_a_failing_worker_is_one_line_and_no_process_is_left(how):
    """A link's delay function that fails in the worker of s3's neighbours' links at scan 5:
    it raises (the worker's error comes back as one line) or kills its own process (the
    parent says it died); either way every worker is ended and reaped."""
    scn = load_scenario("seed000", overrides={"scenario.num_scans": 20})
    parent = os.getpid()

    def delay(sender: str, receiver: str, msg) -> float:
        if os.getpid() != parent and msg.k == 5:
            if how == "raise":
                raise ValueError("link broke\nsecond line")
            os.kill(os.getpid(), signal.SIGKILL)
        return 0.0

    before = set(children(os.getpid()))
    with pytest.raises(RuntimeError) as err:
        run_twin(scn, 0, delay=delay, workers=2)
    text = str(err.value)
    assert "\n" not in text and "twin worker" in text
    assert ("ValueError: link broke" in text) if how == "raise" else ("died" in text)
    assert multiprocessing.active_children() == []
    assert set(children(os.getpid())) <= before


def test_cli_sim_twin_workers_prints_the_same_table(tmp_path, capsys):
    """``sensornet run seed000 --sim --twin-workers 2``: the one-process run's peer table;
    without ``--sim`` the flag is refused in one line."""
    from sensornet.cli import main

    tables = []
    for w in ("1", "2"):
        assert main(["run", "seed000", "--sim", "--twin-workers", w, "--set",
                     "scenario.num_scans=8", "--out", str(tmp_path / w)]) == 0
        out = capsys.readouterr().out
        tables.append([ln for ln in out.splitlines() if ln.startswith("| s")])
    assert len(tables[0]) == 3 and tables[0] == tables[1]
    assert main(["run", "seed000", "--twin-workers", "2", "--out", str(tmp_path / "r")]) != 0
    assert "--twin-workers is the twin's: add --sim" in capsys.readouterr().err


def test_traffic_study_part_over_two_workers_has_the_same_rows():
    """The study's fused part (``--twin-workers 2``): the same per-peer rows, the workers'
    CPU counted; the default is 2 processes from an hour's window on 2 cores."""
    from sensornet.sim.studies.traffic import study as S

    over = {"scenario.num_scans": 20}
    one, two = (S.run_part("paris-8", over, "gmphd", "fused", 0, with_hota=False, workers=w)
                for w in (1, 2))
    assert one.rows == two.rows and len(one.rows) == 8
    assert two.cpu > 0.5 * one.cpu  # the children's CPU is in it (this process's is not)
    assert S.default_twin_workers(3 * 3600) == (2 if (os.cpu_count() or 1) >= 2 else 1)
    assert S.default_twin_workers(600) == 1
