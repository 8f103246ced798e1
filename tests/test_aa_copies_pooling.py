"""AA copies are not pooled as young tracks (issue 33, docs/labelled-tracking.md "AA regression
traced and fixed"): an AA fused density keeps a target's copies, the lighter copy takes a fresh
label every scan (peers.labelling.label_fused ``copies``), and the pooled existence of young
tracks (tracking.support.pooled_weights) took that fresh label for a young target's: held by
two inputs, it was pooled to ~1 and reported instead of the target's labelled row, then the
label flipped back (circ20 training run 100: 277 of 438 pooled rows were such copies)."""

import numpy as np
from sensornet.peers.labelling import FRESH_BASE, copy_rows, label_fused
from sensornet.tracking.fusion_rules import aa_fuse
from sensornet.tracking.gmphd import extract_index
from sensornet.tracking.mixture import GaussianMixture
from sensornet.tracking.reduction import Reducer
from sensornet.tracking.support import input_mass, pooled_weights

L = np.array([[0, 2, 7]])  # the target's network label, a shared stamp of scan 2
K = 20  # the scan: L is old, a fresh label of scan 20 is "young"


def _mix(xs, r, var=400.0):
    m = np.zeros((len(xs), 4))
    m[:, 0] = xs
    return GaussianMixture(np.asarray(r, float), m, np.tile(np.eye(4) * var, (len(xs), 1, 1)))


def _case():
    """One confirmed target at five inputs (own first, r 0.8 each, all labelled L): own and
    the first neighbour at x = 0, the other three at x = 60 m (3 standard deviations: the
    scenario's reducer, U = 5, does not merge them; within the label gate). AA with weights
    0.3, 0.3 and 0.4 / 3 each keeps two copies, 0.48 at 0 and 0.32 at 60 m: both below 0.5."""
    xs = [0.0, 0.0, 60.0, 60.0, 60.0]
    inputs = [(_mix([x], [0.8]), L) for x in xs]
    fused = aa_fuse([m for m, _ in inputs], [0.3, 0.3] + [0.4 / 3] * 3, Reducer())
    return inputs, fused


def test_the_lighter_aa_copy_is_marked_and_not_pooled():
    inputs, fused = _case()
    np.testing.assert_allclose(np.sort(fused.weights), [0.32, 0.48])
    out = label_fused(fused, inputs, origin=3, k=K, copies=True)
    heavy = fused.weights.argmax()
    assert (out.labels[heavy] == L[0]).all()
    lost = np.flatnonzero(~(out.labels == L[0]).all(axis=1))
    assert len(lost) == 1 and (out.labels[lost, 2] >= FRESH_BASE).all()
    assert (out.labels[lost, 1] == K).all()  # "young": a fresh label of this scan
    want = np.zeros(len(fused), dtype=bool)
    want[lost] = True
    np.testing.assert_array_equal(out.copies, want)
    assert label_fused(fused, inputs, origin=3, k=K).copies is None  # hybrid / GCI: no mask

    mixes = [m for m, _ in inputs]
    mass = input_mass(fused.means, mixes)
    plain = pooled_weights(fused, out.labels, K, mass, prior=0.01, young=2)
    fixed = pooled_weights(fused, out.labels, K, mass, prior=0.01, young=2, skip=out.copies)

    def reported(w):
        idx = extract_index(GaussianMixture(w, fused.means, fused.covs), 0.5, "cardinality")
        return out.labels[idx]

    # without the skip a copy (held by the three inputs at 60 m) is pooled to ~1 and
    # reported under its fresh label; the target's row, labelled L, is not reported
    assert plain[lost].max() > 0.99
    assert (reported(plain)[:, 2] >= FRESH_BASE).all()
    # with it nothing is pooled (L is old) and the target is reported once, as L
    np.testing.assert_array_equal(fixed, fused.weights)
    np.testing.assert_array_equal(reported(fixed), L)


def test_a_young_target_is_still_pooled_with_the_copies_marked():
    """A young target (L stamped at this scan) held weakly by three inputs in one merged row:
    no copy, so the pool lifts it as before the fix."""
    young = np.array([[0, K, 7]])
    inputs = [(_mix([0.0], [0.3]), young) for _ in range(3)]
    fused = aa_fuse([m for m, _ in inputs], [1 / 3] * 3, Reducer())
    assert len(fused) == 1
    out = label_fused(fused, inputs, origin=3, k=K, copies=True)
    assert not out.copies.any()
    mass = input_mass(fused.means, [m for m, _ in inputs])
    w = pooled_weights(fused, out.labels, K, mass, prior=0.01, young=2, skip=out.copies)
    assert w[0] > 0.99 > fused.weights[0]


def test_copy_rows_by_hand():
    """Rows 1 and 2 lost their label to row 0: row 1 within the gate (a copy), row 2 not (a
    second target, released); row 3 won its own; row 4 paired with nothing."""
    fused = _mix([0.0, 30.0, 3000.0, 6000.0, 9000.0], [0.5, 0.3, 0.2, 0.9, 0.4])
    J = np.array([0, 1, 2, 3])
    won = np.array([True, False, False, True, False])
    keeper = np.array([0, 0, 0, 3, 4])
    np.testing.assert_array_equal(copy_rows(fused, J, won, keeper, 26.0),
                                  [False, True, False, False, False])
