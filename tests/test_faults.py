"""Link faults: delay laws, rates, partitions, seeding, reordering, plans from tables, the log.

The plan comes from the scenario layer (:func:`sim.scenario.parse_faults`, the loader's
validators); keyed draws and their order independence are in ``test_fault_keys.py``.
"""

from __future__ import annotations

import csv
import dataclasses
import math
from types import SimpleNamespace

import numpy as np
import pytest
from sensornet.peers.faultplan import (
    Constant,
    Exponential,
    FaultPlan,
    LinkFaults,
    LinkLayer,
    MultiStep,
    OneStep,
    Scans,
    ShortDelay,
    Uniform,
)
from sensornet.peers.faults import ACTIONS, FaultInjector, HoldQueue
from sensornet.sim.scenario import ScenarioError, parse_faults

N = 20_000
INTERVAL = 0.1
PEERS = ["s1", "s2", "s3", "s4"]


def _within(value: float, expected: float, std: float, n: int, sigmas: float = 5.0) -> bool:
    """``value`` is within ``sigmas`` standard errors of ``expected`` (exact if ``std == 0``)."""
    return abs(value - expected) <= sigmas * std / math.sqrt(n) + 1e-12


# -- delay distributions ----------------------------------------------------------------------

def _discrete_std(count: int, step: float) -> float:
    return step * math.sqrt((count * count - 1) / 12.0)


DISTRIBUTIONS = [
    # (distribution, support low, support high (inclusive bound), mean, std, discrete values)
    (Constant(0.02), 0.02, 0.02, 0.02, 0.0, [0.02]),
    (Uniform(0.01, 0.05), 0.01, 0.05, 0.03, 0.04 / math.sqrt(12), None),
    (Exponential(0.03), 0.0, math.inf, 0.03, 0.03, None),
    (Scans(0, 3, INTERVAL), 0.0, 0.3, 0.15, _discrete_std(4, INTERVAL), [0.0, 0.1, 0.2, 0.3]),
    (Scans(2, 2, INTERVAL), 0.2, 0.2, 0.2, 0.0, [0.2]),
    (ShortDelay(INTERVAL), 0.0, INTERVAL, 0.05, INTERVAL / math.sqrt(12), None),
    (OneStep(INTERVAL), INTERVAL, INTERVAL, INTERVAL, 0.0, [INTERVAL]),
    (MultiStep(4, INTERVAL), 0.1, 0.4, 0.25, _discrete_std(4, INTERVAL), [0.1, 0.2, 0.3, 0.4]),
]


@pytest.mark.parametrize("dist, low, high, mean, std, values", DISTRIBUTIONS,
                         ids=[type(d[0]).__name__ + str(i) for i, d in enumerate(DISTRIBUTIONS)])
def test_delay_support_and_mean(dist, low, high, mean, std, values) -> None:
    rng = np.random.default_rng(1)
    one = dist.sample(rng)
    assert isinstance(one, float)
    x = dist.sample(rng, N)
    assert isinstance(x, np.ndarray) and x.shape == (N,) and x.dtype == float
    assert x.min() >= low - 1e-12 and x.max() <= high + 1e-12
    if type(dist) in (Uniform, ShortDelay):
        assert x.max() < high  # half-open: [low, high)
    assert dist.mean == pytest.approx(mean)
    assert _within(float(x.mean()), mean, std, N), (x.mean(), mean)
    if values is not None:
        assert np.allclose(np.unique(np.round(x, 9)), values)  # every value, and only those


def test_exponential_has_its_tail() -> None:
    x = Exponential(0.03).sample(np.random.default_rng(2), N)
    # P(X > 3 mean) = e^-3 ~ 0.0498
    p = float((x > 0.09).mean())
    assert _within(p, math.exp(-3), math.sqrt(math.exp(-3) * (1 - math.exp(-3))), N)


def parse_delay(spec, interval: float = INTERVAL):
    """A delay law from its scenario spelling, through the loader (``faults.default.delay``)."""
    return parse_faults({"default": {"delay": spec}}, interval, PEERS).default.delay


