"""Chi-square CDF and quantiles in closed form, against scipy (the peer) and hard cases."""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy.special import gammainc, gammaincinv

from scanmap.registration.chi_square import chi_square_cdf, chi_square_quantile


@given(x=st.floats(0.0, 400.0), dof=st.integers(1, 12))
def test_cdf_matches_scipy(x, dof):
    assert chi_square_cdf(x, dof) == pytest.approx(gammainc(0.5 * dof, 0.5 * x), abs=1e-12)


@given(level=st.floats(1e-6, 1.0 - 1e-9), dof=st.integers(1, 12))
def test_quantile_matches_scipy(level, dof):
    expected = 2.0 * gammaincinv(0.5 * dof, level)
    assert chi_square_quantile(level, dof) == pytest.approx(expected, rel=1e-9, abs=1e-12)


def test_textbook_values():
    """95 % points of the chi-square tables: 3.841, 5.991, 7.815, 12.592 (dof 1, 2, 3, 6)."""
    for dof, value in ((1, 3.841459), (2, 5.991465), (3, 7.814728), (6, 12.591587)):
        assert chi_square_quantile(0.95, dof) == pytest.approx(value, abs=1e-6)


def test_hard_inputs():
    assert chi_square_cdf(-1.0, 3) == 0.0
    assert chi_square_cdf(math.inf, 3) == 1.0
    assert chi_square_quantile(0.0, 3) == 0.0 == 2.0 * gammaincinv(1.5, 0.0)
    assert chi_square_quantile(1.0, 3) == math.inf == 2.0 * gammaincinv(1.5, 1.0)
    for level, dof in ((-0.1, 3), (1.1, 3), (math.nan, 3), (0.5, 0), (1.0, 0)):
        with pytest.raises(ValueError):
            chi_square_quantile(level, dof)
