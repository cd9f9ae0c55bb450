"""LiftGapEstimator and pln2033.lift_fill: counts lost while lifted, from windows of polls.

The mean of up to WINDOW (20) good polls each side of a gap, a straight line between
the window centres; the streaming estimator (the board's) gives exactly what the
offline rule (the PC's) gives for the same polls, and a 1-sigma uncertainty.
"""

from __future__ import annotations

import math
import random

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mm_beagle.poller.lift_gap import WINDOW, LiftGapEstimator
from pln2033.lift_fill import fill_gap, fill_sequence, gap_runs


def feed(est: LiftGapEstimator, polls: list[tuple[int, int, bool]]) -> list:
    return [est.update(dx, dy, lifted) for dx, dy, lifted in polls]


def stream(values: list[float], lifted: list[bool], window: int = WINDOW) -> list:
    """(index, estimate) of every gap the streaming estimator closes, fed one axis."""
    est = LiftGapEstimator(window)
    out = []
    for k, (v, f) in enumerate(zip(values, lifted, strict=True)):
        r = est.update(0 if f else v, 0, f)
        if r is not None:
            out.append((k, r))
    return out


def test_window_is_twenty_polls():
    assert WINDOW == 20


def test_no_gap_no_estimate_and_not_busy():
    est = LiftGapEstimator()
    assert feed(est, [(5, -3, False), (0, 0, False), (7, 9, False)]) == [None] * 3
    assert not est.busy


def test_estimate_comes_when_the_after_window_is_full():
    est = LiftGapEstimator()
    out = feed(est, [(10, 20, False)] * 30 + [(0, 0, True)] * 5)
    assert out == [None] * 35 and est.busy and est.gap == 5
    out = feed(est, [(10, 20, False)] * (WINDOW - 1))
    assert out == [None] * (WINDOW - 1) and est.busy
    x, y, sx, sy = est.update(10, 20, False)
    assert (x, y) == pytest.approx((50.0, 100.0)) and sy == sx
    # the remainder term only (both rates equal): 5 polls, windows of 20 each side
    assert sx == pytest.approx(5 * math.sqrt((0.5**2 + 0.5**2) / 20**2 / 6))
    assert not est.busy
    assert est.update(10, 20, False) is None


def test_one_poll_each_side_is_the_seeds_interpolation():
    # windows of 1 poll: a + (b - a) * k / (G + 1), so G * (a + b) / 2
    f = fill_gap(2.0, 1, 3, 10.0, 1)
    assert f.per_poll() == pytest.approx([4.0, 6.0, 8.0])
    assert f.total == pytest.approx(18.0)


def test_window_rounding_is_averaged_not_multiplied():
    """Constant 0.3 counts/poll read as whole counts: the one-poll rule is off by up to
    G counts, the 20-poll windows by a few tenths."""
    rate, gap = 0.3, 400
    n = 100 + gap + 100
    pos = [rate * k for k in range(n + 1)]
    counts = [math.floor(pos[k + 1]) - math.floor(pos[k]) for k in range(n)]
    lifted = [100 <= k < 100 + gap for k in range(n)]
    true_lost = rate * gap
    one = fill_gap(counts[99], 1, gap, counts[100 + gap], 1).total
    win = stream(counts, lifted)[0][1]
    assert abs(one - true_lost) > 50  # 0 and 1 around the gap: 200 or 0 counts
    assert abs(win[0] - true_lost) < 3 * win[2]
    assert win[2] < 8.0  # the means differ by 1/20: G * 0.05 / sqrt(12)


def test_gap_at_the_start_holds_the_rate_after_with_a_wide_sigma():
    values = [0.0] * 10 + [4.0] * 30
    lifted = [True] * 10 + [False] * 30
    filled, gaps = fill_sequence(values, lifted)
    assert filled[:10] == [4.0] * 10
    ((start, f),) = gaps
    assert start == 0 and f.total == 40.0
    assert f.sigma == pytest.approx(math.sqrt((10 / 20) ** 2 / 6 + 40.0**2 / 12))
    ((k, (x, _, sx, _)),) = stream(values, lifted)
    assert k == 29 and x == 40.0 and sx == pytest.approx(f.sigma)


