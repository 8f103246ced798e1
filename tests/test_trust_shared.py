"""A host's stacked trust requests over mixtures its peers share give each request's own numbers.

A neighbour's estimate is one object at every co-hosted receiver (``peers.host_parts.
SharedDecode``), so a host's overlaps, offsets and masses requests hold the same mixtures many
times; ``peers.trust_batch`` computes each object (and each two objects' overlap block) once.
Held to the one-at-a-time functions to the bit, with shared, empty, single-component, NaN and
``-0.0`` inputs, and a twin of a host whose peers share their decoded estimates (honest, and
with a *biased*, *empty* and *inflated* liar) tests its rounds together with the fused states,
trust records and summaries of its peers testing alone.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
import pytest
from sensornet.peers.batching import FusionBatch
from sensornet.peers.host import SharedDecode
from sensornet.peers.trust_batch import TOGETHER, shared_log_overlaps
from sensornet.peers.trust_checks import ALONE
from sensornet.sim.run.peers import make_peer
from sensornet.sim.scenario import load_scenario
from sensornet.tracking.divergence import log_overlaps
from sensornet.tracking.mixture import GaussianMixture

from benchmarks.bench_network import scenario_text
from tests.trust_twin import run_with_batch


def _mixture(rng: np.random.Generator, size: int, d: int = 4, side: float = 400.0,
             odd: bool = True) -> GaussianMixture:
    """``size`` components near each other (gates pair some); ``odd``: some weights NaN,
    ``-0.0``, ``0.0`` or exactly 0.5 and some mean entries ``-0.0`` or NaN."""
    if size == 0:
        return GaussianMixture.empty(d)
    A = rng.normal(0, 1, (size, d, d)) * rng.uniform(1, 40, (size, 1, 1))
    w = rng.uniform(0.05, 1.2, size)
    m = rng.uniform(-side / 2, side / 2, (size, d))
    if odd:
        r = rng.random(size)
        w[r < 0.04] = np.nan
        w[(r >= 0.04) & (r < 0.08)] = -0.0
        w[(r >= 0.08) & (r < 0.1)] = 0.0
        w[(r >= 0.1) & (r < 0.14)] = 0.5
        m[rng.random((size, d)) < 0.04] = -0.0
        if rng.random() < 0.03:
            m[0, 0] = np.nan
    return GaussianMixture(w, m, A @ A.transpose(0, 2, 1) + np.eye(d))


def _shared_groups(rng: np.random.Generator) -> list[list[GaussianMixture]]:
    """Requests' mixture lists as a host's: own first (its own object), then neighbours drawn
    from a pool of objects shared between requests (some twice in one list), some empty,
    some lists of single components, now and then one of another dimension."""
    pool = [_mixture(rng, int(rng.integers(0, 9))) for _ in range(10)]
    groups = []
    for _ in range(int(rng.integers(1, 14))):
        mixes = [_mixture(rng, int(rng.integers(0, 5)))]
        mixes += [pool[i] for i in rng.integers(0, len(pool), int(rng.integers(0, 6)))]
        if rng.random() < 0.1:
            mixes = [_mixture(rng, int(rng.integers(0, 2))) for _ in range(4)]
        if rng.random() < 0.04:
            mixes = [_mixture(rng, 2, d=2), _mixture(rng, 1, d=2)]
        groups.append(mixes)
    return groups


def _same(a, b) -> bool:
    """Equal to the bit: values, NaN where NaN, the sign of every zero."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    return (a.shape == b.shape and np.array_equal(a, b, equal_nan=True)
            and np.array_equal(np.signbit(a), np.signbit(b)))


def test_shared_log_overlaps_are_each_groups_log_overlaps_to_the_bit():
    rng = np.random.default_rng(5)
    checked = 0
    with np.errstate(all="ignore"):
        for _ in range(300):
            groups = _shared_groups(rng)
            for mixes, L in zip(groups, shared_log_overlaps(groups), strict=True):
                assert _same(L, log_overlaps(mixes))
                checked += 1
    assert checked > 1000


