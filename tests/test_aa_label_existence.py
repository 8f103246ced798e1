"""Per-label existence over the AA rule's copies (``lmb.aa_label_existence``, issue 33,
docs/labelled-tracking.md "Per-label existence over the AA copies"): an AA-fused density keeps
each input's component of a target at weight ``w_i r_i`` (a copy), so a target three inputs
hold at 0.9 is three rows at 0.3 and an existence test per row (``lmb.fused_extraction``
``"round"``) drops it. Li 2022's AA of LMB densities is per label, ``r(l) = sum_i w_i r_i(l)``:
the copies' existence summed onto the labelled row reports the target once at 0.9."""

from __future__ import annotations

import numpy as np
import pytest
from sensornet.peers.consensus import Consensus
from sensornet.peers.consensus_types import ConsensusOptions
from sensornet.peers.contracts import FusionInput
from sensornet.peers.fusers import AaFuser, GciFuser, HybridFuser
from sensornet.peers.labelling import copy_keepers, label_fused
from sensornet.sim.kinds import kind
from sensornet.sim.kinds.lmb import aa_label_existence
from sensornet.sim.scenario import ScenarioError, load_scenario
from sensornet.tracking.fusion_rules import aa_fuse, aa_label_density
from sensornet.tracking.mixture import GaussianMixture
from sensornet.tracking.reduction import Reducer

LMB = {"network.filter": "lmb"}
L = np.array([[0, 2, 7]])  # the target's network label
K = 20
VAR = 400.0  # 20 m position sd


def _mix(xs, r, var=VAR):
    m = np.zeros((len(xs), 4))
    m[:, 0] = xs
    return GaussianMixture(np.asarray(r, float), m, np.tile(np.eye(4) * var, (len(xs), 1, 1)))


def _three_inputs():
    """One target at three inputs (own first), r = 0.9 each, all labelled L, at x = 0, 60 and
    -60 m (3 sd apart: ``Reducer()`` merges none of them; within the label gate): AA at 1/3
    each keeps three copies at 0.3."""
    inputs = [(_mix([x], [0.9]), L) for x in (0.0, 60.0, -60.0)]
    fused = aa_fuse([m for m, _ in inputs], [1 / 3] * 3, Reducer())
    return inputs, fused


def _peer(fuser, scn_over=None):
    est, _ = kind("lmb").build(load_scenario("seed000", {**LMB, **(scn_over or {})}), "s1", 0)
    return Consensus(ConsensusOptions("s1", ("s2", "s3"), (("s1", 2), ("s2", 2), ("s3", 2))),
                     est, fuser)


def _reported(fuser, fused, labels, copies):
    """The Tracks message of :meth:`Consensus._tracks` for ``fused`` (the fused rule:
    ``lmb.fused_extraction`` auto, ``"round"`` under AA and hybrid)."""
    (msg,) = _peer(fuser)._tracks(K, fused, 0.0, labels, None, copies)
    return msg


def test_three_copies_at_a_third_are_reported_once_at_their_sum():
    inputs, fused = _three_inputs()
    np.testing.assert_allclose(fused.weights, [0.3, 0.3, 0.3])
    out = label_fused(fused, inputs, origin=1, k=K, copies=True)
    assert out.copies.sum() == 2  # two rows lost L to the first (equal weights: stable order)
    keeper = np.flatnonzero(~out.copies)
    assert len(keeper) == 1 and (out.labels[keeper[0]] == L[0]).all()
    np.testing.assert_array_equal(copy_keepers(fused, out.copies), np.full(3, keeper[0]))

    off = _reported(AaFuser(Reducer()), fused, out.labels, out.copies)
    assert len(off.states) == 0  # the bug: every copy under 0.5
    for state, x in (("mean", 0.0), ("heaviest", fused.means[keeper[0], 0])):
        fuser = AaFuser(Reducer())
        fuser.label_state = state
        msg = _reported(fuser, fused, out.labels, out.copies)
        assert len(msg.states) == 1
        assert msg.existence[0] == pytest.approx(0.9, abs=1e-12)
        assert (msg.ids[0] == L[0]).all()
        assert msg.states[0, 0] == pytest.approx(x, abs=1e-9)
    fuser.label_state = "mean"
    cov = _reported(fuser, fused, out.labels, out.copies).covs[0]
    assert cov[0, 0] == pytest.approx(VAR + (60.0**2 * 2) / 3, abs=1e-9)  # the spread added


def test_two_labels_are_never_summed():
    """Two targets 5 km apart, each at three inputs: no copy lies within the gate of the other
    target's row, so each label keeps its own 0.9."""
    L2 = np.array([[0, 3, 1]])
    inputs = [(_mix([x, 5000.0 + x], [0.9, 0.9]), np.vstack([L, L2])) for x in (0, 60, -60)]
    fused = aa_fuse([m for m, _ in inputs], [1 / 3] * 3, Reducer())
    out = label_fused(fused, inputs, origin=1, k=K, copies=True)
    groups = copy_keepers(fused, out.copies)
    near = fused.means[:, 0] < 2500
    assert len(set(groups[near])) == 1 and len(set(groups[~near])) == 1
    assert groups[near][0] != groups[~near][0]
    w, _, _ = aa_label_density(fused.weights, fused.means, fused.covs, groups)
    np.testing.assert_allclose(np.sort(w)[-2:], [0.9, 0.9])
    # a row that is no copy is never summed, even beside another: not a label's copy
    none = np.zeros(len(fused), dtype=bool)
    np.testing.assert_array_equal(copy_keepers(fused, none), np.arange(len(fused)))
    fuser = AaFuser(Reducer())
    fuser.label_state = "mean"
    msg = _reported(fuser, fused, out.labels, out.copies)
    assert len(msg.states) == 2
    np.testing.assert_allclose(msg.existence, [0.9, 0.9], atol=1e-12)
    assert {tuple(i) for i in msg.ids} == {tuple(L[0]), tuple(L2[0])}


