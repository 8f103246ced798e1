"""The neighbour test: the Cauchy–Schwarz divergence against numerical integration, the
statistic and score on hand-made mixtures, and the consensus leaving out what it quarantines."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from sensornet.peers.trust import Trust, TrustConfig, alarm_limits, offset_information
from sensornet.tracking.divergence import cs_divergence, log_overlaps
from sensornet.tracking.mixture import GaussianMixture


def _cfg(**kw) -> TrustConfig:
    """The test alone (no registration, no repair: both on by default), which these
    tests are about; :mod:`tests.test_trust_repair` has the repairs."""
    return TrustConfig(**{"register": False, "repair": False, **kw})


P4 = np.diag([100.0, 25.0, 100.0, 25.0])


def mix(*comps) -> GaussianMixture:
    w, m, P = zip(*comps, strict=True)
    return GaussianMixture(np.array(w, float), np.array(m, float), np.array(P, float))


def _grid_density(D: GaussianMixture, X: np.ndarray, Y: np.ndarray) -> np.ndarray:
    pts = np.stack([X.ravel(), Y.ravel()], axis=1)
    out = np.zeros(len(pts))
    for w, m, P in zip(D.weights, D.means, D.covs, strict=True):
        diff = pts - m
        q = np.einsum("ni,ij,nj->n", diff, np.linalg.inv(P), diff)
        out += w * np.exp(-0.5 * q) / (2 * np.pi * np.sqrt(np.linalg.det(P)))
    return out


def test_overlaps_and_cs_divergence_match_numerical_integration():
    p = mix((0.9, [0.0, 0.0], [[40.0, 10.0], [10.0, 30.0]]),
            (0.6, [60.0, -20.0], [[25.0, 0.0], [0.0, 60.0]]))
    q = mix((1.2, [8.0, 5.0], [[50.0, -5.0], [-5.0, 45.0]]),
            (0.3, [-40.0, 30.0], [[80.0, 0.0], [0.0, 20.0]]),
            (0.5, [55.0, -10.0], [[30.0, 12.0], [12.0, 40.0]]))
    x = np.linspace(-120.0, 140.0, 1041)
    X, Y = np.meshgrid(x, x)
    cell = (x[1] - x[0]) ** 2
    fp, fq = _grid_density(p, X, Y), _grid_density(q, X, Y)
    L = log_overlaps([p, q])
    np.testing.assert_allclose(np.exp(L), [[np.sum(fp * fp) * cell, np.sum(fp * fq) * cell],
                                           [np.sum(fq * fp) * cell, np.sum(fq * fq) * cell]],
                               rtol=1e-6)
    numeric = (-np.log(np.sum(fp * fq)) + 0.5 * np.log(np.sum(fp * fp))
               + 0.5 * np.log(np.sum(fq * fq)))
    assert cs_divergence(p, q) == pytest.approx(numeric, rel=1e-6)
    assert cs_divergence(p, p.scaled(3.0)) == pytest.approx(0.0, abs=1e-12)  # scale-free


def test_cs_divergence_of_two_gaussians_is_the_closed_form():
    # equal covariances: D_CS = (m1 - m2)' P^-1 (m1 - m2) / 4
    d = np.array([30.0, 2.0, -10.0, 1.0])
    a, b = mix((1.0, np.zeros(4), P4)), mix((2.0, d, P4))
    assert cs_divergence(a, b) == pytest.approx(d @ np.linalg.solve(P4, d) / 4.0)
    # far-apart tight components underflow nothing: the log-domain sum stays finite
    far = mix((1.0, [5000.0, 0.0, 0.0, 0.0], np.eye(4)))
    value = cs_divergence(a, far)
    assert np.isfinite(value) and value > 1e3
    assert np.isnan(cs_divergence(a, GaussianMixture.empty(4)))


A = np.array([0.0, 1.0, 0.0, -1.0])
B = np.array([500.0, 0.0, -400.0, 2.0])


def _honest(rng, n=4):
    """An honest neighbour: the two targets, estimated with scatter of its own covariance."""
    L = np.linalg.cholesky(P4)
    return mix((0.95, A + L @ rng.standard_normal(4), P4),
               (0.9, B + L @ rng.standard_normal(4), P4))


def test_statistic_is_small_for_honest_neighbours_and_large_for_lies():
    rng = np.random.default_rng(11)
    t = Trust(_cfg(), ("h1", "h2", "liar"))
    own = _honest(rng)
    lies = {
        "shifted": mix((0.95, A + [110.0, 0, 0, 0], np.eye(4)), (0.9, B + [110.0, 0, 0, 0],
                                                                  np.eye(4))),
        "inflated": _honest(rng).scaled(5.0),
        "empty": GaussianMixture.empty(4),
        "phantoms": GaussianMixture.concatenate([_honest(rng), mix(
            (1.0, [-800.0, 0, 800.0, 0], np.eye(4)), (1.0, [800.0, 0, 800.0, 0], np.eye(4)))]),
    }
    w = {"": 0.25, "h1": 0.25, "h2": 0.25, "liar": 0.25}
    for name, lie in lies.items():
        stats = t.statistics(own, {"h1": _honest(rng), "h2": _honest(rng), "liar": lie}, w)
        assert stats["h1"] < 2.0 and stats["h2"] < 2.0, (name, stats)
        assert stats["liar"] > 4.0, (name, stats)


def test_score_weight_quarantine_and_readmission():
    cfg = _cfg(warmup=0)
    t = Trust(cfg, ("h", "liar"))
    rng = np.random.default_rng(5)
    shifted = mix((0.95, A + [150.0, 0, 0, 0], np.eye(4)))
    weights_seen = []
    for k in range(1, 30):
        lying = k <= 10
        inputs = {"h": _honest(rng), "liar": shifted if lying else _honest(rng)}
        w = t.weigh(k, 0, _honest(rng), inputs, [0.5, 0.25, 0.25])
        assert sum(w) == pytest.approx(1.0) and min(w) >= 0.0
        weights_seen.append((k, w[2]))
    t.finish()
    by_k = dict(weights_seen)
    # (the liar's consensus weight is 0.25)
    assert by_k[1] < 0.25 and by_k[2] == 0.0  # down-weighted at once, out by the second scan
    assert all(by_k[k] == 0.0 for k in range(3, 12))  # quarantined, then hysteresis
    assert by_k[29] == 0.25  # readmitted once consistent for `readmit` scans
    changes = t.summary()["changes"]
    assert [c["to"] for c in changes if c["neighbour"] == "liar"] == ["suspect", "quarantined",
                                                                       "trusted"]
    assert not [c for c in changes if c["neighbour"] == "h"]


def test_what_is_taken_from_a_neighbour_is_renormalised_over_the_trusted_set():
    own = mix((1.0, A, P4))
    inputs = {"a": mix((1.0, A, P4)), "b": mix((1.0, A + 200.0, np.eye(4)))}
    w = Trust(_cfg(), ("a", "b")).weigh(1, 0, own, inputs, [0.4, 0.3, 0.3])
    assert w[2] < 0.3 and sum(w) == pytest.approx(1.0)
    trust_b = w[2] / 0.3 * (w[0] / 0.4)  # b's trust: its share before the renormalisation
    assert 0.0 < trust_b < 1.0
    # own and a keep their ratio 0.4 : 0.3, together 1 - w_b
    assert w[0] / w[1] == pytest.approx(0.4 / 0.3)
    assert w[0] + w[1] == pytest.approx(1.0 - w[2])
    to_own = Trust(_cfg(renormalise=False), ("a", "b")).weigh(1, 0, own, inputs,
                                                                     [0.4, 0.3, 0.3])
    assert to_own[1] == 0.3 and to_own[2] < 0.3
    assert to_own[0] == pytest.approx(1.0 - to_own[1] - to_own[2])
    # under a product rule the suspect is dropped, not down-weighted
    drop = Trust(_cfg(), ("a", "b")).weigh(1, 0, own, inputs, [0.4, 0.3, 0.3],
                                                  drop_suspects=True)
    assert drop[2] == 0.0 and drop[0] == pytest.approx(0.4 / 0.7)


def test_an_exact_repeat_is_quarantined_at_once_and_a_birth_only_density_is_not():
    rng = np.random.default_rng(3)
    t = Trust(_cfg(), ("h", "stuck"))
    held = _honest(rng)
    births = mix((0.1, A, P4), (0.1, B, P4))  # the birth intensity: the same every scan
    weights = {}
    for k in (1, 2, 3):
        own = _honest(rng)
        w = t.weigh(k, 0, own, {"h": births, "stuck": held.copy()}, [0.4, 0.3, 0.3])
        weights[k] = w
    t.finish()
    # scan 1 agrees with own (nothing to compare it with yet); scan 2 repeats scan 1 exactly
    assert weights[1][2] == pytest.approx(weights[1][0] * 0.75, rel=0.5)
    assert weights[2][2] == 0.0 and weights[3][2] == 0.0
    assert t.n["stuck"].state == "quarantined"
    assert t.n["h"].last_statistic < t.cfg.quarantine  # births alone repeat honestly
    # the same object again (a stale input reused) is no repeat; nor is a second round
    t2 = Trust(_cfg(), ("x",))
    same = _honest(rng)
    t2.weigh(1, 0, same, {"x": same}, [0.5, 0.5])
    assert t2.weigh(2, 0, same, {"x": same}, [0.5, 0.5])[1] == 0.5
    assert t2.weigh(2, 1, same, {"x": same.copy()}, [0.5, 0.5])[1] == 0.5
    off = Trust(_cfg(repeat=False), ("x",))
    for k in (1, 2, 3):
        w = off.weigh(k, 0, same, {"x": same.copy()}, [0.5, 0.5])
    assert w[1] == 0.5


def test_offset_information_is_the_least_squares_offset_of_the_matched_pairs():
    rng = np.random.default_rng(5)
    ref = mix((0.9, A, P4), (0.8, B, 2.0 * P4), (0.2, [50.0, 0, 50.0, 0], P4))
    b = np.array([12.0, -7.0])
    shift = np.array([b[0], 0.0, b[1], 0.0])
    noise = [rng.normal(0, 3, 4) * [1, 0, 1, 0] for _ in range(2)]
    nb = mix((0.95, A + shift + noise[0], 3.0 * P4), (0.7, B + shift + noise[1], P4),
             (0.9, [900.0, 0, 900.0, 0], P4))  # out of the gate: left out
    info, y = offset_information(ref, nb, [0, 2], 0.5, 60.0)
    # brute force: the pairs (nb 0, ref 0) and (nb 1, ref 1); ref 2 is under the weight
    S = [np.diag([400.0, 400.0]), np.diag([300.0, 300.0])]
    d = [(nb.means[i] - ref.means[i])[[0, 2]] for i in range(2)]
    np.testing.assert_allclose(info, sum(np.linalg.inv(x) for x in S))
    np.testing.assert_allclose(y, sum(np.linalg.solve(x, v) for x, v in zip(S, d, strict=True)))
    gls = np.linalg.solve(info, y)  # the weighted mean offset, near b
    assert np.linalg.norm(gls - b) < 6.0
    zero_i, zero_y = offset_information(ref, GaussianMixture.empty(4), [0, 2], 0.5, 60.0)
    assert not zero_i.any() and not zero_y.any()


def test_a_biased_neighbour_is_caught_by_its_offset_within_three_scans():
    """40 m off along x with an honest covariance (8 m position deviation): per scan within
    the divergence test's allowance, but the same offset every scan; honest neighbours'
    scatter averages out. (Gate 100 m: the test's scatter is drawn independently per peer.)"""
    P = np.diag([64.0, 25.0, 64.0, 25.0])
    L = np.linalg.cholesky(P)

    def honest(rng, off=0.0):
        return mix((0.95, A + L @ rng.standard_normal(4) + [off, 0, 0, 0], P),
                   (0.9, B + L @ rng.standard_normal(4) + [off, 0, 0, 0], P))

    def run(cfg, scans):
        rng = np.random.default_rng(8)
        t = Trust(cfg, ("h1", "h2", "biased"))
        low, honest_weights = None, []
        for k in range(1, scans + 1):
            w = t.weigh(k, 0, honest(rng), {"h1": honest(rng), "h2": honest(rng),
                                            "biased": honest(rng, 40.0)}, [0.25] * 4)
            honest_weights += w[2:4]  # [own, biased, h1, h2]: sorted names
            if low is None and w[1] <= 0.1:
                low = k
        return low, min(honest_weights)

    low, least = run(_cfg(bias_gate=100.0), 40)
    assert low is not None and low <= 3 and least >= 0.25  # theirs grows: the liar's share
    low_off, _ = run(_cfg(bias=False, bias_gate=100.0), 40)
    assert low_off is None or low_off > 3  # the divergence test alone is slower


def test_two_liars_telling_the_same_lie_do_not_cover_for_each_other():
    """Phantoms told by two neighbours are in each one's leave-one-out average, so the old
    statistic (smaller of own and the average) let both through; the median test does not."""
    rng = np.random.default_rng(21)
    own = _honest(rng)
    phantoms = mix((1.0, [-800.0, 0, 800.0, 0], np.eye(4)), (1.0, [800.0, 0, 800.0, 0],
                                                                np.eye(4)))
    names = ("h1", "h2", "h3", "h4", "l1", "l2")
    inputs = {s: _honest(rng) for s in names[:4]}
    inputs |= {s: GaussianMixture.concatenate([_honest(rng), phantoms]) for s in names[4:]}
    w = {"": 1 / 7, **{s: 1 / 7 for s in names}}
    med = Trust(_cfg(), names).statistics(own, inputs, w)
    old = Trust(_cfg(median_test=False), names).statistics(own, inputs, w)
    assert min(med["l1"], med["l2"]) > 4.0 and max(med[s] for s in names[:4]) < 1.0
    assert max(old["l1"], old["l2"]) < 1.0  # what the average reference gave


def test_disabled_or_warming_up_changes_nothing():
    own = mix((1.0, A, P4))
    bad = {"x": mix((1.0, A + 500.0, np.eye(4)))}
    assert Trust(_cfg(enabled=False), ("x",)).weigh(1, 0, own, bad, [0.5, 0.5]) == [0.5,
                                                                                         0.5]
    warm = Trust(_cfg(warmup=2), ("x",))
    assert warm.weigh(1, 0, own, bad, [0.5, 0.5]) == [0.5, 0.5]
    with pytest.raises(ValueError):
        _cfg(suspect=5.0, quarantine=4.0)


def test_consensus_leaves_a_quarantined_neighbour_out_and_the_summary_says_so():
    from sensornet.sim.run.launcher import trust_note
    from sensornet.sim.scenario import load_scenario
    from sensornet.sim.studies.lying.study import run_with_liar

    # plain GCI: a confident wrong estimate erases every target the honest peers fuse, unless
    # the liar is left out
    base = {"fusion.rule": "gci", "scenario.num_scans": 25}
    scn = load_scenario("seed000", overrides={**base, "fusion.trust": True,
                                              "fusion.trust_register": False,
                                              "fusion.trust_repair": False})
    res = run_with_liar(scn, 8100, "s2", "shifted")
    for n in ("s1", "s3"):
        trust = res.peers[n].snapshot()["trust"]
        assert trust["neighbours"]["s2"]["state"] == "quarantined"
        other = "s3" if n == "s1" else "s1"
        assert trust["neighbours"][other]["state"] == "trusted"
        first = [c for c in trust["changes"] if c["neighbour"] == "s2" and c["to"] ==
                 "quarantined"][0]
        assert first["k"] <= 3  # within 3 scans of the first lie
    note = trust_note({n: res.summary(n) for n in ("s1", "s3")})
    assert note.startswith("quarantined: s2 by s1 at scan") and "s3 at scan" in note
    # the undefended network (the defence is on by default: pinned off)
    open_door = run_with_liar(load_scenario("seed000", overrides={**base, "fusion.trust": False}),
                              8100, "s2", "shifted")
    for n in ("s1", "s3"):  # near its own filter (two peers left), far better than the lie
        assert res.mean_ospa(n) < 1.1 * res.mean_ospa(n, "local")
        assert res.mean_ospa(n) < 0.5 * open_door.mean_ospa(n)


def test_majority_spread_is_not_held_against_one_neighbour():
    """When every input disagrees with every other (a birth seen a scan apart), no neighbour
    is singled out; when the others agree, the one that does not is (W-MSR-style)."""
    spread = [mix((1.0, A + [dx, 0, 0, 0], P4)) for dx in (0.0, 40.0, 80.0, 120.0)]
    names = ("n1", "n2", "n3")
    on = Trust(_cfg(), names)
    off = Trust(_cfg(majority=False), names)
    inputs = dict(zip(names, spread[1:], strict=True))
    w = {"": 0.25, **{s: 0.25 for s in names}}
    loo = Trust(_cfg(median_test=False), names)  # the leave-one-out reference
    assert max(loo.statistics(spread[0], inputs, w).values()) < 1.0  # 0, 0, 0.56
    # the median test: the end of the line is the odd one, by half the cap at most (one such
    # scan leaves the score at 2 after the drift, under `suspect`); the others not at all
    s = on.statistics(spread[0], inputs, w)
    assert s["n1"] == s["n2"] == 0.0 and 0.0 < s["n3"] <= on.cfg.cap / 2
    assert s["n3"] - on.cfg.drift < on.cfg.suspect
    assert min(off.statistics(spread[0], inputs, w).values()) > 3.0  # 3.9, 3.9, 4.6
    agree = {"n1": spread[0], "n2": spread[0].scaled(1.05), "n3": spread[3]}
    s = on.statistics(spread[0], agree, w)
    assert s["n3"] > 5.0 and s["n1"] < 0.5 and s["n2"] < 0.5
    # with own and one other neighbour only there is no majority: the plain test
    two = {"n1": spread[0], "n3": spread[3]}
    assert on.statistics(spread[0], two, w) == off.statistics(spread[0], two, w)


def test_only_product_rules_drop_their_suspects():
    from sensornet.peers.contracts import FuserHooks
    from sensornet.peers.fusers import AaFuser, GciFuser, HybridFuser
    from sensornet.tracking.reduction import Reducer

    r = Reducer()
    assert FuserHooks.of(GciFuser(r)).product
    assert not FuserHooks.of(HybridFuser(r)).product and not FuserHooks.of(AaFuser(r)).product


def test_a_missed_or_newly_born_target_costs_what_a_miss_explains():
    """At Pd 0.9 an honest neighbour that missed its only target publishes nothing (level-2
    pruning); one that picked up a new target a scan before own disagrees with own entirely.
    The statistic is at most ``-log(1 - Pd)`` per target on either side (the closed form),
    so four such scans in a row do not quarantine; without the Pd nothing changes."""
    from sensornet.peers.trust_checks import miss_cost, pair_tests

    pd = 0.9
    cfg = _cfg(detection_probability=pd)
    own = mix((0.95, A, P4))
    missed = GaussianMixture.empty(4)
    born = mix((0.8, B, P4))  # a target own has not confirmed yet, own's far from it
    per = -np.log(1.0 - pd)
    assert float(miss_cost(cfg, 0.95, 0.0)) == pytest.approx(per * 0.95)

    def card(n_j, n_r):
        return (n_j - n_r) ** 2 / (n_r + 1.0)  # kappa = 1: the cardinality term stays

    for other, cost in ((missed, per * 0.95 + card(0.0, 0.95)),
                        (born, per * (0.95 + 0.8) + card(0.8, 0.95))):
        t = Trust(cfg, ("x",))
        old = Trust(_cfg(), ("x",))
        for k in (1, 2, 3, 4):
            t.weigh(k, 0, own, {"x": other}, [0.5, 0.5])
            old.weigh(k, 0, own, {"x": other}, [0.5, 0.5])
            assert t.n["x"].last_statistic == pytest.approx(cost)
            assert old.n["x"].last_statistic > cost  # the divergence test alone
        t.finish()
        old.finish()
        assert t.n["x"].state != "quarantined" and old.n["x"].state == "quarantined"
    # the majority's pair tests take the same bound, elementwise
    mixes = [own, missed, born]
    L = log_overlaps(mixes)
    mass = np.array([m.mass for m in mixes])
    targets = np.array([0.95, 0.0, 0.8])
    P = pair_tests(cfg, L, mass, targets)
    expect = np.zeros((3, 3))
    for a in range(3):
        for b in range(3):
            if a == b:
                continue
            if min(mass[a], mass[b]) <= 1e-9:
                where = 5.0 * min(1.0, max(mass[a], mass[b]))  # the empty penalty
            else:
                where = min(8.0, -L[a, b] + 0.5 * (L[a, a] + L[b, b]))
            where = min(where, per * (targets[a] + targets[b]))
            expect[a, b] = min(8.0, where + min(card(mass[a], mass[b]), card(mass[b], mass[a])))
    np.testing.assert_allclose(P, expect)
    # where misses are rare (Pd 0.99) hiding two targets costs more than the divergence
    # test's value, which stays the statistic
    two = _honest(np.random.default_rng(1))
    t, old = Trust(_cfg(detection_probability=0.99), ("x",)), Trust(_cfg(), ("x",))
    t.weigh(1, 0, two, {"x": missed}, [0.5, 0.5])
    old.weigh(1, 0, two, {"x": missed}, [0.5, 0.5])
    assert -np.log(0.01) * two.mass > t.n["x"].last_statistic
    assert t.n["x"].last_statistic == old.n["x"].last_statistic > 5.0


def test_an_estimate_is_tested_once_against_own_of_its_scan():
    """A neighbour's estimate of scan 1 used again at scans 2 and 3 (its later ones lost,
    predicted forward) adds nothing; one that arrives late is tested against own's density
    of its scan, not of the scan at hand."""
    far = A + [300.0, 0, 0, 0]
    own1, own2 = mix((0.95, A, P4)), mix((0.95, far, P4))
    stale = mix((0.95, A + [5.0, 0, 0, 0], P4))  # scan 1's estimate, near own1
    t = Trust(_cfg(), ("x",))
    t.weigh(1, 0, own1, {"x": stale}, [0.5, 0.5])
    first = t.n["x"].last_statistic
    assert first < 1.0
    # used again at scans 2 and 3 (against own2 it would be a total disagreement)
    for k in (2, 3):
        w = t.weigh(k, 0, own2, {"x": stale.copy()}, [0.5, 0.5], late={"x": (1, stale)})
        assert t.n["x"].last_statistic == 0.0 and w[1] == 0.5
    plain = Trust(_cfg(same_scan=False), ("x",))
    plain.weigh(1, 0, own1, {"x": stale}, [0.5, 0.5])
    plain.weigh(2, 0, own2, {"x": stale.copy()}, [0.5, 0.5], late={"x": (1, stale)})
    assert plain.n["x"].last_statistic >= _cfg().cap
    # a late first use: scan 4's estimate reaches the fusion of scan 5 and is tested
    # against own's density of scan 4 (kept though nothing came at scan 4), not of scan 5
    t.weigh(4, 0, own1, {}, [1.0])
    t.weigh(5, 0, own2, {"x": stale.copy()}, [0.5, 0.5], late={"x": (4, stale)})
    assert t.n["x"].last_statistic == pytest.approx(first)
    t.weigh(6, 0, own2, {}, [1.0])
    t.weigh(7, 0, own1, {"x": stale.copy()}, [0.5, 0.5], late={"x": (6, stale)})
    assert t.n["x"].last_statistic >= _cfg().cap  # against own2, its scan's


def test_unmatched_target_weights_against_brute_force_and_phantoms():
    """``U[a, b]``: the target weight of ``a`` with nothing of ``b`` within the gate, against
    a loop over components; in the pair tests (the majority's) phantoms next to honest
    targets score ``unmatched_cost`` each, more than one extra target does."""
    from dataclasses import replace

    from sensornet.peers.trust_checks import pair_tests, unmatched_weights

    rng = np.random.default_rng(21)
    mixes = [mix(*[(w, [x, 0.0, y, 0.0], P4) for w, x, y in zip(
        rng.uniform(0.2, 1.5, n), rng.uniform(0, 300, n), rng.uniform(0, 300, n),
        strict=True)]) if n else GaussianMixture.empty(4) for n in (4, 0, 6, 3, 1)]
    U, _ = unmatched_weights(mixes, [0, 2], 0.5, 60.0)
    for a, Da in enumerate(mixes):
        for b, Db in enumerate(mixes):
            brute = 0.0
            for w, m in zip(Da.weights, Da.means, strict=True):
                if w < 0.5:
                    continue
                if not any(v >= 0.5 and np.hypot(*(m - q)[[0, 2]]) <= 60.0
                           for v, q in zip(Db.weights, Db.means, strict=True)):
                    brute += w
            assert U[a, b] == pytest.approx(brute), (a, b)
    cfg = _cfg(detection_probability=0.99)
    own = _honest(rng)
    phantoms = GaussianMixture.concatenate([_honest(rng), mix(  # honest-looking covariances
        (1.0, [-800.0, 0, 800.0, 0], P4), (1.0, [800.0, 0, 800.0, 0], P4),
        (1.0, [-800.0, 0, -800.0, 0], P4))])
    extra = GaussianMixture.concatenate([_honest(rng), mix((0.9, [0.0, 0, 800.0, 0], P4))])
    # the pair tests: the location part at least unmatched_cost per unmatched target weight
    mixes = [own, phantoms, extra]
    L = log_overlaps(mixes)
    mass = np.array([m.mass for m in mixes])
    U, _ = unmatched_weights(mixes, [0, 2], 0.5, 60.0)
    np.testing.assert_allclose(U, [[0, 0, 0], [3.0, 0, 3.0], [0.9, 0.9, 0]])
    P = pair_tests(cfg, L, mass, None, U)
    for a in range(3):
        for b in range(3):
            if a != b:
                where = max(-L[a, b] + 0.5 * (L[a, a] + L[b, b]), 2.0 * (U[a, b] + U[b, a]))
                card = min((mass[a] - mass[b]) ** 2 / (mass[b] + 1.0),
                           (mass[b] - mass[a]) ** 2 / (mass[a] + 1.0))
                assert P[a, b] == pytest.approx(min(8.0, where + card))
    # with a majority (own and three others) phantoms stand out, one extra target does not
    names = ("h1", "h2", "e", "p")
    inputs = {"h1": _honest(rng), "h2": _honest(rng), "e": extra, "p": phantoms}
    on, off = Trust(cfg, names), Trust(replace(cfg, unmatched=False), names)
    on.weigh(1, 0, own, inputs, [0.2] * 5)
    off.weigh(1, 0, own, inputs, [0.2] * 5)
    assert on.n["p"].last_statistic > off.n["p"].last_statistic + 1.0
    assert on.n["p"].last_statistic > cfg.drift + 2.0 > on.n["e"].last_statistic
    # without a majority (two neighbours) the term is not used
    two = Trust(cfg, ("e", "p"))
    two.weigh(1, 0, own, {"e": extra, "p": phantoms}, [0.4, 0.3, 0.3])
    plain = Trust(replace(cfg, unmatched=False), ("e", "p"))
    plain.weigh(1, 0, own, {"e": extra, "p": phantoms}, [0.4, 0.3, 0.3])
    assert two.n["p"].last_statistic == plain.n["p"].last_statistic


def test_relative_offsets_take_own_error_out_of_every_neighbours_offset():
    """Own 70 m off (re-acquired from a birth) moves every neighbour's offset against own by
    the same amount; the median of the others' takes it out, a biased one keeps its 30 m."""
    from sensornet.peers.trust_checks import relative_offsets

    rng = np.random.default_rng(4)
    own_err = np.array([-70.0, 20.0])
    infos, true = {}, {}
    for s in ("a", "b", "c", "d", "biased"):
        info = np.linalg.inv(np.diag(rng.uniform(150.0, 400.0, 2)))  # (2, 2)
        off = -own_err + rng.normal(0.0, 5.0, 2) + ([30.0, 0.0] if s == "biased" else 0.0)
        infos[s], true[s] = (info, info @ off), off
    infos["late"] = (np.eye(2), np.array([3.0, 4.0]))  # not among: untouched
    out = relative_offsets(infos, ["a", "b", "c", "d", "biased"])
    for s in ("a", "b", "c", "d", "biased"):
        others = np.array([true[h] for h in ("a", "b", "c", "d", "biased") if h != s])
        np.testing.assert_allclose(out[s][1], infos[s][0] @ (true[s] - np.median(others, 0)))
        np.testing.assert_array_equal(out[s][0], infos[s][0])
    assert out["late"] is infos["late"]
    chi2 = {s: out[s][1] @ np.linalg.solve(out[s][0], out[s][1]) for s in out if s != "late"}
    raw = {s: infos[s][1] @ np.linalg.solve(*infos[s]) for s in chi2}
    assert max(chi2[s] for s in "abcd") < 1.0 < min(raw[s] for s in "abcd")  # own's error out
    assert chi2["biased"] > 2.0  # 30 m against a 12-20 m deviation: its own
    # with fewer than three offsets nothing changes
    two = relative_offsets({s: infos[s] for s in ("a", "b")}, ["a", "b"])
    assert all(two[s] is infos[s] for s in two)


def test_calibration_counts_which_test_began_each_quarantine():
    from sensornet.sim.studies.lying.trust_calibration import simulate

    cfg = _cfg()
    none = np.zeros((6, 2))
    hit = none.copy()
    hit[2, 0] = cfg.bias_thresholds[0] + 1.0
    seqs = [(np.array([0.5, 8.0, 8.0, 0.0, 0.0, 0.0]), none),  # divergence: 6, then 10.8
            (np.array([0.5, 0.5, 0.5, 0.5, 0.5, 0.5]), hit),  # the offset at scan 3
            (np.array([0.5, cfg.quarantine + cfg.drift, 0.0, 0.0, 0.0, 0.0]), none),
            (np.full(6, 1.0), none)]  # honest: never
    sim = simulate(seqs, cfg)
    assert sim["causes"] == {"divergence": 1, "offset": 1, "repeat": 1, "withhold": 0}
    assert sim["first_low"] == [3, 3, 2, None]
    # the withheld-target CUSUM is the last column of alarm_limits
    full = np.zeros((6, len(alarm_limits(cfg))))
    held = full.copy()
    held[3:, -1] = cfg.withhold_threshold + 1.0
    sim = simulate([(np.full(6, 0.5), held), (np.full(6, 0.5), full)], cfg)
    assert sim["causes"] == {"divergence": 0, "offset": 0, "repeat": 0, "withhold": 1}
    assert sim["first_low"] == [4, None]


def test_calibration_counts_holds_apart_from_quarantines():
    """A withheld-target CUSUM above the hold but under the quarantine threshold takes the
    weight to 0 (first_low) without a quarantine; the share of such triples is ``held``."""
    from sensornet.sim.studies.lying.trust_calibration import simulate

    cfg = TrustConfig(detection_probability=0.99)
    col = np.zeros((6, len(alarm_limits(cfg))))
    col[2:4, -1] = cfg.withhold_hold + 1.0  # two scans above the hold, under quarantine
    sim = simulate([(np.full(6, 0.5), col), (np.full(6, 0.5), np.zeros_like(col))], cfg)
    assert sim["held"] == pytest.approx(2 / 12)
    assert sim["quarantined"] == 0.0 and sim["causes"]["withhold"] == 0
    assert sim["first_low"] == [3, None]
    off = simulate([(np.full(6, 0.5), col)], replace(cfg, withhold_hold=None))
    assert off["held"] == 0.0 and off["first_low"] == [None]
