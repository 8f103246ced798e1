"""Repair of a neighbour's density (peers/trust_repair.py, TrustConfig.repair): the pure parts
against brute force and closed forms, and Trust fusing the repaired density of the lies that
still carry the liar's measurements (inflated, phantoms), never of those that do not."""

from __future__ import annotations

import numpy as np
from sensornet.peers.trust import Trust, TrustConfig
from sensornet.peers.trust_repair import corroborated, corroborated_part, mass_factor, scan_factor
from sensornet.tracking.mixture import GaussianMixture

POS = [0, 2]
P4 = np.diag([100.0, 25.0, 100.0, 25.0])
A = np.array([0.0, 1.0, 0.0, -1.0])
B = np.array([500.0, 0.0, -400.0, 2.0])
FAR = np.array([-900.0, 0.0, 900.0, 0.0])


def mix(*comps) -> GaussianMixture:
    w, m, P = zip(*comps, strict=True)
    return GaussianMixture(np.array(w, float), np.array(m, float), np.array(P, float))


def _honest(rng, wa=0.95, wb=0.9) -> GaussianMixture:
    L = np.linalg.cholesky(P4)
    return mix((wa, A + L @ rng.standard_normal(4), P4), (wb, B + L @ rng.standard_normal(4), P4))


def test_corroborated_is_the_brute_force_gate_over_the_others_targets():
    rng = np.random.default_rng(3)
    mixes = [GaussianMixture(rng.uniform(0.1, 1.5, n), rng.uniform(-300, 300, (n, 4)),
                             np.broadcast_to(P4, (n, 4, 4)).copy()) for n in (12, 7, 9)]
    got = corroborated(mixes[0], mixes[1:], POS, 0.5, 80.0)
    want = [any(np.hypot(*(mixes[0].means[i, POS] - D.means[j, POS])) <= 80.0
                for D in mixes[1:] for j in range(len(D)) if D.weights[j] >= 0.5)
            for i in range(len(mixes[0]))]
    assert got.tolist() == want and 0 < sum(want) < len(want)
    assert corroborated(mixes[0], [GaussianMixture.empty(4)], POS, 0.5, 80.0).sum() == 0


def test_with_three_references_a_component_needs_own_or_two_others():
    """Two liars adding the same phantoms must not corroborate each other."""
    target, phantom = mix((1.0, A, P4)), mix((1.0, FAR, np.eye(4)))
    liar = GaussianMixture.concatenate([target, phantom])
    empty = GaussianMixture.empty(4)
    other_liar, honest = phantom, target
    assert corroborated(liar, [target, other_liar, honest], POS, 0.5, 60.0).tolist() == [
        True, False]  # the phantom: one other only
    assert corroborated(liar, [empty, other_liar, phantom], POS, 0.5, 60.0).tolist() == [
        False, True]  # two others show it
    assert corroborated(liar, [phantom, empty, empty], POS, 0.5, 60.0).tolist() == [
        False, True]  # own shows it
    assert corroborated(liar, [empty, other_liar], POS, 0.5, 60.0).tolist() == [False, True]


def test_mass_factor_is_one_over_the_inflation_and_one_for_the_same_targets():
    rng = np.random.default_rng(5)
    own = _honest(rng)
    assert mass_factor(own, own, POS, 0.5, 60.0) == 1.0
    assert np.isclose(mass_factor(own.scaled(5.0), own, POS, 0.5, 60.0), 0.2)
    # own sees only A: the factor is over the component A went to, not the whole density
    only_a = mix((0.8, A, P4))
    assert np.isclose(mass_factor(own, only_a, POS, 0.5, 60.0), 0.8 / own.weights[0])
    assert mass_factor(own, mix((0.9, FAR, P4)), POS, 0.5, 60.0) is None
    zero = mix((0.0, A, P4), (0.0, B, P4))  # hostile: weightless components matched
    assert mass_factor(zero, own, POS, 0.5, 60.0) is None
    # with fewer than three references only the first (own) counts: one liar is not a median
    liar_ref = own.scaled(9.0)
    assert scan_factor(own, [own, liar_ref], POS, 0.5, 60.0) == 1.0
    assert scan_factor(own, [own, liar_ref, own], POS, 0.5, 60.0) == 1.0
    phantoms_only = mix((1.0, FAR, np.eye(4)))
    assert corroborated_part(phantoms_only, [own], POS, 0.5, 60.0) is None


def _scans(lie, n=6, repair=True, seed=7, **cfg):
    """n scans of one peer with two honest neighbours and a liar telling ``lie``; per scan
    the liar's statistic and what is fused of it."""
    rng = np.random.default_rng(seed)
    t = Trust(TrustConfig(repair=repair, register=False, detection_probability=0.95, **cfg),
              ("h1", "liar"))
    out = []
    for k in range(1, n + 1):
        own, real = _honest(rng), _honest(rng)
        inputs = {"h1": _honest(rng), "liar": lie(real)}
        w = t.weigh(k, 0, own, inputs, [1 / 3] * 3)
        out.append((real, t.n["liar"].last_statistic, w[2], t.fused_input("liar",
                                                                          inputs["liar"])))
    t.finish()
    return t, out


