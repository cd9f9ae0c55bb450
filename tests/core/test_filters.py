"""Median filter and lift-gap interpolation (mm_pc.core.filters).

The original's median filter used a window of 2N, returned the upper median
and had the X/Y check boxes swapped; these tests pin the fixed behaviour.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mm_beagle.poller.lift_gap import WINDOW, LiftGapEstimator
from mm_pc.core.filters import (
    MAX_WINDOW,
    MedianFilter,
    SensorMedianFilter,
    fill_lift_gaps,
    interpolate_lift_gaps,
    median_filter,
    validate_window,
)

values = st.floats(min_value=-1e6, max_value=1e6, allow_nan=False, allow_infinity=False)
windows = st.integers(min_value=1, max_value=25)


# --- window validation ----------------------------------------------------------------


@pytest.mark.parametrize(
    "bad", [0, -1, -5, 1000, 10**6, 2.5, float("nan"), float("inf"), True, False, "5", None, [3]]
)
def test_bad_windows_rejected_with_allowed_range(bad):
    with pytest.raises(ValueError, match=r"median window must be an integer .* in 1\.\.999"):
        validate_window(bad)
    with pytest.raises(ValueError, match=r"1\.\.999"):
        MedianFilter(bad)
    with pytest.raises(ValueError, match=r"1\.\.999"):
        SensorMedianFilter(bad)
    with pytest.raises(ValueError, match=r"1\.\.999"):
        median_filter([1.0, 2.0], bad)


@pytest.mark.parametrize(("good", "expected"), [(1, 1), (999, 999), (5.0, 5), (np.int64(7), 7)])
def test_good_windows(good, expected):
    assert validate_window(good) == expected
    assert isinstance(validate_window(good), int)
    assert MedianFilter(good).window == expected


# --- streaming median -----------------------------------------------------------------


@given(st.lists(values, min_size=1, max_size=80), windows)
@settings(max_examples=100)
def test_streaming_equals_numpy_median_over_window(samples, window):
    f = MedianFilter(window)
    for i, v in enumerate(samples):
        got = f.push(v)
        expected = float(np.median(samples[max(0, i - window + 1) : i + 1]))
        assert got == pytest.approx(expected, rel=1e-12, abs=1e-9)
        assert len(f) == min(i + 1, window)


def test_even_window_is_the_true_median_not_the_upper_one():
    f = MedianFilter(2)
    assert f.push(1.0) == 1.0
    assert f.push(3.0) == 2.0  # the original returned 3 (upper median)
    assert f.push(10.0) == 6.5  # window is 2 samples, not 2N = 4
    f = MedianFilter(4)
    assert [f.push(v) for v in (1, 2, 3, 10, 0)] == [1.0, 1.5, 2.0, 2.5, 2.5]


def test_odd_window_and_outlier():
    f = MedianFilter(3)
    out = [f.push(v) for v in (5, 5, 500, 5, 6, 7)]
    assert out == [5.0, 5.0, 5.0, 5.0, 6.0, 6.0]


def test_window_one_is_identity():
    f = MedianFilter(1)
    assert [f.push(v) for v in (3, -1, 7.5)] == [3.0, -1.0, 7.5]


def test_reset_and_empty_median():
    f = MedianFilter(3)
    for v in (1, 2, 3):
        f.push(v)
    f.reset()
    assert len(f) == 0 and f.median() == 0.0
    assert f.push(10) == 10.0  # warm-up again
    assert f.window == 3


def test_window_change_keeps_newest_samples():
    f = MedianFilter(5)
    for v in (100, 1, 2, 3, 4):
        f.push(v)
    f.window = 3
    assert len(f) == 3 and f.median() == 3.0  # keeps 2, 3, 4
    f.window = 10
    assert f.push(5) == 3.5  # 2, 3, 4, 5
    with pytest.raises(ValueError, match=r"1\.\.999"):
        f.window = 0
    assert f.window == 10


@pytest.mark.parametrize("bad", [float("nan"), float("inf"), -float("inf")])
def test_non_finite_sample_rejected_without_changing_state(bad):
    f = MedianFilter(3)
    f.push(1.0)
    with pytest.raises(ValueError, match="must be finite"):
        f.push(bad)
    assert len(f) == 1 and f.push(3.0) == 2.0


def test_large_window_is_fast_and_right():
    rng = np.random.default_rng(3)
    data = rng.normal(size=5000)
    f = MedianFilter(MAX_WINDOW)
    out = f.push_many(data)
    np.testing.assert_allclose(out[-1], np.median(data[-MAX_WINDOW:]))
    np.testing.assert_allclose(out, median_filter(data, MAX_WINDOW))


# --- per sensor, per axis -----------------------------------------------------------------

SPIKY_X = [0.0, 0.0, 9.0, 0.0, 0.0]
SPIKY_Y = [1.0, 1.0, -7.0, 1.0, 1.0]


def run(f: SensorMedianFilter, xs=SPIKY_X, ys=SPIKY_Y):
    out = [f.push(x, y) for x, y in zip(xs, ys, strict=True)]
    return [o[0] for o in out], [o[1] for o in out]


def test_enabling_x_filters_only_x():
    fx, fy = run(SensorMedianFilter(3, filter_x=True))
    assert fx == [0.0] * 5  # spike removed
    assert fy == SPIKY_Y  # Y untouched


def test_enabling_y_filters_only_y():
    fx, fy = run(SensorMedianFilter(3, filter_y=True))
    assert fx == SPIKY_X
    assert fy == [1.0] * 5


def test_both_and_neither():
    assert run(SensorMedianFilter(3, filter_x=True, filter_y=True)) == ([0.0] * 5, [1.0] * 5)
    assert run(SensorMedianFilter(3)) == (SPIKY_X, SPIKY_Y)


@given(st.lists(st.tuples(values, values), min_size=1, max_size=40), windows)
@settings(max_examples=50)
def test_axes_are_independent(samples, window):
    xs = [s[0] for s in samples]
    ys = [s[1] for s in samples]
    f = SensorMedianFilter(window, filter_x=True, filter_y=True)
    fx, fy = f.push_many(xs, ys)
    np.testing.assert_allclose(fx, median_filter(xs, window))
    np.testing.assert_allclose(fy, median_filter(ys, window))
    # Changing Y never changes filtered X.
    g = SensorMedianFilter(window, filter_x=True, filter_y=True)
    gx, _ = g.push_many(xs, [0.0] * len(xs))
    np.testing.assert_array_equal(gx, fx)


def test_enabling_mid_run_filters_over_a_full_window():
    f = SensorMedianFilter(3)
    for x in (5.0, 6.0):
        assert f.push(x, 0.0) == (x, 0.0)
    f.filter_x = True
    assert f.push(100.0, 0.0) == (6.0, 0.0)  # median of 5, 6, 100


def test_sensor_filter_window_change_and_reset():
    f = SensorMedianFilter(5, filter_x=True, filter_y=True)
    run(f)
    f.window = 1
    assert f.window == 1
    assert f.push(3.0, 4.0) == (3.0, 4.0)
    with pytest.raises(ValueError, match=r"1\.\.999"):
        f.window = "3"
    assert f.window == 1
    f.reset()
    f.window = 3
    assert f.push(2.0, 2.0) == (2.0, 2.0)


def test_sensor_filter_bad_sample_changes_neither_axis():
    f = SensorMedianFilter(3, filter_x=True, filter_y=True)
    f.push(1.0, 1.0)
    with pytest.raises(ValueError, match="finite"):
        f.push(5.0, float("nan"))
    assert f.push(3.0, 3.0) == (2.0, 2.0)  # X did not see the 5
    with pytest.raises(ValueError, match="same length"):
        f.push_many([1.0, 2.0], [1.0])
    with pytest.raises(ValueError, match="finite"):
        f.push_many([1.0, np.inf], [1.0, 2.0])
    ex, ey = f.push_many([], [])
    assert ex.size == 0 and ey.size == 0


# --- offline median ---------------------------------------------------------------------------


@given(st.lists(values, min_size=0, max_size=120), windows)
@settings(max_examples=100)
def test_offline_equals_streaming(samples, window):
    stream = MedianFilter(window).push_many(samples)
    offline = median_filter(np.array(samples, dtype=float), window)
    assert offline.shape == (len(samples),)
    np.testing.assert_allclose(offline, stream, rtol=1e-12, atol=1e-9)


def test_offline_columns_and_chunking():
    rng = np.random.default_rng(7)
    data = rng.normal(size=(500, 2))
    out = median_filter(data, 6)
    assert out.shape == (500, 2)
    np.testing.assert_allclose(out[:, 0], median_filter(data[:, 0], 6))
    np.testing.assert_allclose(out[:, 1], median_filter(data[:, 1], 6))
    # A tiny chunk gives the same answer.
    np.testing.assert_allclose(median_filter(data, 6, chunk=7), out)
    assert np.all(median_filter(np.arange(10), 3) == [0, 0.5, 1, 2, 3, 4, 5, 6, 7, 8])


def test_offline_rejects_scalar_and_nan():
    with pytest.raises(ValueError, match="scalar"):
        median_filter(3.0, 3)
    with pytest.raises(ValueError, match="finite"):
        median_filter([1.0, float("nan")], 3)


# --- lift gaps --------------------------------------------------------------------------------


def test_interior_gap_is_the_window_line():
    counts = np.array([2, 0, 0, 0, 10, 10])
    lifted = np.array([0, 1, 1, 1, 0, 0], dtype=bool)
    out = interpolate_lift_gaps(counts, lifted)
    # windows: [2] centred at 0, [10, 10] at 4.5 (gap polls 1..3): slope 8 / 4.5 per poll
    np.testing.assert_allclose(out, [2, 2 + 8 / 4.5, 2 + 16 / 4.5, 2 + 24 / 4.5, 10, 10])
    # The input is not modified, and lifted-poll values are ignored.
    assert counts[1] == 0
    np.testing.assert_allclose(interpolate_lift_gaps([2, 99, 99, 99, 10, 10], lifted), out)


def test_edges_hold_the_window_rate_and_all_lifted_is_zero():
    out = interpolate_lift_gaps([0, 0, 5, 7, 0], np.array([1, 1, 0, 0, 1], dtype=bool))
    np.testing.assert_allclose(out, [6, 6, 5, 7, 6])
    out = interpolate_lift_gaps([4, 4, 4], np.ones(3, dtype=bool))
    np.testing.assert_array_equal(out, [0, 0, 0])
    assert out.dtype == float


def test_fill_is_the_boards_rule_with_its_sigma():
    """The same polls through the board's streaming estimator give the same totals."""
    rng = np.random.default_rng(3)
    n = 400
    pos = np.cumsum(rng.uniform(0.0, 0.8, (n, 2)), axis=0)
    counts = np.diff(np.floor(np.vstack([[0, 0], pos])), axis=0)
    lifted = np.zeros(n, dtype=bool)
    lifted[50:130] = lifted[140:150] = lifted[300:330] = True
    filled, gaps = fill_lift_gaps(counts, lifted)
    est = LiftGapEstimator()
    board = [
        r
        for (x, y), f in zip(counts.tolist(), lifted.tolist(), strict=True)
        if (r := est.update(x, y, f)) is not None
    ]
    assert [(a, b) for a, b, _ in gaps] == [(50, 130), (140, 150), (300, 330)]
    for (a, b, sigma), r in zip(gaps, board, strict=True):
        np.testing.assert_allclose(filled[a:b].sum(axis=0), r[:2])
        np.testing.assert_allclose(sigma, r[2:])
        assert np.all(sigma > 0)
    np.testing.assert_array_equal(filled[~lifted], counts[~lifted])


