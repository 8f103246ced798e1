"""Fault decisions are keyed by (seed, link, scan, round, kind, copy), not by the order of draws.

So the twin, which decides when a message leaves, and the real processes, which decide when it
arrives (in whatever order, some never), take the same decisions: checked here on the
injector alone, and line by line between the twin's fault log and the real processes'.
"""

from __future__ import annotations

import csv
import random
import zlib
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from sensornet.peers.faults import FaultInjector, default_msg_id, message_key
from sensornet.sim.scenario import load_scenario, parse_faults, scenario_text

INTERVAL = 0.1
PEERS = ["s1", "s2", "s3"]
SPEC = {"default": {"delay": {"kind": "scans", "low": 0, "high": 2}, "loss": 0.3,
                    "duplicate": 0.3, "reorder": 0.3},
        "peers": {"s3": {"partitions": [[1.05, 1.45]]}},
        "links": [{"from": "s1", "to": "s2", "delay": {"kind": "exponential", "mean": 0.05}}]}


def _plan():
    return parse_faults(SPEC, INTERVAL, PEERS)


def _messages(scans: int = 30, rounds: int = 2) -> list[tuple[str, str, SimpleNamespace]]:
    return [(s, r, SimpleNamespace(sender=s, k=k, round=rnd, kind=kind))
            for k in range(1, scans + 1) for rnd in range(rounds)
            for kind in ("posterior", "prediction")
            for s in PEERS for r in PEERS if s != r]


def _decisions(inj: FaultInjector) -> dict[tuple[str, str, str], tuple]:
    out = {}
    for rec in inj.log:
        key = (rec.sender, rec.receiver, rec.msg_id)
        assert key not in out, key
        out[key] = (rec.t, rec.action, rec.delays, rec.reordered)
    return out