@pytest.mark.parametrize("spec, expected", [
    (0.01, Constant(0.01)),
    (0, Constant(0.0)),
    ("one-step", OneStep(INTERVAL)),
    ("short", ShortDelay(INTERVAL)),
    ({"kind": "constant", "value": 0.2}, Constant(0.2)),
    ({"kind": "uniform", "low": 0.0, "high": 0.05}, Uniform(0.0, 0.05)),
    ({"kind": "exponential", "mean": 0.02}, Exponential(0.02)),
    ({"kind": "scans", "low": 0, "high": 3}, Scans(0, 3, INTERVAL)),
    ({"kind": "short"}, ShortDelay(INTERVAL)),
    ({"kind": "one-step"}, OneStep(INTERVAL)),
    ({"kind": "multi-step", "max_steps": 3}, MultiStep(3, INTERVAL)),
])
def test_parse_delay(spec, expected) -> None:
    assert parse_delay(spec) == expected


@pytest.mark.parametrize("spec, culprit", [
    (-0.1, "'faults.default.delay'"),
    (True, "'faults.default.delay'"),
    ("two-step", "'faults.default.delay'"),
    ("multi-step", "max_steps"),
    ({"low": 0, "high": 3}, "'faults.default.delay.kind'"),
    ({"kind": "gauss"}, "'faults.default.delay.kind'"),
    ({"kind": "scans", "low": 0}, "'faults.default.delay.high'"),
    ({"kind": "scans", "low": 0, "high": 3, "hi": 1}, "'faults.default.delay.hi'"),
    ({"kind": "scans", "low": 0.5, "high": 3}, "'faults.default.delay.low'"),
    ({"kind": "scans", "low": 3, "high": 1}, "'faults.default.delay.high'"),
    ({"kind": "uniform", "low": 0.2, "high": 0.1}, "'faults.default.delay.high'"),
    ({"kind": "uniform", "low": "a", "high": 0.1}, "'faults.default.delay.low'"),
    ({"kind": "exponential", "mean": 0.0}, "'faults.default.delay.mean'"),
    ({"kind": "multi-step", "max_steps": 0}, "'faults.default.delay.max_steps'"),
    ({"kind": ["scans"]}, "'faults.default.delay.kind'"),
    ([0.1], "'faults.default.delay'"),
])
def test_parse_delay_rejects(spec, culprit) -> None:
    with pytest.raises(ScenarioError) as err:
        parse_delay(spec)
    assert culprit in str(err.value) and "\n" not in str(err.value), str(err.value)


def test_link_faults_validation() -> None:
    with pytest.raises(ValueError, match="loss"):
        LinkFaults(loss=1.5)
    with pytest.raises(ValueError, match="duplicate"):
        LinkFaults(duplicate=-0.1)
    with pytest.raises(ValueError, match="reorder_delay"):
        LinkFaults(reorder=0.5)  # no extra delay: nothing would be reordered
    with pytest.raises(ValueError, match="partitions"):
        LinkFaults(partitions=((20.0, 10.0),))
    LinkFaults(reorder=0.5, reorder_delay=Uniform(0.0, 0.2))


# -- the injector ------------------------------------------------------------------------------

def _injector(faults: LinkFaults, seed: int = 7) -> FaultInjector:
    return FaultInjector(FaultPlan(default=faults), seed)


def _run(inj: FaultInjector, n: int = N, sender: str = "s1", receiver: str = "s2",
         dt: float = INTERVAL) -> list[list[float]]:
    return [inj.decide(sender, receiver, i * dt, f"m{i}") for i in range(n)]


@pytest.mark.parametrize("p", [0.0, 0.1, 0.3, 1.0])
def test_loss_rate(p: float) -> None:
    inj = _injector(LinkFaults(loss=p))
    out = _run(inj)
    rate = sum(not d for d in out) / N
    assert _within(rate, p, math.sqrt(p * (1 - p)), N)
    assert inj.counts()["drop-loss"] == sum(not d for d in out)
    assert all(d == [0.0] for d in out if d)


