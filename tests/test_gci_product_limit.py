"""gci_product's size guard: beyond ``limit`` combinations (default MAX_COMBINATIONS) a one-line
ValueError naming the count, instead of forming them all (a script of 9 overlapping densities of
10 components asked for 10^9 combinations and ran out of memory)."""

from __future__ import annotations

import numpy as np
import pytest
from sensornet.tracking.fusion import NARY_MAX_COMBINATIONS, gci_fuse
from sensornet.tracking.gci_product import MAX_COMBINATIONS, gci_product
from sensornet.tracking.mixture import GaussianMixture
from sensornet.tracking.reduction import Reducer


def overlapping(rng, n, k, spread=1.0):
    """``n`` densities of ``k`` components all within a few sigma: the gate drops nothing."""
    return [GaussianMixture(rng.uniform(0.5, 1.0, k), rng.normal(size=(k, 4)) * spread,
                            np.tile(np.eye(4) * 100.0, (k, 1, 1))) for _ in range(n)]


@pytest.mark.parametrize("gate", [True, False])
def test_too_many_combinations_is_a_one_line_error_naming_the_count(gate):
    dens = overlapping(np.random.default_rng(0), 9, 10)  # 10^9 combinations
    with pytest.raises(ValueError) as err:
        gci_product(dens, [1 / 9] * 9, gate=gate)
    msg = str(err.value)
    assert "\n" not in msg and f"{MAX_COMBINATIONS:,}" in msg
    # the gate stops at the first density whose kept combinations pass the limit (10^6 at
    # the 6th); without it the count is every combination
    assert ("1,000,000 combinations of the first 6 densities" if gate
            else "1,000,000,000 combinations to form") in msg


def test_limit_is_the_bound_and_below_it_nothing_changes():
    rng = np.random.default_rng(1)
    dens = overlapping(rng, 3, 10)  # 1,000 combinations, all kept by the gate
    full = gci_product(dens, [0.2, 0.3, 0.5], gate=True)
    assert len(full) == 1000
    same = gci_product(dens, [0.2, 0.3, 0.5], gate=True, limit=1000)
    assert np.array_equal(full.weights, same.weights) and np.array_equal(full.covs, same.covs)
    with pytest.raises(ValueError, match="1,000 combinations of the first 3 densities"):
        gci_product(dens, [0.2, 0.3, 0.5], gate=True, limit=999)
    with pytest.raises(ValueError, match="1,000 combinations to form"):
        gci_product(dens, [0.2, 0.3, 0.5], limit=999)


def test_gate_that_drops_enough_passes_a_limit_below_the_full_count():
    """Far-apart targets: 10^4 combinations, the gate keeps ~10, so a limit of 100 is met."""
    rng = np.random.default_rng(2)
    targets = rng.uniform(-1e4, 1e4, size=(10, 4))
    dens = [GaussianMixture(np.full(10, 0.9), targets + rng.normal(size=(10, 4)),
                            np.tile(np.eye(4) * 25.0, (10, 1, 1))) for _ in range(4)]
    out = gci_product(dens, [0.25] * 4, gate=True, limit=100)
    assert 10 <= len(out) <= 100


def test_gci_fuse_never_asks_for_more_than_its_own_bound():
    """The precondition the fusers rely on: gci_fuse's one-step product has at most
    NARY_MAX_COMBINATIONS (below the limit); 9 overlapping densities go in steps."""
    assert NARY_MAX_COMBINATIONS < MAX_COMBINATIONS
    dens = overlapping(np.random.default_rng(3), 9, 10)
    out = gci_fuse(dens, [1 / 9] * 9, reduce=Reducer())
    assert 0 < len(out) <= 100 and np.isfinite(out.weights).all()