def test_same_key_same_decision_in_any_order_and_subset() -> None:
    messages = _messages()
    in_order = FaultInjector(_plan(), 7)
    for s, r, msg in messages:
        in_order.deliveries(s, r, msg.k * INTERVAL, msg)
    expected = _decisions(in_order)
    assert len(expected) == len(messages)
    assert {rec.action for rec in in_order.log} == {
        "deliver", "drop-loss", "drop-partition", "duplicate", "reorder"}

    rng = random.Random(3)
    for trial in range(3):
        shuffled = messages[:]
        rng.shuffle(shuffled)
        if trial == 2:  # some never arrive; the others do not notice
            shuffled = shuffled[: len(shuffled) // 3]
        inj = FaultInjector(_plan(), 7)
        for s, r, msg in shuffled:
            # the runtime passes its own (later, jittered) run-clock time: decisions use the
            # message's scan time anyway
            inj.deliveries(s, r, msg.k * INTERVAL + rng.uniform(0.0, 0.09), msg)
        got = _decisions(inj)
        assert got == {key: expected[key] for key in got}
        assert [rec.msg_id for rec in inj.log] == [default_msg_id(m) for _, _, m in shuffled]


def test_a_decision_is_its_documented_draw() -> None:
    """Pin the key: the twin and the runtime share it, and other tools may recompute it."""
    plan = _plan()
    inj = FaultInjector(plan, 12345)
    msg = SimpleNamespace(sender="s2", k=17, round=1, kind="posterior")
    crc = [zlib.crc32(x.encode()) for x in ("s2", "s1", "posterior")]

    def rng(stream: int) -> np.random.Generator:
        return np.random.default_rng(np.random.SeedSequence(
            [12345, crc[0], crc[1], 17, 1, crc[2], stream]))

    delays = inj.deliveries("s2", "s1", 99.0, msg)
    u_loss, u_dup, u_reorder = rng(0).random(3)
    faults = plan.for_link("s2", "s1")
    if u_loss < faults.loss:
        assert delays == []
    else:
        assert len(delays) == (2 if u_dup < faults.duplicate else 1)
        for copy, d in enumerate(delays):
            g = rng(1 + copy)
            want = faults.delay.sample(g)
            if u_reorder < faults.reorder:
                want += faults.reorder_delay.sample(g)
            assert d == want
    assert message_key(msg) == (17, 1, crc[2])


def test_keys_tell_rounds_kinds_links_and_seeds_apart() -> None:
    plan = parse_faults({"default": {"delay": {"kind": "uniform", "low": 0.0, "high": 1.0}}},
                        INTERVAL, PEERS)

    def delay(seed=1, s="s1", r="s2", k=5, rnd=0, kind="posterior") -> float:
        msg = SimpleNamespace(sender=s, k=k, round=rnd, kind=kind)
        return FaultInjector(plan, seed).deliveries(s, r, 0.0, msg)[0]

    base = delay()
    assert base == delay()
    for other in (delay(seed=2), delay(s="s2", r="s1"), delay(r="s3"), delay(k=6),
                  delay(rnd=1), delay(kind="prediction")):
        assert other != base
    assert default_msg_id(SimpleNamespace(sender="s1", k=5, round=0, kind="prediction")) \
        == "s1:k5:r0:prediction"
    assert default_msg_id(SimpleNamespace(sender="s1", k=5, round=2)) == "s1:k5:r2"


def test_partitions_apply_at_the_scan_time() -> None:
    plan = parse_faults({"default": {"partitions": [[0.5, 0.8]]}}, INTERVAL, PEERS)
    inj = FaultInjector(plan, 0)
    for k in range(1, 11):
        msg = SimpleNamespace(sender="s1", k=k, round=0, kind="posterior")
        inj.deliveries("s1", "s2", 5.0 + k, msg)  # the caller's clock does not matter
    assert [rec.t for rec in inj.log] == [k * INTERVAL for k in range(1, 11)]
    assert [rec.action for rec in inj.log] == ["deliver"] * 4 + ["drop-partition"] * 3 + [
        "deliver"] * 3
    # without a scan (or a plan without an interval) the caller's time counts
    inj.decide("s1", "s2", 0.6, "no-scan")
    assert inj.log[-1].action == "drop-partition" and inj.log[-1].t == 0.6


# -- the twin and the real processes, line by line ---------------------------------------------

FAULTS = """
[faults.default]
loss = 0.25
duplicate = 0.3
delay = { kind = "uniform", low = 0.0, high = 0.04 }
reorder = 0.2

[faults.peers.s3]
partitions = [[0.55, 0.75]]
"""


def _rows(paths: list[Path]) -> list[list[str]]:
    rows = []
    for path in paths:
        with path.open(newline="", encoding="utf-8") as fh:
            reader = csv.reader(fh)
            assert next(reader) == ["t", "sender", "receiver", "msg_id", "action", "reordered",
                                    "delays"]
            rows += list(reader)
    return sorted(rows, key=lambda row: (row[2], row[1], row[3]))


@pytest.mark.network
@pytest.mark.timeout(180)
def test_twin_and_real_processes_write_the_same_fault_log(tmp_path) -> None:
    from sensornet.sim.run.launcher import start_run, wait_run
    from sensornet.sim.run.twin import run_twin

    source = tmp_path / "faulty.toml"
    source.write_text(scenario_text("seed000") + FAULTS)
    # 5 scans/s: a receiver decides on an estimate only if it lands inside its scan window,
    # which a loaded machine could otherwise let a slow peer fall out of
    sets = ["birth.model=truth", "scenario.num_scans=12", "network.speed=5"]
    scn = load_scenario(source, overrides={"birth.model": "truth", "scenario.num_scans": 12,
                                           "network.speed": 5})
    out = tmp_path / "run"
    out.mkdir()
    handle = start_run(scn, str(source), out, overrides=sets, rerun=False)
    try:
        codes = wait_run(handle, timeout=120)
    finally:
        handle.stop_all()
    assert all(c == 0 for c in codes.values()), codes

    real = _rows(sorted(out.glob("faults-into-*.csv")))
    twin = run_twin(scn, 0)
    twin.faults.write_log(tmp_path / "twin-faults.csv")
    virtual = _rows([tmp_path / "twin-faults.csv"])
    assert len(virtual) == 3 * 2 * scn.num_scans  # every estimate on every link, decided once
    assert {row[4] for row in virtual} >= {"deliver", "drop-loss", "drop-partition",
                                           "duplicate"}
    for line, (a, b) in enumerate(zip(real, virtual, strict=False)):
        assert a == b, (line, a, b)
    assert len(real) == len(virtual)
