"""A watched peer's map marks, cheaper to make and the same to see (issue 38): the heaviest
components' position marginals straight from the mixture (checked against a per-component
brute force), the fused ones sent as points like the local ones, drawn by the view as the
solid fused marks it drew from a 4-D mixture before."""

from __future__ import annotations

import numpy as np
import pytest
import rerun as rr
from sensornet.peers.core import Publish, Record
from sensornet.peers.observer import Observer, heaviest_marginals, pack_marginals
from sensornet.protocol.bundle import unpack_bundle
from sensornet.protocol.codec import decode, encode
from sensornet.protocol.messages import Telemetry, Tracks
from sensornet.sim.run.peers import make_peer
from sensornet.sim.scenario import load_scenario
from sensornet.tracking.mixture import GaussianMixture

from sensornet.view import Batcher, ViewState


class _Rec:
    """A recording stream that keeps what it is sent, by entity."""

    def __init__(self) -> None:
        self.calls: dict[str, list] = {}

    def send_columns(self, path, indexes, columns):
        self.calls[path] = [c.as_arrow_array().to_pylist() for c in columns]


def _brute(mix: GaussianMixture, n: int) -> np.ndarray:
    """Reference: component by component, heaviest first, the (px, py) block symmetrised,
    floored at 1e-9 of its trace, kept if its eigenvalues are positive; rows as packed."""
    i, j = (0, 3) if mix.dim == 6 else (0, 2)
    rows = []
    for c in sorted(range(len(mix)), key=lambda c: -mix.weights[c])[:n]:
        P = mix.covs[c][np.ix_([i, j], [i, j])]
        P = 0.5 * (P + P.T)
        P = P + 1e-9 * max(np.trace(P), 1e-9) * np.eye(2)
        if np.linalg.eigvalsh(P).min() <= 0:
            continue
        rows += [[mix.means[c, i], mix.means[c, j]], [P[0, 0], P[0, 1]],
                 [P[1, 1], mix.weights[c]]]
    return np.array(rows).reshape(-1, 2)


@pytest.mark.parametrize("dim", [4, 6])
def test_heaviest_marginals_match_a_per_component_brute_force(dim):
    """Random mixtures with asymmetric, indefinite and all-zero blocks, more components than
    shown and fewer: the same rows as the brute force, in the same order."""
    rng = np.random.default_rng(dim)
    for n_comp, shown in ((30, 8), (5, 64)):
        A = rng.normal(size=(n_comp, dim, dim))
        covs = A @ A.transpose(0, 2, 1) + rng.normal(scale=0.3, size=(n_comp, dim, dim))
        covs[0] = 0.0
        covs[1] = -np.eye(dim)
        mix = GaussianMixture.trusted(rng.permutation(n_comp) + 1.0,
                                      rng.normal(size=(n_comp, dim)) * 100, covs)
        got, want = heaviest_marginals(mix, shown), _brute(mix, shown)
        assert got.shape == want.shape and len(want) >= 3
        np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-300)


def _drawn(msg: Telemetry) -> dict:
    rec = _Rec()
    state = ViewState(Batcher(rr, rec), ["s1"])
    state.message(decode(encode(msg)))
    state.b.flush()
    return rec.calls


def test_the_fused_marks_as_points_are_drawn_as_the_mixture_was():
    """The fused estimate's marks sent as points (``fused/mixture``) draw the same means and
    solid ellipses on the same entities as the 4-D mixture sent before (float32 on the wire:
    to its precision), and nothing under a ``fused/mixture`` entity."""
    rng = np.random.default_rng(7)
    A = rng.normal(size=(6, 4, 4))
    mix = GaussianMixture.trusted(rng.uniform(0.2, 1.0, 6), rng.normal(size=(6, 4)) * 50,
                                  A @ A.transpose(0, 2, 1) + np.eye(4))
    pts = heaviest_marginals(mix, 64)
    o = np.argsort(-mix.weights)  # the peer sent its heaviest first
    before = _drawn(Telemetry("s1", 3, mixture=GaussianMixture.trusted(
        mix.weights[o], mix.means[o], mix.covs[o])))
    now = _drawn(Telemetry("s1", 3, points={"fused/mixture": pts}))
    assert "peers/s1/fused/mixture" not in now
    for path in ("peers/s1/fused/means", "peers/s1/fused/ellipses"):
        a, b = before[path], now[path]
        assert len(a) == len(b)
        for ca, cb in zip(a, b, strict=True):
            if isinstance(ca[0], list) and ca[0] and isinstance(ca[0][0], list):
                np.testing.assert_allclose(np.array(cb[0], float), np.array(ca[0], float),
                                           rtol=1e-4, atol=1e-3)
            elif isinstance(ca[0], list) and ca[0] and isinstance(ca[0][0], float):
                np.testing.assert_allclose(cb[0], ca[0], rtol=1e-4, atol=1e-3)
            else:  # colours, radii, ...: equal
                assert ca == cb


def test_a_watched_peers_report_carries_both_estimates_as_points():
    """A watched GM-PHD peer of seed 000: its scan's report has its local and fused marks as
    points (the heaviest components' marginals of the core's own mixtures), no 4-D mixture."""
    scn = load_scenario("seed000")
    core = make_peer(scn, scn.sensor_names[0], 0)
    sent: list[bytes] = []
    obs = Observer(core).attach(sent.append)
    assert obs.enabled
    mix = GaussianMixture.trusted(np.array([0.9, 0.4]), np.array([[1.0, 0, 2, 0], [5, 0, 6, 0]]),
                                  np.tile(np.eye(4), (2, 1, 1)))
    core.consensus.last_local = mix
    core.consensus.last_fused = mix
    obs.record(Record("local", 1, {"n_components": 2, "n_published": 2}))
    obs.record(Record("fusion", 1, {"n_fused": 2, "round": core.consensus.rounds}))
    obs.published(Publish("tracks", 1, b"", Tracks(core.name, 1, np.zeros((0, 4)))), 1.0)
    obs.flush(idle=True, force=True)
    reports = [m for m in map(decode, _entries(sent)) if isinstance(m, Telemetry)]
    assert len(reports) == 1
    msg = reports[0]
    assert msg.mixture is None
    for name in ("local/mixture", "fused/mixture"):
        np.testing.assert_allclose(msg.points[name], pack_marginals(mix), rtol=1e-6)


def _entries(puts: list[bytes]) -> list[bytes]:
    """The messages in a peer's puts on its report key (each a bundle)."""
    return [e for p in puts for _, e in unpack_bundle(p).entries]
