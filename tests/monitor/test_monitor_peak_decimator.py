"""The one peak decimator of the plots (model/peak_decimator.py): values, no Qt.

The Graphs view draws a window as min/max pairs (``window``), the Health view a
whole column as each bucket's largest or smallest value (``thinned``); both must
equal a fresh computation however the column grew.
"""

from __future__ import annotations

import numpy as np

from mm_pc.monitor.model.peak_decimator import PeakDecimator, bucket_peak, bucket_size


def reference_window(t, y, i0, size):
    """Min/max pairs of the buckets aligned to row numbers, the partial edges as they are."""
    b0, b1 = -(-i0 // size), len(t) // size
    blocks = y[b0 * size : b1 * size].reshape(-1, size)
    mid = np.column_stack((np.fmin.reduce(blocks, axis=1), np.fmax.reduce(blocks, axis=1)))
    ys = np.concatenate((y[i0 : b0 * size], mid.ravel(), y[b1 * size :]))
    ts = np.concatenate((t[i0 : b0 * size], np.repeat(t[b0 * size : b1 * size : size], 2),
                         t[b1 * size :]))
    return ts, ys


def test_window_incremental_equals_fresh():
    rng = np.random.default_rng(3)
    t = np.arange(50_000) / 100.0
    y = rng.normal(size=50_000)
    cache = PeakDecimator()
    for n in (20_000, 20_001, 20_064, 31_000, 50_000):
        i0 = n - 9000
        got = cache.window(t[:n], y[:n], i0, 8)
        want = reference_window(t[:n], y[:n], i0, 8)
        np.testing.assert_array_equal(got[0], want[0])
        np.testing.assert_array_equal(got[1], want[1])
    assert bucket_size(4000) == 1 and bucket_size(4001) == 4 and bucket_size(360_000) == 256
    _x, v = cache.window(t, y, 100, 1)  # size 1: the rows themselves
    np.testing.assert_array_equal(v, y[100:])


def test_window_reads_only_new_buckets_and_merges_on_a_larger_size():
    t = np.arange(10_000) * 0.01
    y = np.sin(np.arange(10_000) / 37.0)
    y[5_003] = 9.0  # one spike
    cache = PeakDecimator()
    cache.window(t[:8_000], y[:8_000], 0, 4)
    assert cache.rows_read == 8_000
    cache.window(t[:8_010], y[:8_010], 0, 4)
    assert cache.rows_read == 8  # two new buckets of 4 rows
    x, v = cache.window(t[:8_010], y[:8_010], 0, 16)  # the window doubled twice: merged
    assert cache.rows_read == 0
    want = reference_window(t[:8_010], y[:8_010], 0, 16)
    np.testing.assert_array_equal(x, want[0])
    np.testing.assert_array_equal(v, want[1])
    assert v.max() == 9.0 and v.min() == y[:8_010].min()
    x, v = cache.window(t, y, 1_000, 16)  # the window moved on: older buckets forgotten
    want = reference_window(t, y, 1_000, 16)
    np.testing.assert_array_equal(v, want[1])
    assert cache.start == 1_000 // 16 + 1 and cache.end == 10_000 // 16


def test_window_ignores_nan_within_a_bucket():
    t = np.arange(12.0)
    y = np.array([np.nan, 1, 2, 3, np.nan, np.nan, np.nan, np.nan, 5, np.nan, -1, 0])
    x, v = PeakDecimator().window(t, y, 0, 4)
    np.testing.assert_array_equal(x, [0, 0, 4, 4, 8, 8])
    np.testing.assert_array_equal(v, [1, 3, np.nan, np.nan, -1, 5])


def test_thinned_reads_only_new_rows_and_keeps_every_peak():
    rng = np.random.default_rng(3)
    n = 50_000
    table = rng.random((n, 3))
    table[:, 0] = np.arange(n) * 0.01
    table[rng.random(n) < 0.3, 2] = np.nan
    table[12_345, 2] = 7.0  # one peak among NaN and noise
    table[23_456, 2] = -3.0  # one dip
    cache = PeakDecimator()
    end = 0
    for chunk in rng.integers(1, 4000, 60):
        end = min(n, end + int(chunk))
        t, y = table[:end, 0], table[:end, 2]
        bt, by = cache.thinned(t, y, 500)
        assert len(bt) <= 501
        starts = np.arange(0, end, cache.size)
        assert np.array_equal(bt, t[starts])
        assert np.array_equal(by, np.fmax.reduceat(y, starts), equal_nan=True)
        assert cache.rows_read <= int(chunk) + 2 * cache.size
        lt, ly = cache.thinned(t, y, 500, lowest=True)  # the same buckets, their smallest
        assert np.array_equal(lt, bt)
        assert np.array_equal(ly, np.fmin.reduceat(y, starts), equal_nan=True)
    assert end == n and np.nanmax(by) == 7.0 and np.nanmin(ly) == -3.0
    assert cache.size == 128  # the smallest power of two with at most 500 whole buckets
    bt, by = cache.thinned(table[:10, 0], table[:10, 2], 500)  # shorter: the history was cleared
    assert np.array_equal(by, table[:10, 2], equal_nan=True) and cache.rows_read == 10


def test_bucket_peak_of_a_short_range():
    rng = np.random.default_rng(5)
    t = np.arange(1000) * 0.01
    y = rng.random(1000)
    y[777] = 7.0
    y[333] = -2.0
    bt, by = bucket_peak(t, y, 100)
    assert len(bt) == 100 and by.max() == 7.0 and by[77] == 7.0
    np.testing.assert_array_equal(bt, t[::10])
    _, low = bucket_peak(t, y, 100, lowest=True)
    assert low.min() == -2.0 and low[33] == -2.0
    same_t, same_y = bucket_peak(t[:50], y[:50], 100)  # fewer rows than points: as they are
    assert same_t is not None and np.array_equal(same_y, y[:50])