@pytest.mark.parametrize("p", [0.0, 0.2, 0.5, 1.0])
def test_duplication_rate(p: float) -> None:
    inj = _injector(LinkFaults(duplicate=p, delay=Uniform(0.0, 0.05)))
    out = _run(inj)
    assert all(len(d) in (1, 2) for d in out)
    rate = sum(len(d) == 2 for d in out) / N
    assert _within(rate, p, math.sqrt(p * (1 - p)), N)
    assert inj.counts()["duplicate"] == sum(len(d) == 2 for d in out)
    twice = [d for d in out if len(d) == 2]
    if twice:  # each copy draws its own delay
        assert any(a != b for a, b in twice)


def test_partition_drops_inside_and_nothing_outside() -> None:
    inj = _injector(LinkFaults(partitions=((10.0, 20.0),)))
    times = np.arange(0, 3000) * 0.01  # 0 .. 29.99 s
    for t in times:
        inj.decide("s1", "s2", float(t), "m")
    for r in inj.log:
        inside = 10.0 <= r.t < 20.0
        assert r.action == ("drop-partition" if inside else "deliver"), r
    assert inj.counts()["drop-partition"] == int(((times >= 10.0) & (times < 20.0)).sum())


def test_partition_catches_messages_in_flight() -> None:
    inj = _injector(LinkFaults(delay=Constant(0.5), partitions=((10.0, 20.0),)))
    assert inj.decide("s1", "s2", 9.4, "early") == [0.5]  # arrives at 9.9, before the cut
    assert inj.decide("s1", "s2", 9.6, "flying") == []  # would arrive at 10.1
    assert inj.decide("s1", "s2", 20.0, "after") == [0.5]
    assert [r.action for r in inj.log] == ["deliver", "drop-partition", "deliver"]


def test_partition_and_probabilities_leave_the_other_draws_alone() -> None:
    lossy = dict(delay=Exponential(0.05), duplicate=0.2)
    plain = _run(_injector(LinkFaults(**lossy)), n=2000)
    cut = _run(_injector(LinkFaults(**lossy, partitions=((50.0, 100.0),))), n=2000)
    dropped = _run(_injector(LinkFaults(**lossy, loss=0.4)), n=2000)
    for i, (a, b, c) in enumerate(zip(plain, cut, dropped, strict=True)):
        t = i * INTERVAL
        if not any(t < 100.0 and t + d >= 50.0 for d in a):
            assert b == a
        if c:
            assert c == a


def test_same_seed_same_log_other_seed_differs() -> None:
    faults = LinkFaults(delay=Scans(0, 3, INTERVAL), loss=0.2, duplicate=0.1, reorder=0.3,
                        reorder_delay=Uniform(0.0, 0.2))

    def log(seed: int) -> list:
        inj = FaultInjector(FaultPlan(default=faults), seed)
        for i in range(500):
            for s, r in [("s1", "s2"), ("s2", "s1"), ("s1", "s3")]:
                inj.decide(s, r, i * INTERVAL, f"{s}:k{i}")
        return inj.log

    assert log(3) == log(3)
    assert log(3) != log(4)


def test_links_draw_from_independent_streams() -> None:
    faults = LinkFaults(delay=Exponential(0.05), loss=0.3, duplicate=0.2)
    alone = FaultInjector(FaultPlan(default=faults), 11)
    busy = FaultInjector(FaultPlan(default=faults, links={
        ("s1", "s3"): LinkFaults(delay=Uniform(0.0, 1.0), loss=0.5)}), 11)
    for i in range(1000):
        t = i * INTERVAL
        alone.decide("s1", "s2", t, i)
        busy.decide("s2", "s1", t, i)  # other links, interleaved, one with other faults
        busy.decide("s1", "s3", t, i)
        busy.decide("s1", "s2", t, i)
        busy.decide("s3", "s2", t, i)
    mine = [r for r in busy.log if (r.sender, r.receiver) == ("s1", "s2")]
    assert mine == alone.log
    # and the streams differ between links
    other = [r.delays for r in busy.log if (r.sender, r.receiver) == ("s2", "s1")]
    assert other != [r.delays for r in mine]


