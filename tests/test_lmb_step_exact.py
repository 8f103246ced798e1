"""The LMB step made cheaper (issue 33, 50 labelled peers in real time) gives the same numbers
to the bit as the step it replaced (benchmarks/lmb_before.py, commit 211455b's code): whole
scan sequences with clutter, births (fixed, adaptive, shared labels) and scan gaps, the update
alone on the 200 random association cases, and the merge's two ways of finding pairs."""

from __future__ import annotations

import numpy as np
import pytest
from sensornet.tracking import lmb_association, lmb_sets
from sensornet.tracking.gmphd import SensorParams
from sensornet.tracking.label_keys import CELL_BASE, shared_births
from sensornet.tracking.lmb import LmbFilter, LmbState, update
from sensornet.tracking.lmb_sets import reduce_components
from sensornet.tracking.mixture import GaussianMixture
from sensornet.tracking.models import ConstantVelocity, LinearPosition

from benchmarks import lmb_before
from tests.lmb_cases import random_case

FIELDS = ("labels", "existence", "weights", "means", "covs", "owner")


def _same(a: LmbState, b: LmbState) -> bool:
    """Every array of two states equal to the bit (and of one shape and dtype)."""
    pairs = [(getattr(a.tracks, f), getattr(b.tracks, f)) for f in FIELDS]
    pairs += [(getattr(a.pending, f), getattr(b.pending, f)) for f in ("weights", "means", "covs")]
    pairs.append((a.hits, b.hits))
    return a.k == b.k and all(x.shape == y.shape and x.dtype == y.dtype and np.array_equal(x, y)
                              for x, y in pairs)


def _scans(rng: np.random.Generator, n_targets: int, clutter: float, scans: int,
           pd: float = 0.9) -> list[np.ndarray]:
    """Position plots ``(m, 2)`` per scan of ``n_targets`` targets on straight lines through a
    2 km square, detected with ``pd``, and Poisson(``clutter``) uniform clutter."""
    pos = rng.uniform(-800, 800, size=(n_targets, 2))
    vel = rng.normal(0, 8, size=(n_targets, 2))
    out = []
    for k in range(scans):
        p = pos + k * vel
        seen = p[rng.random(n_targets) < pd]
        seen = seen + rng.normal(0, 10, size=seen.shape)
        noise = rng.uniform(-1000, 1000, size=(rng.poisson(clutter), 2))
        out.append(np.concatenate((seen, noise))[rng.permutation(len(seen) + len(noise))])
    return out


def _filters(**kw) -> tuple[LmbFilter, LmbFilter]:
    """The new filter and the before one with the same settings (so the same Gibbs seed)."""
    base = dict(motion=ConstantVelocity(1.0, 2.0),
                sensor=SensorParams(LinearPosition(10.0), 0.9, 10.0 / 4e6),
                gibbs_tracks=None)  # the step before samples every large cluster by Gibbs
    base.update(kw)
    return LmbFilter(**base), lmb_before.LmbFilterBefore(**base)


BIRTH = GaussianMixture(np.array([0.03, 0.03]), np.array([[0.0, 0.0, 0.0, 0.0],
                                                          [500.0, 0.0, -500.0, 0.0]]),
                        np.tile(np.diag([100.0**2, 10.0**2, 100.0**2, 10.0**2]), (2, 1, 1)))


@pytest.mark.parametrize("settings", [
    dict(),
    dict(shared_origin=0, origin=3),
    dict(shared_origin=0, origin=3, birth=BIRTH),
    dict(birth=BIRTH, adaptive_birth=False),
    dict(scalable="lbp", exact_limit=50),
    dict(method="lbp"),
    dict(method="gibbs", gibbs_samples=200),
    dict(extraction="map", max_components=2),
])
@pytest.mark.parametrize("seed", [0, 1])
def test_scan_sequences_equal_the_step_before_to_the_bit(settings, seed):
    """30 scans of 8 targets in clutter 10 (some scans left out: 2-scan predictions), the new
    step and the old one fed the same inputs, every state compared; the tracks are real (some
    are confirmed) so the association and the merge are exercised, not an empty filter."""
    rng = np.random.default_rng(seed)
    scans = _scans(rng, 8, 10.0, 30)
    new, old = _filters(**settings)
    a, b = new.initial(), old.initial()
    k = -1
    for i, z in enumerate(scans):
        k += 2 if i % 7 == 6 else 1
        a, b = new.step(a, z, k), old.step(b, z, k)
        assert _same(a, b), f"scan {i} differs"
    assert (a.hits >= new.confirm_scans).sum() >= 3
    assert len(new.extract(a)) == len(old.extract(b))


