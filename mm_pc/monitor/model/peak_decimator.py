"""Peaks of a growing history column in buckets of rows, computed incrementally (no Qt).

An hour at 100 Hz is 360 000 rows, far more than a plot has pixels; drawn as
the smallest and largest value of each bucket of rows, no spike or single lift
is hidden by the thinning. Buckets are aligned to absolute row numbers
``[b * size, (b + 1) * size)``: the history only grows, so a complete bucket
never changes and each call computes only the buckets completed since the
previous one (plus the partial bucket at the end). NaN is ignored within a
bucket; a bucket of only NaN stays NaN.

Used by the Graphs view (:meth:`PeakDecimator.window`: a time window as
minimum/maximum pairs) and the Health view (:meth:`PeakDecimator.thinned`:
the whole column as each bucket's largest or smallest value).
"""

from __future__ import annotations

import numpy as np

__all__ = ["MAX_BUCKETS", "PeakDecimator", "bucket_peak", "bucket_size"]

#: windows longer than 2 * MAX_BUCKETS rows are drawn min/max-decimated (a few px per bucket)
MAX_BUCKETS = 2000


def bucket_size(rows: int, buckets: int = MAX_BUCKETS) -> int:
    """Rows per min/max bucket for a window of ``rows`` (1 = draw every row).

    A power of two, so it changes only when the window's length doubles or
    halves (finished buckets can then be kept from frame to frame)."""
    if rows <= 2 * buckets:
        return 1
    return 1 << (-(-rows // buckets) - 1).bit_length()


def bucket_peak(
    t: np.ndarray, y: np.ndarray, max_points: int, lowest: bool = False
) -> tuple[np.ndarray, np.ndarray]:
    """At most ``max_points`` points: each bucket of rows as (its first t, its largest y;
    ``lowest``: its smallest). Stateless, for a short zoomed-in range."""
    n = len(t)
    if n <= max_points:
        return t, y
    idx = np.arange(0, n, -(-n // max_points))
    return t[idx], (np.fmin if lowest else np.fmax).reduceat(y, idx)


class PeakDecimator:
    """Minimum and maximum of one column over buckets of ``size`` rows, kept between calls.

    Call with the full, append-only column each time; a shorter column starts
    over, and :meth:`clear` does so when rows were dropped from the front (the
    bucket numbers moved). A larger ``size`` that is a multiple of the old one
    merges the kept buckets instead of reading the rows again.
    """

    def __init__(self) -> None:
        self.clear()

    def clear(self) -> None:
        self.size = 0
        self.start = 0  # bucket number of mins[0]
        self.mins = np.empty(0)
        self.maxs = np.empty(0)
        self._rows = 0  # the column's length at the last call
        #: rows of the column the last call read (new complete buckets and the partial one)
        self.rows_read = 0

    @property
    def end(self) -> int:
        """The bucket number after the last one kept."""
        return self.start + len(self.mins)

    def buckets(
        self, col: np.ndarray, b0: int, b1: int, size: int
    ) -> tuple[np.ndarray, np.ndarray]:
        """(minimum, maximum) of the complete buckets ``b0..b1`` of ``size`` rows of ``col``.

        Buckets before ``b0`` are forgotten (a scrolling window only moves on)."""
        if len(col) < self._rows:
            self.clear()
        self._rows = len(col)
        if size != self.size:
            self._resize(size)
        if not self.start <= b0 <= self.end:
            self.start, self.mins, self.maxs = b0, np.empty(0), np.empty(0)
        self.rows_read = 0
        lo = b0 - self.start
        if b1 > self.end:
            block = col[self.end * size : b1 * size].reshape(-1, size)
            self.rows_read = block.size
            self.mins = np.concatenate((self.mins[lo:], np.fmin.reduce(block, axis=1)))
            self.maxs = np.concatenate((self.maxs[lo:], np.fmax.reduce(block, axis=1)))
        else:
            self.mins, self.maxs = self.mins[lo:], self.maxs[lo:]
        self.start = b0
        return self.mins[: b1 - b0], self.maxs[: b1 - b0]

    def _resize(self, size: int) -> None:
        """Change the bucket size, merging the kept buckets when ``size`` is a multiple."""
        old, self.size = self.size, size
        if old and size > old and size % old == 0 and len(self.mins):
            f = size // old
            nb0, nb1 = -(-self.start // f), self.end // f  # new buckets wholly kept
            lo, hi = nb0 * f - self.start, max(nb0, nb1) * f - self.start
            self.mins = np.fmin.reduce(self.mins[lo:hi].reshape(-1, f), axis=1)
            self.maxs = np.fmax.reduce(self.maxs[lo:hi].reshape(-1, f), axis=1)
            self.start = nb0
            return
        self.start, self.mins, self.maxs = 0, np.empty(0), np.empty(0)

    def window(
        self, t: np.ndarray, col: np.ndarray, i0: int, size: int
    ) -> tuple[np.ndarray, np.ndarray]:
        """(t, value) points for rows ``i0..len(t)``: whole buckets as their minimum then
        maximum (both at the bucket's first t), the partial ones at either end as they are."""
        n = len(t)
        b0, b1 = -(-i0 // size), n // size
        if size == 1 or b1 <= b0:
            self.rows_read = n - i0
            return t[i0:n], col[i0:n]
        mins, maxs = self.buckets(col, b0, b1, size)
        peaks = np.empty(2 * len(mins))
        peaks[0::2] = mins
        peaks[1::2] = maxs
        head, tail = slice(i0, b0 * size), slice(b1 * size, n)
        out_t = np.concatenate((t[head], np.repeat(t[b0 * size : b1 * size : size], 2), t[tail]))
        return out_t, np.concatenate((col[head], peaks, col[tail]))

    def thinned(
        self, t: np.ndarray, col: np.ndarray, max_points: int, lowest: bool = False
    ) -> tuple[np.ndarray, np.ndarray]:
        """The whole column as at most ``max_points`` + 1 points: each bucket as (its first t,
        its largest value; ``lowest``: its smallest), the rows after the last complete bucket
        as one more point. The bucket size is the smallest power of two that fits."""
        n = len(col)
        size = max(self.size, 1) if n >= self._rows else 1
        while n // size > max_points:
            size *= 2
        b1 = n // size
        mins, maxs = self.buckets(col, 0, b1, size)
        peaks = mins if lowest else maxs
        done = b1 * size
        if n > done:
            self.rows_read += n - done
            rest = (np.fmin if lowest else np.fmax).reduce(col[done:n])
            return np.append(t[0:done:size], t[done]), np.append(peaks, rest)
        return t[0:done:size], peaks.copy()
