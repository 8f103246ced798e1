"""Stacked fusions (a peer host's batch, peers.batching) against one fusion at a time:
the same fused mixtures on random inputs, the same consensus outputs, the same twin run."""

from __future__ import annotations

import numpy as np
import pytest
from sensornet.peers.batching import FusionBatch
from sensornet.peers.consensus import Consensus, ConsensusOptions
from sensornet.peers.contracts import LocalOutput
from sensornet.peers.fusers import HybridFuser
from sensornet.protocol.messages import Estimate, Tracks
from sensornet.sim.run.twin import run_twin
from sensornet.sim.scenario import load_scenario
from sensornet.sim.world.graphs import network_scenario
from sensornet.tracking.fusion_batch import hybrid_fuse_many
from sensornet.tracking.fusion_rules import hybrid_fuse
from sensornet.tracking.mixture import GaussianMixture
from sensornet.tracking.reduction import Reducer


def _random_spd(rng, n: int) -> np.ndarray:
    A = rng.normal(0, 1, (n, 4, 4))
    return A @ A.swapaxes(1, 2) * rng.uniform(5, 60, (n, 1, 1)) + 4 * np.eye(4)


def _problem(rng, centres: np.ndarray):
    """A fusion of 1-6 inputs, each with 0-6 components around the targets ``centres``
    (several of one input near one target: cells of more than one component)."""
    n_in = int(rng.integers(1, 7))
    dens = []
    for _ in range(n_in):
        k = int(rng.integers(0, 7))
        at = centres[rng.integers(0, len(centres), k)]
        means = at + rng.normal(0, 4, (k, 4))
        covs = _random_spd(rng, k)
        if k and rng.random() < 0.3:  # round-off asymmetry, as a decoded covariance may have
            covs[0, 0, 1] += 1e-12 * covs[0, 0, 1]
        w = rng.uniform(0.0, 1.2, k)
        if k and rng.random() < 0.2:
            w[0] = 0.0
        dens.append(GaussianMixture(w, means, covs))
    raw = rng.uniform(0.1, 1, n_in)
    if n_in > 1 and rng.random() < 0.2:
        raw[-1] = 0.0  # an input at weight 0
    return dens, list(raw / raw.sum())