def test_dense_clutter_sequence_with_large_clusters_equal_to_the_bit(monkeypatch):
    """20 targets in clutter 50, exact limit 200: loopy clusters beyond it (so the thinning
    and Gibbs sampling run, counted) and mixtures of hundreds of components (beyond the dense
    pair mask's size)."""
    calls = {"drop": 0, "gibbs": 0}

    def counted(name, fn):
        def run(*args, **kw):
            calls[name] += 1
            return fn(*args, **kw)
        return run

    monkeypatch.setattr(lmb_association, "drop_weak_links",
                        counted("drop", lmb_association.drop_weak_links))
    monkeypatch.setattr(lmb_association, "marginals_gibbs",
                        counted("gibbs", lmb_association.marginals_gibbs))
    rng = np.random.default_rng(7)
    new, old = _filters(exact_limit=200)
    a, b = new.initial(), old.initial()
    for k, z in enumerate(_scans(rng, 20, 50.0, 6)):
        with np.errstate(over="ignore"):  # the hypothesis bound of a big cluster overflows
            a, b = new.step(a, z, k), old.step(b, z, k)
        assert _same(a, b), f"scan {k} differs"
    assert len(a.tracks.weights) > lmb_sets.PAIRS_DENSE
    assert calls["drop"] >= 1 and calls["gibbs"] >= 1


def test_update_on_the_random_association_cases_equals_the_update_before():
    """The 200 random cases of tests/lmb_cases.py (tracks competing for plots), the update's
    posterior and ``r_U`` equal to the bit."""
    rng = np.random.default_rng(2014)
    for _ in range(200):
        tracks, z, sensor = random_case(rng)
        post, r_u = update(tracks, z, sensor, min_weight=1e-4)
        post0, r_u0 = lmb_before.update(tracks, z, sensor, min_weight=1e-4)
        assert np.array_equal(r_u, r_u0)
        for f in FIELDS:
            assert np.array_equal(getattr(post, f), getattr(post0, f)), f


def test_merge_pairs_dense_and_from_sizes_agree(monkeypatch):
    """:func:`lmb_sets._merge_within` finds same-track pairs by a dense mask on small mixtures
    and from the track sizes on large ones: both ways, the reduced set equals the old code's."""
    rng = np.random.default_rng(3)
    for _ in range(50):
        tracks, z, sensor = random_case(rng, max_tracks=6, max_meas=8)
        post, _ = update(tracks, z, sensor)
        want = lmb_before.reduce_components(post, 1e-4, 4.0, 3)
        for dense in (0, 10_000):
            monkeypatch.setattr(lmb_sets, "PAIRS_DENSE", dense)
            got = reduce_components(post, 1e-4, 4.0, 3)
            for f in FIELDS:
                assert np.array_equal(getattr(got, f), getattr(want, f)), (dense, f)


def test_predict_without_births_keeps_the_tracks_and_copies_nothing_shared():
    """No birth model, nothing pending: the prediction holds the survivors only (labels,
    weights and owner equal to the input's) in new arrays, as before."""
    new, old = _filters(adaptive_birth=False)
    rng = np.random.default_rng(5)
    tracks, _, _ = random_case(rng)
    state = LmbState(tracks, np.zeros(len(tracks), dtype=np.int64), 4, new.initial().pending)
    a, b = new.predict(state), old.predict(state)
    assert _same(a, b)
    assert not np.shares_memory(a.tracks.labels, tracks.labels)
    assert a.k == 5 and len(a.tracks) == len(tracks)


def test_shared_births_with_ties_equal_the_labels_before():
    """Births in a few cells with tied priorities (the first of a tie keeps the cell): the
    labels equal the old code's (whose sort had the position as an explicit last key)."""
    rng = np.random.default_rng(11)
    for _ in range(500):
        n = int(rng.integers(0, 30))
        cells = CELL_BASE + rng.integers(0, 5, n)
        priority = rng.integers(0, 3, n).astype(float)
        want = lmb_before.shared_births(cells, priority, 0, 4, 9, 2)
        got = shared_births(cells, priority, 0, 4, 9, 2)
        assert np.array_equal(got, want)
    assert (want[:, 0] == 4).any()  # the last case had a shared cell lost to a tie or rank


def test_select_by_mask_equals_select_by_index():
    """:meth:`LabelledBernoulliSet.select` by a boolean mask (no sort) and by the same tracks'
    indexes (the general path) give the same arrays and dtypes."""
    rng = np.random.default_rng(12)
    for _ in range(100):
        tracks, z, sensor = random_case(rng, max_tracks=6)
        post, _ = update(tracks, z, sensor)
        mask = rng.random(len(post)) < 0.5
        a, b = post.select(mask), post.select(np.flatnonzero(mask))
        for f in FIELDS:
            x, y = getattr(a, f), getattr(b, f)
            assert x.dtype == y.dtype and np.array_equal(x, y), f
