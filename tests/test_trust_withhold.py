"""The withheld-target test (``TrustConfig.withhold``): its per-scan log-likelihood ratio
against the closed form and a brute-force loop, and Page's CUSUM of it in the score."""

from __future__ import annotations

import numpy as np
import pytest
from sensornet.peers.trust import Trust, TrustConfig
from sensornet.peers.trust_checks import target_mass, unmatched_weights, withheld_increments
from sensornet.tracking.mixture import GaussianMixture

P4 = np.diag([100.0, 25.0, 100.0, 25.0])
A = np.array([0.0, 1.0, 0.0, -1.0])
B = np.array([500.0, 0.0, -400.0, 2.0])
EMPTY = GaussianMixture.empty(4)


def mix(*comps) -> GaussianMixture:
    w, m, P = zip(*comps, strict=True)
    return GaussianMixture(np.array(w, float), np.array(m, float), np.array(P, float))


def _inputs(mixes):
    U, _ = unmatched_weights(mixes, [0, 2], 0.5, 60.0)
    tm = np.array([target_mass(m, 0.5) for m in mixes])
    return U, tm


def test_increment_is_the_bernoulli_miss_log_likelihood_ratio():
    pd, alt = 0.99, 0.99
    a, b = np.log(alt / (1 - pd)), np.log((1 - alt) / pd)
    own = mix((0.9, A, P4))
    cases = {"empty": (EMPTY, min(0.9 * a, 4.47)),  # withholds own's target: capped
             "matched": (mix((0.8, A + [10.0, 0, 0, 0], P4)), 0.9 * b),
             "elsewhere": (mix((0.9, B, P4)), 0.0)}  # re-acquired far off: not withheld
    for name, (other, expect) in cases.items():
        U, tm = _inputs([own, other])
        refs = np.array([[False, True], [True, False]])
        inc = withheld_increments(U, tm, refs, pd, alt, 4.47)
        assert inc[0] == 0.0 and inc[1] == pytest.approx(expect), name
    # uncapped, two targets withheld count twice
    two = mix((0.9, A, P4), (0.7, B, P4))
    U, tm = _inputs([two, EMPTY])
    inc = withheld_increments(U, tm, np.array([[False, True], [True, False]]), pd, alt, 1e9)
    assert inc[1] == pytest.approx(1.6 * a)


def test_references_combine_by_median_with_a_majority_and_minimum_without_brute_force():
    rng = np.random.default_rng(3)
    pd, alt, cap = 0.95, 0.9, 4.0
    a, b = np.log(alt / (1 - pd)), np.log((1 - alt) / pd)
    pool = [A, B, A + [300.0, 0, 0, 0], B + [0, 0, 250.0, 0]]
    mixes = []
    for _ in range(6):  # random subsets of the four targets, random weights
        keep = [x for x in pool if rng.random() < 0.6]
        mixes.append(mix(*[(rng.uniform(0.5, 1.2), x + rng.normal(0, 5, 4), P4) for x in keep])
                     if keep else EMPTY)
    U, tm = _inputs(mixes)
    n = len(mixes)
    for refs in (rng.random((n, n)) < 0.7, np.ones((n, n), bool)):
        np.fill_diagonal(refs, False)
        got = withheld_increments(U, tm, refs, pd, alt, cap)
        for j in range(1, n):
            ls = []
            for r in range(n):
                if not refs[j, r]:
                    continue
                # r's targets with no target of j within 60 m, against j's with none of r's
                lack = sum(w for w, x in zip(mixes[r].weights, mixes[r].means, strict=True)
                           if w >= 0.5 and not any(v >= 0.5 and np.hypot(*(x - y)[[0, 2]]) <= 60
                                                   for v, y in zip(mixes[j].weights,
                                                                   mixes[j].means, strict=True)))
                extra = sum(w for w, x in zip(mixes[j].weights, mixes[j].means, strict=True)
                            if w >= 0.5 and not any(v >= 0.5 and np.hypot(*(x - y)[[0, 2]]) <= 60
                                                    for v, y in zip(mixes[r].weights,
                                                                    mixes[r].means, strict=True)))
                shown = sum(w for w in mixes[r].weights if w >= 0.5) - lack
                ls.append(min(a * max(0.0, lack - extra), cap) + b * shown)
            expect = (np.median(ls) if len(ls) >= 3 else min(ls)) if ls else 0.0
            assert got[j] == pytest.approx(expect), (j, refs[j])