def test_an_inflated_liar_is_fused_at_its_real_weights_and_stays_trusted():
    t, scans = _scans(lambda m: m.scaled(5.0))
    _, off = _scans(lambda m: m.scaled(5.0), repair=False)
    _, honest = _scans(lambda m: m)
    for (real, stat, w, fused), (_, stat_off, _, _), (_, stat_honest, _, _) in zip(
            scans, off, honest, strict=True):
        assert stat < stat_off and stat_off > 4.0
        assert np.isclose(stat, stat_honest, rtol=0.05, atol=0.05)  # as if it told the truth
        assert w > 0.3
        np.testing.assert_allclose(fused.means, real.means)
        # the median factor over the scans so far: within 15 % of the real weights
        np.testing.assert_allclose(fused.weights, real.weights, rtol=0.15)
    assert t.n["liar"].state == "trusted" and t.n["liar"].repaired_k == 1
    assert t.summary()["neighbours"]["liar"]["repairs"] == 6
    assert t.n["liar"].low_k is None
    assert _scans(lambda m: m.scaled(5.0), repair=False)[0].n["liar"].state == "quarantined"


def test_phantoms_are_dropped_and_the_real_targets_kept():
    def phantoms(m):
        return GaussianMixture.concatenate([m, mix((1.0, FAR, np.eye(4)),
                                                   (1.0, -FAR, np.eye(4)))])
    t, scans = _scans(phantoms)
    _, honest = _scans(lambda m: m)
    for (real, stat, _, fused), (_, stat_honest, _, _) in zip(scans, honest, strict=True):
        assert np.isclose(stat, stat_honest) and len(fused) == 2
        np.testing.assert_allclose(fused.means, real.means)
    assert t.n["liar"].state == "trusted"


def test_an_empty_liar_is_not_repaired():
    t = _scans(lambda m: GaussianMixture.empty(4))[0]
    assert t.n["liar"].repairs == 0 and t.n["liar"].state == "quarantined"


def test_a_shifted_confident_liar_is_moved_back_with_owns_covariances():
    """Every component 110 m off along x with a 1 m^2 covariance: nothing is corroborated
    within the gate, so from the second such scan its offset against own (pairs up to 250 m
    apart, over the scans so far) is subtracted and its covariances are own's."""
    def shifted(m):
        return GaussianMixture(m.weights, m.means + [110.0, 0, 0, 0],
                               np.broadcast_to(np.eye(4), (2, 4, 4)).copy())
    t, scans = _scans(shifted, n=8)
    assert t.n["liar"].repaired_k == 2 and t.n["liar"].state == "trusted"
    for real, _, w, fused in scans[2:]:
        assert len(fused) == 2 and w > 0.3
        # own's and the liar's errors are each of covariance P4: the registered offset is
        # within a few of their standard deviations (10 m) of the true 110 m
        np.testing.assert_allclose(fused.means[:, POS], real.means[:, POS], atol=25.0)
        np.testing.assert_allclose(fused.covs, np.broadcast_to(P4, (2, 4, 4)))
    off = _scans(shifted, n=8, repair_offset_gate=0.0)[0]  # no registration of large offsets
    assert off.n["liar"].repairs == 0 and off.n["liar"].state == "quarantined"


def test_moved_to_own_subtracts_the_offset_and_floors_covariances_at_owns():
    from sensornet.peers.trust_repair import moved_to_own
    own = mix((1.0, A, P4), (1.0, B, 4 * P4))
    liar = mix((1.0, A + [100.0, 0, 50.0, 0], np.eye(4)), (1.0, B + [100.0, 0, 50.0, 0],
                                                            9 * P4))
    moved = moved_to_own(liar, own, np.array([100.0, 50.0]), POS)
    np.testing.assert_allclose(moved.means, own.means)
    np.testing.assert_allclose(moved.covs[0], P4)  # 1 m^2 claimed: own's, wider
    np.testing.assert_allclose(moved.covs[1], 9 * P4)  # its own is wider than own's: kept
    np.testing.assert_allclose(liar.means[0], A + [100.0, 0, 50.0, 0])  # not changed in place


def test_an_honest_neighbour_within_the_drift_is_fused_as_it_is():
    rng = np.random.default_rng(1)
    t = Trust(TrustConfig(repair=True), ("h1", "h2"))
    own, h1, h2 = _honest(rng), _honest(rng), _honest(rng)
    t.weigh(1, 0, own, {"h1": h1, "h2": h2}, [1 / 3] * 3)
    assert t.n["h1"].repairs == 0 and t.fused_input("h1", h1) is h1


def test_a_phantoms_liar_on_the_twin_is_repaired_and_run_says_so():
    from sensornet.sim.run.launcher import trust_note
    from sensornet.sim.scenario import load_scenario
    from sensornet.sim.studies.lying.study import run_with_liar

    base = {"scenario.num_scans": 25, "fusion.trust": True}
    res = run_with_liar(load_scenario("seed000", overrides=base), 8100, "s2", "phantoms")
    out = run_with_liar(load_scenario("seed000", overrides={**base, "fusion.trust_repair": False}),
                        8100, "s2", "phantoms")
    for n in ("s1", "s3"):
        rec = res.summary(n)["trust"]["neighbours"]["s2"]
        assert rec["state"] == "trusted" and rec["repairs"] >= 0.7 * rec["rounds"], rec
        assert out.summary(n)["trust"]["neighbours"]["s2"]["state"] == "quarantined"
        assert res.mean_ospa(n) < out.mean_ospa(n)  # its real targets kept
    note = trust_note({n: res.summary(n) for n in ("s1", "s3")})
    assert "repaired: s2 by s1 from scan 1 (" in note and ", s3 from scan 1 (" in note