def test_the_sum_is_capped_at_one_and_a_lighter_row_is_no_keeper():
    w, m, P = aa_label_density(np.array([0.7, 0.6, 0.2]), np.zeros((3, 4)),
                               np.tile(np.eye(4), (3, 1, 1)), np.array([0, 0, 2]))
    np.testing.assert_allclose(w, [1.0, 0.0, 0.2])
    mix = _mix([0.0, 10.0], [0.2, 0.5])
    # the copy (row 1) is heavier than the only other row: it stays its own
    np.testing.assert_array_equal(copy_keepers(mix, np.array([False, True])), [0, 1])


@pytest.mark.parametrize("fuser", [HybridFuser(Reducer()), GciFuser(Reducer())])
def test_hybrid_and_gci_are_unchanged(fuser):
    """They give no copies (FusedLabels.copies None) and carry no label_state: each row by its
    own weight, as before."""
    inputs, fused = _three_inputs()
    assert label_fused(fused, inputs, origin=1, k=K).copies is None
    labels = label_fused(fused, inputs, origin=1, k=K).labels
    assert getattr(fuser, "label_state", None) is None
    assert len(_reported(fuser, fused, labels, None).states) == 0
    for rule in ("hybrid", "gci"):
        scn = load_scenario("seed000", {**LMB, "fusion.rule": rule,
                                        "lmb.aa_label_existence": "mean"})
        _, built = kind("lmb").build(scn, "s1", 0)
        assert getattr(built, "label_state", None) is None


def test_the_option_reaches_the_aa_fuser():
    for value, want in (("auto", "mean"), ("off", None), ("mean", "mean"),
                        ("heaviest", "heaviest")):
        scn = load_scenario("seed000", {**LMB, "fusion.rule": "aa",
                                        "lmb.aa_label_existence": value})
        assert aa_label_existence(scn) == want
        _, fuser = kind("lmb").build(scn, "s1", 0)
        assert isinstance(fuser, AaFuser) and fuser.label_state == want
    assert AaFuser(Reducer()).label_state is None  # another AaFuser is not changed


def test_bad_input_is_a_one_line_error():
    with pytest.raises(ScenarioError, match="aa_label_existence") as e:
        load_scenario("seed000", {**LMB, "lmb.aa_label_existence": "sum"})
    assert "\n" not in str(e.value)
    one = (np.ones(2), np.zeros((2, 4)), np.tile(np.eye(4), (2, 1, 1)))
    with pytest.raises(ValueError, match="state"):
        aa_label_density(*one, np.array([0, 1]), state="median")
    with pytest.raises(ValueError, match="own group"):
        aa_label_density(*one, np.array([1, 0]))  # row 1's group is a copy
    with pytest.raises(ValueError, match="rows"):
        aa_label_density(*one, np.array([0]))
    with pytest.raises(ValueError, match="copies"):
        copy_keepers(_mix([0.0], [0.5]), np.array([True, False]))


def test_the_mature_cap_keeps_the_fusers_weights_as_its_prior():
    """``fusion.existence_mature`` pools a mature row's inputs about its last fused weight, an
    input with no mass at the row counting at ``existence_absent``. Four inputs at 1/4: own and
    s2 at x = 0 (one row, 0.5 r), s3 and s4 at +-60 m (copies, 0.25 r each), r = 0.999. Summed
    before the cap, the remembered weight was the label's 0.999, and the two inputs whose mass
    sits on the copies pulled the pooled existence about that prior to ~0: the target was
    dropped every scan after its first (circ20 training run 100: per-scan OSPA 38.7 -> 44.8 m).
    With the fuser's 0.5 as the prior it is reported at 0.999."""
    r = 0.999
    own, s2, s3, s4 = _mix([0.0], [r]), _mix([0.0], [r]), _mix([60.0], [r]), _mix([-60.0], [r])
    mixes = [own, s2, s3, s4]
    fused = aa_fuse(mixes, [0.25] * 4, Reducer())
    np.testing.assert_allclose(np.sort(fused.weights), [0.25 * r, 0.25 * r, 0.5 * r])
    out = label_fused(fused, [(m, L) for m in mixes], origin=1, k=K, copies=True)
    assert out.copies.sum() == 2
    est, _ = kind("lmb").build(load_scenario("seed000", LMB), "s1", 0)
    fuser = AaFuser(Reducer())
    fuser.label_state = "mean"
    peer = Consensus(ConsensusOptions("s1", ("s2", "s3", "s4"), existence_mature=0.99,
                                      existence_absent=0.05), est, fuser)
    inp = {k: FusionInput(k, 0, own, {"s2": {"posterior": s2}, "s3": {"posterior": s3},
                                      "s4": {"posterior": s4}}, [0.25] * 4, np.zeros((0, 2)))
           for k in (K, K + 1, K + 2)}
    for k in (K, K + 1, K + 2):
        (msg,) = peer._tracks(k, fused, 0.0, out.labels, inp[k], out.copies)
        assert len(msg.states) == 1, k
        assert msg.existence[0] == pytest.approx(r, abs=1e-9)