def test_an_empty_neighbour_is_held_at_its_second_scan_and_out_at_its_fourth():
    """Own and an honest neighbour each show one target; ``x`` publishes nothing. The
    leaky score alone needs four scans (statistic about 5 a scan); the withheld CUSUM,
    ``min(-log(1 - Pd) w + log 0.99, 4.47)`` a scan with no drift, passes the hold (4.47:
    more than one scan's evidence) at the second, which holds x's weight at 0 without a
    quarantine, and the quarantine threshold (14) at the fourth."""
    cfg = TrustConfig(detection_probability=0.99)
    per = min(np.log(0.99 / 0.01) * 0.95, cfg.withhold_cap)
    assert per <= cfg.withhold_hold < 2 * per
    assert 3 * per < cfg.withhold_threshold < 4 * per
    target = mix((0.95, A, P4))
    low, states = {}, []
    for on in (True, False):
        t = Trust(TrustConfig(detection_probability=0.99, withhold=on), ("h", "x"))
        for k in range(1, 7):
            w = t.weigh(k, 0, target, {"h": target, "x": EMPTY}, [1 / 3, 1 / 3, 1 / 3])
            if w[2] <= 0.1 * (1 / 3):
                low.setdefault(on, k)
            if on:
                states.append(t.n["x"].state)  # as the previous scan closed it
        assert t.n["x"].withheld == (pytest.approx(6 * per) if on else 0.0)
        # held where the score alone would fuse it: scans 2-3 (from scan 4 the withheld
        # CUSUM's quarantine statistic zeroes the score's weight too)
        assert t.n["x"].holds == (2 if on else 0)
        # the per-round records (Rerun, CSVs) say so
        held = [(r["k"], r["held"]) for r in t.records if r["neighbour"] == "x"]
        assert held == [(k, on and k >= 2) for k in range(1, 7)]
    assert low == {True: 2, False: 4}
    # held from scan 2, but quarantined only after scan 4 (shown from scan 5 on)
    assert "quarantined" not in states[:4] and states[4:] == ["quarantined"] * 2


def test_an_honest_loss_of_three_scans_is_held_and_fused_again_at_once_not_quarantined():
    cfg = TrustConfig(detection_probability=0.99)
    per = min(np.log(0.99 / 0.01) * 0.95, cfg.withhold_cap)
    target = mix((0.95, A, P4))
    t = Trust(cfg, ("h", "x"))
    weights = {}
    for k in range(1, 12):
        x = EMPTY if k in (4, 5, 6) else target
        weights[k] = t.weigh(k, 0, target, {"h": target, "x": x}, [1 / 3, 1 / 3, 1 / 3])[2]
        assert t.n["x"].withheld <= 3 * per + 1e-9
        assert t.n["x"].state != "quarantined"
    t.finish()
    # the first lost scan is fused, the next two are held; each scan showing the target
    # again takes 0.95 log(Pd / 0.01) = 4.37 off: 13.1 -> 8.7 (held) -> 4.4 (fused at full
    # weight again, no hysteresis)
    assert [k for k, w in weights.items() if w == 0.0] == [5, 6, 7]
    assert weights[8] == pytest.approx(1 / 3)
    assert t.n["x"].state == "trusted" and t.n["x"].withheld == 0.0


def test_without_a_hold_the_weight_falls_only_with_the_score():
    target = mix((0.95, A, P4))
    t = Trust(TrustConfig(detection_probability=0.99, withhold_hold=None), ("h", "x"))
    w = [t.weigh(k, 0, target, {"h": target, "x": EMPTY}, [1 / 3] * 3)[2] for k in (1, 2)]
    assert w[1] > 0.1 / 3 and t.n["x"].holds == 0