def _assert_same(a: GaussianMixture, b: GaussianMixture) -> None:
    assert len(a) == len(b)
    np.testing.assert_allclose(b.weights, a.weights, rtol=1e-12, atol=1e-300)
    np.testing.assert_allclose(b.means, a.means, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(b.covs, a.covs, rtol=1e-12, atol=1e-9)


@pytest.mark.parametrize("reducer", [
    Reducer(), Reducer(merge_rule="weighted", merge_threshold=2.0),
    Reducer(merge_threshold=50.0, max_components=2), Reducer(refit=True), None])
def test_stacked_hybrid_fusions_equal_one_at_a_time(reducer):
    rng = np.random.default_rng(23)
    centres = rng.uniform(-500, 500, (4, 4))
    problems = [_problem(rng, centres) for _ in range(60)]
    problems.append(([GaussianMixture.empty(4)] * 3, [0.5, 0.25, 0.25]))  # nothing to fuse
    big = GaussianMixture(rng.uniform(0.1, 1, 40), centres[rng.integers(0, 4, 40)]
                          + rng.normal(0, 4, (40, 4)), _random_spd(rng, 40))
    problems.append(([big, big], [0.5, 0.5]))  # 80 > 48 components: the per-problem path
    one = [hybrid_fuse(D, w, reducer) for D, w in problems]
    many = hybrid_fuse_many(problems, reducer)
    for a, b in zip(one, many, strict=True):
        _assert_same(a, b)
    unreduced = [hybrid_fuse(D, w) for D, w in problems]
    union = sum(len(D) for Ds, _ in problems for D in Ds)
    assert sum(len(u) for u in unreduced) < union  # components of one target grouped
    if reducer is not None and not reducer.refit:  # the reducer merged some fused outputs
        assert any(len(a) < len(u) for a, u in zip(one, unreduced, strict=True))


def test_stacked_fusions_raise_on_bad_weights_as_one_does():
    mix = GaussianMixture(np.ones(1), np.zeros((1, 4)), np.eye(4)[None])
    with pytest.raises(ValueError, match="sum to 1"):
        hybrid_fuse_many([([mix, mix], [0.5, 0.5]), ([mix, mix], [0.7, 0.7])], Reducer())


class _Echo:
    """A local estimator whose density is given per scan (``self.next``)."""

    dim, kinds, position_index = 4, ("posterior",), (0, 2)

    def __init__(self) -> None:
        self.next = GaussianMixture.empty(4)

    def step(self, steps, z):
        return LocalOutput(self.next, {"posterior": self.next})

    def predict(self, mix, steps):
        return mix

    def extract(self, mix):
        return mix.means

    def adopt(self, fused):
        pass


def _consensus(batch: FusionBatch | None) -> tuple[Consensus, _Echo]:
    est = _Echo()
    opts = ConsensusOptions("a", ("b", "c"), (("a", 2), ("b", 2), ("c", 2)), rounds=2)
    c = Consensus(opts, est, HybridFuser(Reducer()))
    c.batch = batch
    return c, est


def _same_messages(xs: list, ys: list) -> None:
    assert [(type(x).__name__, x.k, getattr(x, "round", None)) for x in xs] == [
        (type(y).__name__, y.k, getattr(y, "round", None)) for y in ys]
    for x, y in zip(xs, ys, strict=True):
        if isinstance(x, Estimate):
            _assert_same(x.mixture, y.mixture)
        elif isinstance(x, Tracks):
            np.testing.assert_allclose(y.states, x.states, rtol=1e-12)


def test_consensus_through_a_batch_gives_what_it_gives_alone():
    """Peer a with neighbours b, c, two rounds, alone and through a batch shared with a
    second peer: the rounds a batch completes (normally, forced by the deadline, or settled
    at once by the next scan) give the same messages and counts as fusing each at once."""
    rng = np.random.default_rng(5)
    centres = rng.uniform(-500, 500, (3, 4))

    def density():
        return _problem(rng, centres)[0][0]

    batch = FusionBatch()
    alone, est_a = _consensus(None)
    batched, est_b = _consensus(batch)
    other, est_o = _consensus(batch)  # a co-hosted peer: its rounds stacked with a's
    got_alone: list = []
    got_batched: list = []

    def both(f) -> None:
        got_alone.extend(f(alone))
        got_batched.extend(f(batched))

    def flush() -> None:
        for c in batch.run(0.0):
            if c is batched:
                got_batched.extend(c.take_completed())
            else:
                c.take_completed()

    for k in (1, 2, 3):
        est_a.next = est_b.next = est_o.next = density()
        both(lambda c, k=k: c.on_scan(k, np.zeros((0, 2)), 1, 0.0))
        other.on_scan(k, np.zeros((0, 2)), 1, 0.0)
        for s in ("b", "c"):
            e = Estimate(s, k, density())
            both(lambda c, e=e: c.on_estimate(e, 0.0))
            other.on_estimate(e, 0.0)
        assert batched.busy() and len(batch.jobs) == 2  # a's round 1 and the other peer's
        flush()
        assert batch.stacked >= 2  # fused together
        if k == 1:  # round 2 complete: normal path
            for s in ("b", "c"):
                e = Estimate(s, k, density(), round=1)
                both(lambda c, e=e: c.on_estimate(e, 0.0))
            flush()
        elif k == 2:  # the deadline passes with only b's round-1 input: forced
            e = Estimate("b", k, density(), round=1)
            both(lambda c, e=e: c.on_estimate(e, 0.0))
            both(lambda c, k=k: c.on_deadline(k, 0.0))
            flush()
        # k == 3: the run ends while round 2 waits for inputs (finish, below)
        _same_messages(got_alone, got_batched)
        assert not batched.busy() or k == 3
    # a round waiting in the batch when the next scan comes: settled at once, then skipped
    est_a.next = est_b.next = density()
    both(lambda c: c.finish(0.0))
    both(lambda c: c.on_scan(4, np.zeros((0, 2)), 1, 0.0))
    for s in ("b", "c"):
        e = Estimate(s, 4, density())
        both(lambda c, e=e: c.on_estimate(e, 0.0))
    assert batched.busy() and batched._scan.pending is not None and len(batch.jobs) == 1
    both(lambda c: c.on_scan(5, np.zeros((0, 2)), 1, 0.0))
    assert batch.run(0.0) == [] and batch.jobs == []  # settled by the scan: skipped
    _same_messages(got_alone, got_batched)
    assert alone.stats == batched.stats
    assert alone.stats.deadline_fusions == 3  # k = 2 (deadline), 3 (finish), 4 (next scan)


def test_the_twin_with_batched_fusions_is_the_twin(tmp_path):
    """Eight peers of degree 4, two rounds, delayed and lost links (fusions at the deadline
    too): stacking each instant's fusions and local GM-PHD steps (as a host does) changes no
    track and no count."""
    path = tmp_path / "net8.toml"
    path.write_text(network_scenario(8, 4, 12, rounds=2, speed=10.0))
    scn = load_scenario(str(path), overrides={
        "faults.default.delay": {"kind": "uniform", "low": 0.0, "high": 0.12},
        "faults.default.loss": 0.1})
    one = run_twin(scn, 0)
    many = run_twin(scn, 0, batch=True)
    batch = many.peers["p00"].consensus.batch
    assert batch is not None and batch.stacked > 0
    hits = [many.peers[n].consensus.estimator.prepared_hits for n in scn.sensor_names]
    assert min(hits) >= 10  # 12 scans: every one after the first from the stacked steps
    assert all(one.peers[n].consensus.estimator.prepared_hits == 0 for n in scn.sensor_names)
    for name in scn.sensor_names:
        a, b = one.summary(name)["stats"], many.summary(name)["stats"]
        assert a == b, name
        assert one.tracks[name].keys() == many.tracks[name].keys()
        for k, states in one.tracks[name].items():
            np.testing.assert_allclose(many.tracks[name][k], states, rtol=1e-12, atol=1e-9)
    assert sum(one.summary(n)["stats"]["deadline_fusions"] for n in scn.sensor_names) > 0