def _arrivals(reorder: float, seed: int = 5) -> list[float]:
    inj = _injector(LinkFaults(delay=Constant(0.05), reorder=reorder,
                               reorder_delay=Uniform(0.0, 2 * INTERVAL)), seed)
    sent = [i * INTERVAL for i in range(2000)]
    return [t + inj.decide("s1", "s2", t, i)[0] for i, t in enumerate(sent)]


def test_reorder_reorders() -> None:
    arrivals = _arrivals(1.0)
    overtaken = sum(b < a for a, b in zip(arrivals, arrivals[1:], strict=False))
    # a pair swaps when e_i - e_{i+1} > interval: probability 1/8 for extras uniform in [0, 2)
    assert _within(overtaken / 1999, 1 / 8, math.sqrt(7 / 64), 1999)
    assert all(b > a for a, b in zip(_arrivals(0.0), _arrivals(0.0)[1:], strict=False))


def test_reorder_rate_and_log() -> None:
    inj = _injector(LinkFaults(reorder=0.25, reorder_delay=Constant(0.3)))
    out = _run(inj)
    held = sum(d == [0.3] for d in out)
    assert inj.counts()["reorder"] == held
    assert _within(held / N, 0.25, math.sqrt(0.25 * 0.75), N)
    assert all(r.reordered == (r.action == "reorder") for r in inj.log)


def test_counts_and_csv_log(tmp_path) -> None:
    inj = _injector(LinkFaults(delay=Uniform(0.0, 0.05), loss=0.2, duplicate=0.2, reorder=0.2,
                               reorder_delay=Constant(0.2), partitions=((5.0, 6.0),)))
    _run(inj, n=1000)
    counts = inj.counts()
    assert list(counts) == list(ACTIONS)
    assert sum(counts.values()) == 1000 and all(counts[a] > 0 for a in ACTIONS)
    path = tmp_path / "faults.csv"
    inj.write_log(path)
    lines = path.read_text(encoding="utf-8").splitlines()
    assert lines[0] == "t,sender,receiver,msg_id,action,reordered,delays"
    assert len(lines) == 1 + len(inj.log)
    with open(path, newline="", encoding="utf-8") as f:
        rows = list(csv.DictReader(f))
    for row, rec in zip(rows, inj.log, strict=True):
        assert float(row["t"]) == rec.t and row["msg_id"] == rec.msg_id
        assert row["action"] == rec.action and bool(int(row["reordered"])) == rec.reordered
        assert tuple(float(d) for d in row["delays"].split(";") if d) == rec.delays


def test_link_delay_and_deliveries_for_the_twin() -> None:
    inj = _injector(LinkFaults(delay=OneStep(INTERVAL), duplicate=1.0))
    msg = SimpleNamespace(sender="s1", k=3, round=0, send_time=0.3)
    assert inj.deliveries("s1", "s2", 0.3, msg) == [INTERVAL, INTERVAL]
    link_delay = inj.as_link_delay()
    assert link_delay("s1", "s3", msg) == INTERVAL  # one copy through the single-delay API
    assert [(r.receiver, r.msg_id, r.t, r.action) for r in inj.log] == [
        ("s2", "s1:k3:r0", 0.3, "duplicate"), ("s3", "s1:k3:r0", 0.3, "duplicate")]
    lossy = _injector(LinkFaults(loss=1.0)).as_link_delay(msg_id_fn=lambda m: m.k)
    assert lossy("s1", "s2", msg) is None