def test_a_late_or_reused_estimate_adds_no_increment_and_quarantined_ones_are_no_reference():
    cfg = TrustConfig(detection_probability=0.99)
    per = min(np.log(0.99 / 0.01) * 0.95, cfg.withhold_cap)
    target = mix((0.95, A, P4))
    t = Trust(cfg, ("h", "x"))
    t.weigh(1, 0, target, {"h": target, "x": EMPTY}, [1 / 3, 1 / 3, 1 / 3])
    assert t.n["x"].withheld == pytest.approx(per)
    # scan 2: x's input is its scan-1 estimate again (late): no new evidence
    t.weigh(2, 0, target, {"h": target, "x": EMPTY}, [1 / 3, 1 / 3, 1 / 3],
            late={"x": (1, EMPTY)})
    assert t.n["x"].withheld == pytest.approx(per)
    # a quarantined neighbour is no reference: x empty against own empty alone adds 0, and
    # h's targets (h quarantined) do not count against it
    t.n["h"].state = "quarantined"
    t.weigh(3, 0, EMPTY, {"h": target, "x": EMPTY}, [1 / 3, 1 / 3, 1 / 3])
    assert t.n["x"].withheld == pytest.approx(per)


def test_whole_losses_and_their_runs_are_counted_for_the_calibration():
    from collections import Counter

    from sensornet.peers.trust_checks import whole_losses

    targets = np.array([0.9, 0.0, 0.0, 1.2, 0.0])
    refs = ~np.eye(5, dtype=bool)
    refs[2] = refs[3] = [True, False, False, False, False]  # inputs 2, 3: own alone
    refs[4, 0] = False  # input 4: references 1, 2, 3, median 0
    got = whole_losses(targets, refs, 0.5)
    # 1: median of (0.9, 0, 1.2, 0) = 0.45 < 0.5, not compared; 2: own's 0.9, lost;
    # 3: shows 1.2 against own's 0.9; 4: median of (0, 0, 1.2) = 0, not compared
    np.testing.assert_array_equal(got, [np.nan, np.nan, 1.0, 0.0, np.nan])
    t = Trust(TrustConfig(detection_probability=0.99), ("h", "x"))
    t.losses = Counter()
    target = mix((0.95, A, P4))
    for k in range(1, 10):  # x loses everything at scans 2-3 and 5-7, own too at scan 6
        x = EMPTY if k in (2, 3, 5, 6, 7) else target
        t.weigh(k, 0, EMPTY if k == 6 else target, {"h": target, "x": x},
                [1 / 3, 1 / 3, 1 / 3])
    # compared (the smaller of two references at least 0.5): h at scans 1, 4, 8, 9 (else
    # x or own empty), x at every scan but 6 (own empty); x's runs: 2-3 and 5, 7 (scan 6
    # not compared, so no break), two scans each
    assert t.losses == Counter({"compared": 4 + 8, "lost": 4, 2: 2})


def test_the_reference_rule_is_the_median_of_three_or_more_else_the_smallest():
    """:func:`over_references` (shared by the withheld increments and the whole losses)
    against the rule computed reference by reference."""
    from sensornet.peers.trust_checks import over_references

    rng = np.random.default_rng(5)
    for _ in range(300):
        n = int(rng.integers(1, 8))
        V, R = rng.normal(size=(n, n)), rng.random((n, n)) < 0.6
        got = over_references(V, R)
        for j in range(n):
            r = np.flatnonzero(R[j])
            if len(r) == 0:
                assert np.isnan(got[j])
            else:
                want = np.median(V[r, j]) if len(r) >= 3 else V[r, j].min()
                assert got[j] == pytest.approx(want)


def test_the_calibration_refuses_a_setting_the_scenario_refuses():
    from sensornet.sim.studies.lying.trust_calibration import main

    with pytest.raises(SystemExit) as e:
        main(["--runs", "1", "--set", "fusion.trust_register=False"])
    assert e.value.code == 2