def test_no_lift_returns_a_float_copy():
    counts = np.array([1, 2, 3])
    out = interpolate_lift_gaps(counts, np.zeros(3, dtype=bool))
    np.testing.assert_array_equal(out, counts)
    assert out.dtype == float and out is not counts
    assert interpolate_lift_gaps(np.empty(0), np.zeros(0, dtype=bool)).size == 0


def test_two_axes_at_once():
    counts = np.array([[0, 10], [0, 0], [4, 20]])
    lifted = np.array([False, True, False])
    np.testing.assert_allclose(interpolate_lift_gaps(counts, lifted), [[0, 10], [2, 15], [4, 20]])


@pytest.mark.parametrize(
    ("counts", "lifted", "message"),
    [
        ([1, 2, 3], [0, 1, 0], "bool array"),
        ([1, 2, 3], np.array([True, False]), "one flag per poll"),
        (5, np.array(True), "one flag per poll"),
        ([[1, 2], [3, 4]], np.array([True, False, True]), "one flag per poll"),
    ],
)
def test_lift_gap_bad_input(counts, lifted, message):
    with pytest.raises(ValueError, match=message):
        interpolate_lift_gaps(counts, np.asarray(lifted) if isinstance(lifted, list) else lifted)


@st.composite
def polls_with_interior_gaps(draw):
    n = draw(st.integers(min_value=2, max_value=60))
    counts = draw(
        st.lists(st.tuples(st.integers(-50, 50), st.integers(-50, 50)), min_size=n, max_size=n)
    )
    lifted = draw(st.lists(st.booleans(), min_size=n, max_size=n))
    lifted[0] = False
    counts += [(1, -1)] * WINDOW  # every gap's after-window is complete on the board
    lifted += [False] * WINDOW
    return np.array(counts), np.array(lifted)


@given(polls_with_interior_gaps())
@settings(max_examples=100)
def test_sums_agree_with_the_beagle_lift_gap_estimator(data):
    counts, lifted = data
    counts = np.where(lifted[:, None], 0, counts)  # a lifted poll reads 0 on the sensor
    est = LiftGapEstimator()
    total = np.zeros(2)
    for (dx, dy), lift in zip(counts.tolist(), lifted.tolist(), strict=True):
        gap = est.update(dx, dy, lift)
        if gap is not None:
            total += gap[:2]
        if not lift:
            total += (dx, dy)
    filled = interpolate_lift_gaps(counts, lifted)
    np.testing.assert_allclose(filled.sum(axis=0), total, atol=1e-9)