def test_gap_shorter_than_the_window_and_windows_shorter_than_twenty():
    values = [2.0] * 5 + [0.0] * 3 + [8.0] * 5
    lifted = [False] * 5 + [True] * 3 + [False] * 5
    filled, ((start, f),) = fill_sequence(values, lifted)
    assert start == 5
    # centres at -2 and 3 + 1 + 2 = 6 (gap polls 1..3): slope 6 / 8 per poll
    assert filled[5:8] == pytest.approx([2 + 0.75 * 3, 2 + 0.75 * 4, 2 + 0.75 * 5])
    assert f.total == pytest.approx(sum(filled[5:8]))


def test_a_second_lift_inside_the_after_window_closes_the_first_gap():
    values = [1.0] * 30 + [0.0] * 4 + [3.0] * 6 + [0.0] * 2 + [3.0] * 30
    lifted = [False] * 30 + [True] * 4 + [False] * 6 + [True] * 2 + [False] * 30
    got = stream(values, lifted)
    assert [k for k, _ in got] == [40, 61]  # the first with the second lift's first poll
    _, gaps = fill_sequence(values, lifted)
    assert [s for s, _ in gaps] == [30, 40]
    for (_, est), (_, f) in zip(got, gaps, strict=True):
        assert est[0] == pytest.approx(f.total) and est[2] == pytest.approx(f.sigma)
    # the second gap's before-window is the 6 polls between the lifts only
    assert gaps[1][1].total == pytest.approx(6.0)


def test_counts_reported_by_a_lifted_poll_do_not_enter_the_estimate():
    est = LiftGapEstimator(window=1)
    est.update(4, 8, False)
    est.update(100, 100, True)
    x, y, _, _ = est.update(6, 10, False)
    assert (x, y) == (5.0, 9.0)


def test_prime_replaces_the_before_window():
    est = LiftGapEstimator(window=2)
    est.prime([(1, 1), (3, 3)])
    est.update(0, 0, True)
    est.update(5, 5, False)
    x, _, _, _ = est.update(5, 5, False)
    # centres -0.5 and 2.5, means 2 and 5
    assert x == pytest.approx(2 + 3 * 1.5 / 3)


def test_all_lifted_and_gap_runs():
    filled, ((_, f),) = fill_sequence([3.0, 3.0], [True, True])
    assert filled == [0.0, 0.0] and f.sigma == math.inf
    assert gap_runs([False, True, True, False, True]) == [(1, 3), (4, 5)]
    with pytest.raises(ValueError, match="2 values but 1 lift"):
        fill_sequence([1.0, 2.0], [True])
    with pytest.raises(ValueError, match=">= 1 poll"):
        LiftGapEstimator(window=0)


@settings(max_examples=200, deadline=None)
@given(
    c0=st.integers(-2000, 2000),
    slope=st.integers(-50, 50),
    before=st.integers(1, 40),
    gap=st.integers(1, 60),
    after=st.integers(WINDOW, 40),
)
def test_linear_ramp_estimate_is_exact(c0, slope, before, gap, after):
    """Integer counts ramping linearly: the window means lie on the line, so exact."""
    n = before + gap + after
    true = [c0 + slope * k for k in range(n)]
    lifted = [before <= k < before + gap for k in range(n)]
    ((k, (ex, _, _, _)),) = stream([float(v) for v in true], lifted)
    assert k == before + gap + WINDOW - 1
    assert ex == pytest.approx(sum(true[before : before + gap]), abs=1e-6)


@settings(max_examples=200, deadline=None)
@given(seed=st.integers(0, 10**6), gaps=st.integers(1, 4))
def test_streaming_equals_the_offline_rule(seed, gaps):
    rng = random.Random(seed)
    values, lifted = [], []
    for _ in range(gaps):
        good = rng.randint(1, 45)
        values += [float(rng.randint(-5, 5)) for _ in range(good)]
        lifted += [False] * good
        g = rng.randint(1, 30)
        values += [0.0] * g
        lifted += [True] * g
    values += [2.0] * WINDOW
    lifted += [False] * WINDOW
    got = stream(values, lifted)
    _, offline = fill_sequence(values, lifted)
    assert len(got) == len(offline)
    for (_, est), (_, f) in zip(got, offline, strict=True):
        assert est[0] == pytest.approx(f.total) and est[2] == pytest.approx(f.sigma)
