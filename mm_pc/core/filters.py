"""Sample filters of the monitor: the optional median filter and lift-gap filling.

Pure math: numpy, no Qt, no ROS. Values are per-sample displacements in
the sensor frame (X right, Y forward), in counts or metres -- the filters
are unit-agnostic and never mix the axes.

Median filter
-------------
Window ``N`` samples (1..999), a true median: for an even number of values
the mean of the two middle ones (``numpy.median``), over the last ``N``
samples including the newest. During warm-up (fewer than ``N`` samples so
far) the median of what has been seen. The original used a window of 2N
and returned the upper median, and had the X and Y check boxes swapped.

Note the seed's own finding: at low request rates a median filter throws
away correct large samples (a late reply holds more counts), so it is off
by default and meant for 1 kHz-style per-poll data or display only.
"""

from __future__ import annotations

import bisect
import math
import numbers
from collections import deque

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from mm_pc.core.checks import finite
from pln2033 import lift_fill

__all__ = [
    "MAX_WINDOW",
    "MIN_WINDOW",
    "MedianFilter",
    "SensorMedianFilter",
    "fill_lift_gaps",
    "interpolate_lift_gaps",
    "median_filter",
    "validate_window",
]

MIN_WINDOW = 1
MAX_WINDOW = 999


def validate_window(window) -> int:
    """``window`` as an int in MIN_WINDOW..MAX_WINDOW, else ValueError.

    Accepts Python/numpy integers and integral floats (5.0); rejects bools,
    strings, non-integral or non-finite numbers and anything out of range.
    """
    allowed = f"an integer number of samples in {MIN_WINDOW}..{MAX_WINDOW}"
    if isinstance(window, (bool, np.bool_)) or not isinstance(window, numbers.Real):
        raise ValueError(f"median window must be {allowed}, got {window!r}")
    if isinstance(window, numbers.Integral):
        n = int(window)
    else:
        w = float(window)
        if not math.isfinite(w) or not w.is_integer():
            raise ValueError(f"median window must be {allowed}, got {window!r}")
        n = int(w)
    if not MIN_WINDOW <= n <= MAX_WINDOW:
        raise ValueError(f"median window must be {allowed}, got {n}")
    return n


def _finite(value) -> float:
    return finite("median filter input", value)


class MedianFilter:
    """Streaming median over the last ``window`` samples of one axis.

    ``push`` costs O(window) (a sorted list kept next to the FIFO); at the
    GUI's window sizes (<= 999) and rates that is microseconds.
    """

    def __init__(self, window: int) -> None:
        self._window = validate_window(window)
        self._fifo: deque[float] = deque()
        self._sorted: list[float] = []

    @property
    def window(self) -> int:
        """Window length in samples."""
        return self._window

    @window.setter
    def window(self, window: int) -> None:
        """Change the window; keeps the newest min(window, seen) samples."""
        n = validate_window(window)
        while len(self._fifo) > n:
            old = self._fifo.popleft()
            del self._sorted[bisect.bisect_left(self._sorted, old)]
        self._window = n

    def __len__(self) -> int:
        """Samples currently in the window."""
        return len(self._fifo)

    def push(self, value: float) -> float:
        """Add one sample, return the median of the window (incl. this sample)."""
        v = _finite(value)
        if len(self._fifo) == self._window:
            old = self._fifo.popleft()
            del self._sorted[bisect.bisect_left(self._sorted, old)]
        self._fifo.append(v)
        bisect.insort(self._sorted, v)
        return self.median()

    def median(self) -> float:
        """Median of the current window; 0.0 if empty."""
        s = self._sorted
        n = len(s)
        if n == 0:
            return 0.0
        h = n // 2
        return s[h] if n % 2 else (s[h - 1] + s[h]) / 2.0

    def push_many(self, values) -> np.ndarray:
        """Push a sequence of samples, return the filtered values as an array."""
        return np.array([self.push(v) for v in np.asarray(values, dtype=float).ravel()])

    def reset(self) -> None:
        """Forget all samples (the window length stays)."""
        self._fifo.clear()
        self._sorted.clear()


class SensorMedianFilter:
    """The GUI's per-sensor median filter: independent X and Y filters.

    ``filter_x`` enables filtering of sensor X only, ``filter_y`` of sensor
    Y only (the original's check boxes were swapped). Both axis filters see
    every sample even while disabled, so enabling one mid-run filters at
    once over a full window instead of warming up again.
    """

    def __init__(self, window: int = 5, filter_x: bool = False, filter_y: bool = False) -> None:
        self._x = MedianFilter(window)
        self._y = MedianFilter(window)
        self.filter_x = bool(filter_x)
        self.filter_y = bool(filter_y)

    @property
    def window(self) -> int:
        return self._x.window

    @window.setter
    def window(self, window: int) -> None:
        n = validate_window(window)  # validate once, so both change or neither
        self._x.window = n
        self._y.window = n

    def push(self, dx: float, dy: float) -> tuple[float, float]:
        """One sample (sensor X, sensor Y) -> (X', Y'), each filtered if enabled."""
        x = _finite(dx)
        y = _finite(dy)  # both checked before either filter changes
        fx = self._x.push(x)
        fy = self._y.push(y)
        return (fx if self.filter_x else x), (fy if self.filter_y else y)

    def push_many(self, dx, dy) -> tuple[np.ndarray, np.ndarray]:
        """Arrays of samples -> filtered arrays (same rules as :meth:`push`)."""
        dx = np.asarray(dx, dtype=float).ravel()
        dy = np.asarray(dy, dtype=float).ravel()
        if dx.shape != dy.shape:
            raise ValueError(f"dx and dy must have the same length, got {dx.size} and {dy.size}")
        if not (np.all(np.isfinite(dx)) and np.all(np.isfinite(dy))):
            raise ValueError("median filter input must be finite")
        out = [self.push(x, y) for x, y in zip(dx.tolist(), dy.tolist(), strict=True)]
        if not out:
            return np.empty(0), np.empty(0)
        fx, fy = zip(*out, strict=True)
        return np.array(fx), np.array(fy)

    def reset(self) -> None:
        """Forget the history of both axes (settings stay)."""
        self._x.reset()
        self._y.reset()


