"""peers.tracks_batch.masses_many: every peer's input masses and row supports equal its own
tracking.support.input_mass / input_support to the bit, on random groups of problems (rows
near and far, empty inputs, ties, stacks beyond 200 components: the closed-form inverse);
rows_support answers input_support for extracted rows; a twin host of 8 LMB (or GM-PHD) peers
publishes the same bytes with the masses computed together or each on its own."""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
import pytest
from sensornet.peers.batching import FusionBatch
from sensornet.peers.core import Publish
from sensornet.peers.tracks_batch import masses_many, rows_support
from sensornet.sim.run import twin
from sensornet.sim.run.peers import make_peer
from sensornet.sim.scenario import load_scenario
from sensornet.tracking.mixture import GaussianMixture
from sensornet.tracking.support import input_mass, input_support

from benchmarks.bench_network import scenario_text


def _mix(rng, centres, count, spread):
    if count == 0:
        return GaussianMixture.empty(4)
    pick = rng.integers(0, len(centres), count)
    A = rng.normal(size=(count, 4, 4))
    covs = A @ A.swapaxes(1, 2) * rng.uniform(1, 80) + np.eye(4) * rng.uniform(1, 50)
    return GaussianMixture(rng.uniform(0.01, 1.0, count),
                           centres[pick] + rng.normal(0, spread, (count, 4)), covs)


def _problem(rng):
    centres = rng.uniform(-500, 500, (int(rng.integers(1, 8)), 4))
    spread = rng.uniform(1, 30)
    n = int(rng.integers(1, 14))
    X = centres[rng.integers(0, len(centres), n)] + rng.normal(0, spread, (n, 4))
    if n > 1 and rng.random() < 0.3:
        X[1] = X[0]  # two equal rows: a tie for the nearest row
    big = rng.random() < 0.05  # a stack beyond 200 components: the closed-form inverse
    inputs = [_mix(rng, centres, int(rng.integers(0, 60 if big else 9)), spread)
              for _ in range(int(rng.integers(1, 7)))]
    return X, inputs


def test_masses_many_equal_each_problems_own_to_the_bit():
    rng = np.random.default_rng(3303)
    taken = held = big = 0
    for _ in range(120):
        problems = [_problem(rng) for _ in range(int(rng.integers(1, 9)))]
        for (X, inputs), got in zip(problems, masses_many(problems), strict=True):
            if not any(len(D) for D in inputs):
                assert got is None
                continue
            assert got is not None
            taken += 1
            big += sum(len(D) for D in inputs) > 200
            mass, support = got
            want = input_mass(X, inputs)
            assert mass.shape == want.shape and mass.tobytes() == want.tobytes()
            np.testing.assert_array_equal(support, input_support(X, inputs))
            held += int((support > 1).sum())
            rows = rng.permutation(len(X))[:int(rng.integers(0, len(X) + 1))]
            np.testing.assert_array_equal(rows_support(support, X, X[rows]),
                                          input_support(X[rows], inputs))
    assert taken > 300 and held > 300 and big >= 2
    X, inputs = _problem(np.random.default_rng(1))
    assert rows_support(np.zeros(len(X), np.int64), X, X[:1] + 1.0) is None  # not a row


def test_problems_it_cannot_take_are_left_to_their_own():
    rng = np.random.default_rng(4)
    X, inputs = _problem(rng)
    bad = [(X, []), (np.zeros((0, 4)), inputs), (X[:, :2], inputs), (X * np.nan, inputs)]
    assert masses_many(bad) == [None] * 4
    assert masses_many([]) == []


@pytest.mark.parametrize("kind, sets", [("lmb", {}), ("lmb", {"fusion.trust": False}),
                                        ("gmphd", {})])
def test_a_twins_host_computing_masses_together_publishes_the_same_bytes(kind, sets,
                                                                          monkeypatch):
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "twin.toml"
        path.write_text(scenario_text(8, 4, 25, rounds=2, speed=10.0))
        scn = load_scenario(str(path), overrides={"network.filter": kind, **sets})
    sent: dict[bool, list] = {}
    made: list[FusionBatch] = []
    for together in (False, True):
        peers = {q: make_peer(scn, q, 0, network="twin") for q in scn.sensor_names}
        out: list = []
        sent[together] = out
        carry = twin._Clock.carry_out

        def record(self, t, sender, outputs, carry=carry, out=out):
            out.extend((sender, o.channel, o.payload) for o in outputs
                       if isinstance(o, Publish))
            return carry(self, t, sender, outputs)

        def batch(together=together):
            made.append(FusionBatch(tracks_together=together))
            return made[-1]

        monkeypatch.setattr(twin._Clock, "carry_out", record)
        monkeypatch.setattr(twin, "FusionBatch", batch)
        twin.run_twin(scn, 0, peers=peers, batch=True)
        monkeypatch.undo()
    assert made[0].extracted == 0 and made[1].extracted > 8 * 15
    assert sum(ch == "tracks" for _, ch, _ in sent[True]) >= 8 * 20
    assert sent[False] == sent[True]