def test_twin_runs_with_the_injector() -> None:
    from sensornet.sim.run.twin import run_twin
    from sensornet.sim.scenario import load_scenario

    scn = load_scenario("seed000", overrides={"birth.model": "truth"})
    scn = dataclasses.replace(scn, num_scans=8)
    interval = scn.scan_period / scn.network.speed
    plan = parse_faults({"default": {"delay": "short", "loss": 0.2}}, interval,
                        scn.sensor_names)
    inj = FaultInjector(plan, seed=0)
    result = run_twin(scn, delay=inj.as_link_delay())
    assert set(result.tracks) == set(scn.sensor_names)
    assert inj.log and {r.sender for r in inj.log} == set(scn.sensor_names)
    assert all(r.delays == () or 0.0 <= r.delays[0] < interval for r in inj.log)


def test_hold_queue_releases_in_delivery_order() -> None:
    inj = _injector(LinkFaults(delay=Uniform(0.0, 0.3), duplicate=0.3))
    held = HoldQueue()
    assert held.next_due() is None and held.pop_due(1e9) == []
    expected = []
    for i in range(200):
        t = i * INTERVAL
        for d in inj.decide("s1", "s2", t, i):
            held.push(t + d, (i, t + d))
            expected.append((t + d, i))
    assert len(held) == len(expected)
    released = []
    now = 0.0
    while len(held):
        assert held.next_due() is not None
        for i, due in held.pop_due(now):
            assert due <= now
            released.append((due, i))
        now += 0.05
    assert released == sorted(expected)


# -- plans from tables -------------------------------------------------------------------------

def test_parse_faults_example() -> None:
    spec = {"default": {"delay": {"kind": "scans", "low": 0, "high": 3}, "reorder": 1.0,
                        "loss": 0.0},
            "links": [{"from": "s1", "to": "s2", "loss": 0.3}],
            "peers": {"s3": {"partitions": [[10.0, 20.0]]}}}
    plan = parse_faults(spec, INTERVAL, ["s1", "s2", "s3"])
    scans = Scans(0, 3, INTERVAL)
    assert plan.default == LinkFaults(delay=scans, reorder=1.0,
                                      reorder_delay=Uniform(0.0, 2 * INTERVAL))
    assert plan.for_link("s1", "s2") == dataclasses.replace(plan.default, loss=0.3)
    assert plan.for_link("s2", "s1") == plan.default
    for s, r in [("s1", "s3"), ("s3", "s1"), ("s2", "s3"), ("s3", "s2")]:
        assert plan.for_link(s, r).partitions == ((10.0, 20.0),)
        assert plan.for_link(s, r).delay == scans
    assert plan.for_link("s1", "s2").partitions == ()
    assert parse_faults({}, INTERVAL, PEERS) == FaultPlan(
        default=LinkFaults(reorder_delay=Uniform(0.0, 2 * INTERVAL)), interval=INTERVAL)
    assert plan.interval == INTERVAL
    hash(plan)  # frozen all the way down: a Scenario holding it stays hashable


def test_parse_faults_precedence() -> None:
    """default < sender's peer entry < receiver's peer entry < link entry; partitions join."""
    spec = {"default": {"loss": 0.1, "partitions": [[100.0, 110.0]]},
            "peers": {"s1": {"loss": 0.2, "partitions": [[10.0, 20.0]]},
                      "s2": {"loss": 0.25, "duplicate": 0.5, "partitions": [[30.0, 40.0]]}},
            "links": [{"from": "s1", "to": "s2", "loss": 0.3}]}
    plan = parse_faults(spec, INTERVAL, PEERS)

    def loss(s: str, r: str) -> float:
        return plan.for_link(s, r).loss

    assert loss("s1", "s2") == 0.3  # link entry
    assert loss("s2", "s1") == 0.2  # both ends set it: the receiver's entry wins
    assert loss("s1", "s3") == 0.2 and loss("s3", "s1") == 0.2  # out of / into s1
    assert loss("s3", "s2") == 0.25 and loss("s2", "s4") == 0.25
    assert loss("s3", "s4") == 0.1 and loss("s4", "s3") == 0.1  # default
    assert plan.for_link("s1", "s2").duplicate == 0.5  # not set by the link: from peers.s2
    assert plan.for_link("s1", "s2").partitions == ((10.0, 20.0), (30.0, 40.0), (100.0, 110.0))
    assert plan.for_link("s1", "s3").partitions == ((10.0, 20.0), (100.0, 110.0))
    assert plan.for_link("s3", "s4").partitions == ((100.0, 110.0),)