def median_filter(values, window: int, *, chunk: int = 1 << 22) -> np.ndarray:
    """Offline median filter along axis 0; equals :class:`MedianFilter` pushed in order.

    ``values``: array of shape (n,) or (n, ...); each column is filtered
    independently. Output[i] = median(values[max(0, i - window + 1) : i + 1]).
    ``chunk`` bounds the temporary memory (elements copied at once).
    """
    n_win = validate_window(window)
    a = np.asarray(values, dtype=float)
    if a.ndim == 0:
        raise ValueError("median_filter needs an array of samples, got a scalar")
    if not np.all(np.isfinite(a)):
        raise ValueError("median filter input must be finite")
    n = a.shape[0]
    out = np.empty_like(a)
    warm = min(n_win - 1, n)
    for i in range(warm):
        out[i] = np.median(a[: i + 1], axis=0)
    if n >= n_win:
        view = sliding_window_view(a, n_win, axis=0)  # (n - w + 1, ..., w)
        per_row = max(1, chunk // (n_win * max(1, int(np.prod(a.shape[1:])))))
        for start in range(0, view.shape[0], per_row):
            stop = min(start + per_row, view.shape[0])
            out[n_win - 1 + start : n_win - 1 + stop] = np.median(view[start:stop], axis=-1)
    return out


def fill_lift_gaps(counts, lifted, *, unit: float = 1.0, dt=None):
    """Fill the polls taken while the sensor was lifted, and say how sure each fill is.

    The rule is :mod:`pln2033.lift_fill` (the one the board's poller uses): the
    mean of up to ``WINDOW`` (20) good polls on each side of a gap, a straight
    line between the two window centres; a gap with good polls on one side only
    holds that side's rate; if every poll is lifted the result is zeros.

    Args:
        counts: per-poll displacement, shape (n,) or (n, k) (e.g. k = 2 for X
            and Y), counts or metres. Values at lifted polls are ignored.
        lifted: bool array of shape (n,), True where the poll had the lift bit set.
        unit: one count in the unit of ``counts`` (1 for counts, metres per count
            for metres): sets the rounding term of the uncertainty.
        dt: each poll's own interval from the stamps (s), shape (n,): the rule runs per
            unit of time; None: every poll one interval.

    Returns:
        (filled, gaps): a float copy of ``counts`` with every lifted poll replaced
        by its estimate, and per gap ``(start, stop, sigma)``: its index range and
        the 1-sigma uncertainty of its summed estimate per column, shape (k,)
        (inf where no good poll was there to estimate from).
    """
    c = np.array(counts, dtype=float)  # a copy
    m = np.asarray(lifted)
    if m.dtype != bool:
        raise ValueError(f"lifted must be a bool array, got dtype {m.dtype}")
    if c.ndim == 0 or m.shape != c.shape[:1]:
        raise ValueError(
            f"lifted must have one flag per poll: counts shape {c.shape}, lifted shape {m.shape}"
        )
    if not m.any():
        return c, []
    flat = c.reshape(c.shape[0], -1)
    flags = m.tolist()
    times = None if dt is None else np.asarray(dt, dtype=float).tolist()
    columns = [
        lift_fill.fill_sequence(flat[:, j].tolist(), flags, unit=unit, dt=times)
        for j in range(flat.shape[1])
    ]
    for j, (filled, _) in enumerate(columns):
        flat[:, j] = filled
    gaps = [
        (start, start + fill.polls, np.array([col[1][g][1].sigma for col in columns]))
        for g, (start, fill) in enumerate(columns[0][1])
    ]
    return flat.reshape(c.shape), gaps


def interpolate_lift_gaps(counts, lifted, dt=None) -> np.ndarray:
    """Fill the polls taken while the sensor was lifted (:func:`fill_lift_gaps`, values only).

    Args:
        counts: per-poll displacement, shape (n,) or (n, k), counts or metres.
        lifted: bool array of shape (n,), True where the poll had the lift bit set.
        dt: each poll's own interval (s), or None (see :func:`fill_lift_gaps`).

    Returns:
        A float copy of ``counts`` in which every lifted poll is replaced by the
        window estimate of :mod:`pln2033.lift_fill`, as :mod:`mm_beagle.poller.lift_gap`
        estimates it on the board.
    """
    return fill_lift_gaps(counts, lifted, dt=dt)[0]
