"""peers.labelling_batch.label_fused_many: every problem's labels, pairs, fresh count and
copies equal its own peers.labelling.label_fused's to the bit, on random groups of problems
(conflicts, stamps to move, holder masks, AA copies, empty and unlabelled inputs)."""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
import pytest
from sensornet.peers.batching import FusionBatch
from sensornet.peers.core import Publish
from sensornet.peers.label_support import LabelSupport
from sensornet.peers.labelling import LABEL_GATE, FusedLabels
from sensornet.peers.labelling_batch import LabelProblem, label_fused_many
from sensornet.sim.run import twin
from sensornet.sim.run.peers import make_peer
from sensornet.sim.scenario import load_scenario
from sensornet.tracking.label_matching import RELEASE
from sensornet.tracking.mixture import GaussianMixture

from benchmarks.bench_network import scenario_text
from tests.test_label_fused_batched import _case


def _problem(rng) -> LabelProblem:
    fused, inputs = _case(rng)
    k = int(rng.integers(0, 4))  # the cases' labels are of scans 0-3: stamps of k do occur
    bump = None
    own = inputs[0][1]
    if own is not None and len(own) and rng.random() < 0.7:
        bump = np.asarray(own)[np.asarray(own)[:, 1] == k]
    support = None
    if rng.random() < 0.6:
        support = LabelSupport(1 << int(rng.integers(0, 5)))
        for _, lab in inputs:
            if lab is not None and len(lab):
                support.add(lab, rng.integers(1, 64, len(lab)))
    return LabelProblem(fused, inputs, int(rng.integers(0, 5)), k, int(rng.integers(0, 9)),
                        float(rng.choice([9.0, LABEL_GATE, 100.0])), bump,
                        bool(rng.random() < 0.5), support)


def _same(got: FusedLabels, ref: FusedLabels) -> None:
    np.testing.assert_array_equal(got.labels, ref.labels)
    for a, b in ((got.own.own, ref.own.own), (got.own.nbr, ref.own.nbr),
                 (got.own.cost, ref.own.cost)):
        assert a.dtype == b.dtype and a.shape == b.shape
        np.testing.assert_array_equal(a, b)
    assert got.fresh == ref.fresh
    assert (got.copies is None) == (ref.copies is None)
    if ref.copies is not None:
        np.testing.assert_array_equal(got.copies, ref.copies)


def test_label_fused_many_equals_each_problems_own_call_to_the_bit():
    rng = np.random.default_rng(3302)
    moved = released = copied = held = groups = 0
    for _ in range(150):
        problems = [_problem(rng) for _ in range(int(rng.integers(1, 9)))]
        got = label_fused_many(problems)
        assert len(got) == len(problems)
        for pr, g in zip(problems, got, strict=True):
            ref = pr.alone()
            _same(g, ref)
            released += int((ref.own.cost == RELEASE).sum())
            copied += 0 if ref.copies is None else int(ref.copies.sum())
            if pr.bump is not None and len(pr.bump):  # rows a stamp moved a scan later
                plain = LabelProblem(pr.fused, pr.inputs, pr.origin, pr.k, pr.fresh_start,
                                     pr.gate, None, pr.copies, pr.support).alone()
                moved += int((ref.labels != plain.labels).any(axis=1).sum())
            if pr.support is not None:
                held += len(pr.support.keys)
        groups += len(problems) > 1
    # the cases exercise every rule, not only the plain matching
    assert moved > 10 and released > 20 and copied > 10 and held > 100 and groups > 100


def test_empty_fused_densities_and_no_labelled_inputs():
    rng = np.random.default_rng(5)
    empty = GaussianMixture.empty(4)
    fused, inputs = _case(rng)
    while not len(fused):
        fused, inputs = _case(rng)
    problems = [LabelProblem(empty, inputs, 1, 3),
                LabelProblem(fused, [(m, None) for m, _ in inputs], 2, 3, 5),
                LabelProblem(fused, [], 3, 4, copies=True)]
    for pr, g in zip(problems, label_fused_many(problems), strict=True):
        _same(g, pr.alone())
    assert label_fused_many([]) == []


@pytest.mark.parametrize("kind", ["lmb", "gmphd"])
def test_a_twins_host_labelling_together_publishes_the_same_bytes(kind, monkeypatch):
    """A twin of 8 labelled peers as one host, its fused densities labelled one by one and
    together: every message each peer publishes (estimates with their labels, tracks with
    ids, existence and status) is the same bytes."""
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "twin.toml"
        path.write_text(scenario_text(8, 4, 25, rounds=2, speed=10.0))
        scn = load_scenario(str(path), overrides={"network.filter": kind})
    sent: dict[bool, list] = {}
    made: list[FusionBatch] = []
    for together in (False, True):
        peers = {q: make_peer(scn, q, 0, network="twin") for q in scn.sensor_names}
        assert all(c.consensus.labelled for c in peers.values())
        out: list = []
        sent[together] = out
        carry = twin._Clock.carry_out

        def record(self, t, sender, outputs, carry=carry, out=out):
            out.extend((sender, o.channel, o.payload) for o in outputs
                       if isinstance(o, Publish))
            return carry(self, t, sender, outputs)

        def batch(together=together):
            made.append(FusionBatch(label_together=together))
            return made[-1]

        monkeypatch.setattr(twin._Clock, "carry_out", record)
        monkeypatch.setattr(twin, "FusionBatch", batch)
        twin.run_twin(scn, 0, peers=peers, batch=True)
        monkeypatch.undo()
    assert made[0].labelled == 0 and made[1].labelled > 8 * 20  # most rounds labelled together
    assert sum(ch == "tracks" for _, ch, _ in sent[True]) >= 8 * 20
    assert sent[False] == sent[True]
