"""The one angle wrap (pln2033.angles), which the OTOS driver and mm_pc.core.angles use."""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from pln2033.angles import TWO_PI, wrap_pi


def test_both_edges_and_values_in_range_kept():
    assert wrap_pi(math.pi) == math.pi
    assert wrap_pi(-math.pi) == math.pi
    assert wrap_pi(3 * math.pi) == pytest.approx(math.pi)
    assert wrap_pi(-3 * math.pi) == pytest.approx(math.pi)
    assert wrap_pi(-0.1) == -0.1  # fmod is exact: an angle in range comes back unchanged
    assert wrap_pi(math.nextafter(-math.pi, 0.0)) == math.nextafter(-math.pi, 0.0)
    assert wrap_pi(2 * math.pi + 0.1) == pytest.approx(0.1)
    assert wrap_pi(0) == 0.0 and wrap_pi(-1e-300) == -1e-300


@given(st.floats(-1e6, 1e6))
def test_result_in_range_and_the_same_direction(a):
    w = wrap_pi(a)
    assert -math.pi < w <= math.pi
    assert math.remainder(w - a, TWO_PI) == pytest.approx(0.0, abs=1e-9 * max(1.0, abs(a)))


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_non_finite_is_refused(bad):
    with pytest.raises(ValueError, match="finite"):
        wrap_pi(bad)
