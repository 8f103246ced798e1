"""tracking.chi2: the chi-square quantiles peers use equal scipy.stats' (the reference)."""

import numpy as np
import pytest
from scipy.stats import chi2
from sensornet.tracking.chi2 import chi2_isf, chi2_ppf


@pytest.mark.parametrize("dof", [1, 2, 3, 4, 6, 10, 37])
def test_quantiles_equal_scipy_stats(dof):
    for p in np.r_[1e-9, 1e-4, np.linspace(0.01, 0.99, 25), 0.9999, 1 - 1e-9]:
        assert chi2_ppf(p, dof) == pytest.approx(chi2.ppf(p, dof), rel=1e-10, abs=1e-12)
        assert chi2_isf(p, dof) == pytest.approx(chi2.isf(p, dof), rel=1e-10, abs=1e-12)


def test_bad_arguments_are_one_line_errors():
    with pytest.raises(ValueError, match="dof > 0"):
        chi2_ppf(0.5, 0)
    with pytest.raises(ValueError, match="0 <= q <= 1"):
        chi2_isf(1.5, 2)