def test_layered_plan_in_code() -> None:
    """The same layering without a table: typed layers straight into the plan."""
    plan = FaultPlan.layered(PEERS, INTERVAL, LinkLayer(loss=0.1),
                             peers={"s2": LinkLayer(loss=0.25)},
                             links={("s1", "s2"): LinkLayer(loss=0.3)})
    assert plan == parse_faults({"default": {"loss": 0.1}, "peers": {"s2": {"loss": 0.25}},
                                 "links": [{"from": "s1", "to": "s2", "loss": 0.3}]},
                                INTERVAL, PEERS)
    assert FaultPlan(links={("s2", "s1"): LinkFaults(loss=0.5)}) == FaultPlan(
        links=((("s2", "s1"), LinkFaults(loss=0.5)),))


@pytest.mark.parametrize("spec, culprit", [
    ({"nodes": {}}, "'faults.nodes'"),
    ({"default": {"lost": 0.1}}, "'faults.default.lost' (did you mean 'faults.default.loss'?)"),
    ({"default": {"loss": 1.5}}, "'faults.default.loss'"),
    ({"default": {"loss": "high"}}, "'faults.default.loss'"),
    ({"default": {"loss": True}}, "'faults.default.loss'"),
    ({"default": {"delay": {"kind": "scans", "low": 0}}}, "'faults.default.delay.high'"),
    ({"default": {"delay": {"kind": "scans", "low": 0, "high": 3, "hi": 1}}},
     "'faults.default.delay.hi'"),
    ({"default": {"delay": {"kind": "gauss"}}}, "'faults.default.delay.kind'"),
    ({"default": {"reorder_delay": -1.0}}, "'faults.default.reorder_delay'"),
    ({"default": {"reorder": 0.5, "reorder_delay": 0.0}}, "'faults.default.reorder_delay'"),
    ({"default": {"reorder_delay": 0.0}, "links": [{"from": "s1", "to": "s2", "reorder": 0.5}]},
     "'faults.default.reorder_delay'"),
    ({"default": 0.1}, "'faults.default'"),
    ({"links": [{"from": "s1", "to": "s2", "los": 0.3}]}, "'faults.links[0].los'"),
    ({"links": [{"from": "s1", "to": "s9"}]}, "'faults.links[0].to'"),
    ({"links": [{"to": "s2"}]}, "'faults.links[0].from'"),
    ({"links": [{"from": "s1", "to": "s1"}]}, "'faults.links[0].to'"),
    ({"links": [{"from": "s1", "to": "s2"}, {"from": "s1", "to": "s2", "loss": 0.1}]},
     "'faults.links[1]'"),
    ({"links": {"from": "s1"}}, "'faults.links'"),
    ({"peers": {"s9": {}}}, "'faults.peers.s9'"),
    ({"peers": {"s3": {"loss": -0.1}}}, "'faults.peers.s3.loss'"),
    ({"peers": {"s3": {"partitions": [[20.0, 10.0]]}}}, "'faults.peers.s3.partitions[0]'"),
    ({"peers": {"s3": {"partitions": [[-1.0, 10.0]]}}}, "'faults.peers.s3.partitions[0]'"),
    ({"peers": {"s3": {"partitions": [[1.0]]}}}, "'faults.peers.s3.partitions[0]'"),
    ({"peers": {"s3": {"partitions": [10.0, 20.0]}}}, "'faults.peers.s3.partitions[0]'"),
    ({"peers": {"s3": {"partitions": "always"}}}, "'faults.peers.s3.partitions'"),
])
def test_parse_faults_rejects(spec, culprit) -> None:
    with pytest.raises(ScenarioError) as err:
        parse_faults(spec, INTERVAL, PEERS)
    message = str(err.value)
    assert culprit in message and "\n" not in message, message
    assert message.startswith("[faults]: "), message