@pytest.mark.parametrize("op", ["offsets", "masses", "overlaps", "unmatched"])
def test_stacked_requests_over_shared_mixtures_are_each_ones_own(op):
    """The offsets (each request's reference its own object, the neighbours shared), the
    masses, overlaps and unmatched-weights requests of a host, against each request's own
    computation."""
    rng = np.random.default_rng(len(op) + 20)
    with np.errstate(all="ignore"):
        for _ in range(200):
            groups = [g for g in _shared_groups(rng) if g[0].means.shape[1] == 4]
            if op == "offsets":
                chi2 = [None, 13.8][int(rng.integers(0, 2))]
                args = [(g[0], g[1:], [0, 2], 0.5, 60.0, chi2) for g in groups]
            elif op == "masses":
                args = [(g, float(rng.choice([0.3, 0.5]))) for g in groups]
            elif op == "unmatched":
                chi2 = [None, 13.8][int(rng.integers(0, 2))]
                args = [(g, [0, 2], 0.5, 50.0, chi2) for g in groups]
            else:
                args = [(g,) for g in groups]
            if len(args) < 2:
                continue
            for a, got in zip(args, TOGETHER[op](args), strict=True):
                want = ALONE[op](*a)
                if op == "offsets":
                    assert len(got) == len(want)
                    for (I, y), (I0, y0) in zip(got, want, strict=True):
                        assert _same(I, I0) and _same(y, y0)
                elif op == "masses":
                    assert _same(got[0], want[0]) and _same(got[1], want[1])
                    assert all(type(x) is float for x in got[0] + got[1])
                else:
                    assert _same(got, want)


def _twin(lie: str | None, together: bool, n: int = 10, scans: int = 14):
    """A twin of ``n`` GM-PHD peers sharing their decoded estimates as one host's do, its
    rounds tested together or each alone: the fused states, every peer's trust records and
    summary."""
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "twin.toml"
        path.write_text(scenario_text(n, 4, scans, rounds=2, speed=10.0))
        over = {"network.filter": "gmphd", "fusion.trust": True}
        if lie:
            over["fusion.lie"] = lie
        scn = load_scenario(str(path), overrides=over)
    peers = {q: make_peer(scn, q, 0, network="twin") for q in scn.sensor_names}
    shared = SharedDecode()
    records: dict[str, list] = {q: [] for q in peers}
    for q, core in peers.items():
        core.decode = shared
        tr = core.consensus.trust
        drain = tr.drain_records

        def kept(drain=drain, q=q):
            out = drain()
            records[q].extend(out)
            return out
        tr.drain_records = kept
    res, summaries = run_with_batch(scn, peers, lambda: FusionBatch(trust_together=together))
    return res.tracks, records, summaries


@pytest.mark.parametrize("lie", [None, "p02:biased", "p03:empty", "p04:inflated"])
def test_a_host_sharing_estimates_tests_together_as_each_alone(lie):
    alone, together = _twin(lie, False), _twin(lie, True)
    for a, b in zip(alone, together, strict=True):
        assert a.keys() == b.keys()
    tracks_a, tracks_b = alone[0], together[0]
    for q in tracks_a:
        assert tracks_a[q].keys() == tracks_b[q].keys()
        for k in tracks_a[q]:
            assert np.array_equal(tracks_a[q][k], tracks_b[q][k])
    assert alone[1] == together[1]  # every round's statistic, score, weight and state
    assert sum(len(v) for v in together[1].values()) > 0
    assert alone[2] == together[2]
    if lie:  # the liar's neighbours noticed it
        name = lie.split(":")[0]
        assert any(v["neighbours"].get(name, {}).get("state") != "trusted"
                   or v["changes"] for v in together[2].values())
