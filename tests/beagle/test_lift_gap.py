"""LiftGapEstimator: the seed's interpolation of counts lost while the sensor was lifted.

A gap of G lifted polls between a good poll with counts ``a`` and the good poll
after it with counts ``b`` is estimated as G * (a + b) / 2 (linear
interpolation, poll k of the gap = a + (b - a) * k / (G + 1)); the estimate
comes out with the poll that closes the gap, and never without a gap.
"""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mm_beagle.lift_gap import LiftGapEstimator


def feed(est: LiftGapEstimator, polls: list[tuple[int, int, bool]]) -> list:
    return [est.update(dx, dy, lifted) for dx, dy, lifted in polls]


def test_no_gap_no_estimate():
    est = LiftGapEstimator()
    out = feed(est, [(5, -3, False), (0, 0, False), (7, 9, False), (-2, 4, False)])
    assert out == [None, None, None, None]


def test_lifted_polls_give_no_estimate_until_the_gap_closes():
    est = LiftGapEstimator()
    out = feed(est, [(10, 20, False), (0, 0, True), (0, 0, True), (0, 0, True)])
    assert out == [None, None, None, None]
    assert est.update(14, 28, False) == pytest.approx((3 * 12.0, 3 * 24.0))
    # closed: the next good poll estimates nothing
    assert est.update(14, 28, False) is None


@pytest.mark.parametrize("gap", [1, 2, 3, 7, 25, 500])
@pytest.mark.parametrize(("a", "b"), [((10, 20), (14, 28)), ((-6, 3), (-2, 9)), ((0, 0), (5, -5))])
def test_closed_form_for_several_gap_lengths(gap, a, b):
    est = LiftGapEstimator()
    assert est.update(99, 99, False) is None  # an older poll does not matter
    assert est.update(*a, False) is None
    for _ in range(gap):
        assert est.update(0, 0, True) is None
    got = est.update(*b, False)
    assert got == (gap * (a[0] + b[0]) / 2.0, gap * (a[1] + b[1]) / 2.0)


def test_counts_reported_by_a_lifted_poll_do_not_enter_the_interpolation():
    # The lifted poll's own counts are measured (the poller adds them to the
    # totals); the estimate interpolates between the good polls around the gap.
    est = LiftGapEstimator()
    est.update(4, 8, False)
    est.update(100, 100, True)
    assert est.update(6, 10, False) == (5.0, 9.0)


def test_two_gaps_use_the_good_poll_between_them():
    est = LiftGapEstimator()
    out = feed(
        est,
        [(2, 2, False), (0, 0, True), (4, 6, False), (0, 0, True), (0, 0, True), (8, 10, False)],
    )
    assert out == [None, None, (3.0, 4.0), None, None, (12.0, 16.0)]


@settings(max_examples=300, deadline=None)
@given(
    c0=st.integers(-2000, 2000),
    slope=st.integers(-50, 50),
    before=st.integers(1, 40),
    gap=st.integers(1, 60),
    after=st.integers(1, 40),
)
def test_linear_ramp_estimate_is_exact(c0, slope, before, gap, after):
    """Integer counts ramping linearly: the estimate is exactly the lost sum."""
    n = before + gap + after
    true = [c0 + slope * k for k in range(n)]
    est = LiftGapEstimator()
    estimates = []
    for k, c in enumerate(true):
        lifted = before <= k < before + gap
        r = est.update(0 if lifted else c, 0 if lifted else -c, lifted)
        if r is not None:
            estimates.append((k, r))
    lost = sum(true[before : before + gap])
    assert len(estimates) == 1
    k, (ex, ey) = estimates[0]
    assert k == before + gap  # known with the poll that closes the gap
    assert ex == lost
    assert ey == -lost


@settings(max_examples=300, deadline=None)
@given(
    v0=st.floats(-300.0, 300.0),
    accel=st.floats(-2.0, 2.0),
    before=st.integers(1, 40),
    gap=st.integers(1, 60),
    after=st.integers(1, 40),
)
def test_real_valued_ramp_estimate_within_rounding(v0, accel, before, gap, after):
    """A real speed ramp read as whole counts (floor of the cumulative position).

    Per-poll counts are then the true ramp +-1, so the estimate of a gap of G
    polls is within G counts of the truth (plus the truth's own rounding).
    """
    import math

    n = before + gap + after
    pos = [v0 * k + accel * k * k / 2 for k in range(n + 1)]  # cumulative counts
    counts = [math.floor(pos[k + 1]) - math.floor(pos[k]) for k in range(n)]
    est = LiftGapEstimator()
    result = None
    for k, c in enumerate(counts):
        lifted = before <= k < before + gap
        r = est.update(0 if lifted else c, 0, lifted)
        if r is not None:
            result = r
    assert result is not None
    true_lost = pos[before + gap] - pos[before]  # exact, real-valued
    assert abs(result[0] - true_lost) <= gap + 1 + 1e-6 * abs(true_lost)
