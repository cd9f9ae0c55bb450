"""Outages of a time series (no rows for a while: link lost, polling paused), drawn as breaks.

A plot that joins its points with lines draws a straight line across an outage, which
reads as data. :func:`find_outages` finds the steps of the time column much longer than
usual; :func:`with_breaks` puts a NaN in the middle of each, so a curve drawn with
``connect="finite"`` stops there. Times in s.
"""

from __future__ import annotations

import numpy as np

__all__ = ["OUTAGE_FACTOR", "OUTAGE_MIN_S", "OutageFinder", "find_outages", "with_breaks"]

#: a step longer than this many typical steps (the median of the recent ones) is an outage
OUTAGE_FACTOR = 5.0
#: ... and at least this long (s): a late reply or two at 15 Hz is not an outage
OUTAGE_MIN_S = 1.0
#: steps the typical step is taken from (the newest ones)
TYPICAL_STEPS = 1000


def outage_threshold(t: np.ndarray) -> float:
    """The step (s) above which ``t`` has an outage: OUTAGE_FACTOR times the median of its
    newest steps, at least OUTAGE_MIN_S."""
    steps = np.diff(t[-TYPICAL_STEPS - 1 :])
    steps = steps[np.isfinite(steps)]
    typical = float(np.median(steps)) if len(steps) else 0.0
    return max(OUTAGE_MIN_S, OUTAGE_FACTOR * typical)


def find_outages(t: np.ndarray, threshold_s: float | None = None) -> np.ndarray:
    """(n, 2) array of the (last time before, first time after) of each outage of ``t``
    (non-decreasing, s); ``threshold_s`` default: :func:`outage_threshold`."""
    t = np.asarray(t, dtype=float)
    if len(t) < 2:
        return np.empty((0, 2))
    limit = outage_threshold(t) if threshold_s is None else threshold_s
    i = np.flatnonzero(np.diff(t) > limit)
    return np.column_stack((t[i], t[i + 1]))


def with_breaks(t: np.ndarray, y: np.ndarray, outages: np.ndarray) -> tuple[np.ndarray, ...]:
    """``t, y`` with a (mid-time, NaN) point inside every outage that has points of ``t`` on
    both sides (``t`` non-decreasing, e.g. thinned from the rows the outages came from)."""
    t = np.asarray(t, dtype=float)
    y = np.asarray(y, dtype=float)
    if len(t) < 2 or not len(outages):
        return t, y
    mids = outages.mean(axis=1)
    mids = mids[(mids > t[0]) & (mids < t[-1])]
    idx = np.searchsorted(t, mids)
    return np.insert(t, idx, mids), np.insert(y, idx, np.nan)


class OutageFinder:
    """The outages of a growing time column, scanned only where it grew (an hour at
    500 Hz is 1.8 M rows: the whole column is not scanned at every redraw).
    :meth:`reset` when the column was replaced or lost rows at its start."""

    def __init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        self._checked = 0  # rows of the column already scanned
        self._found: list[np.ndarray] = []

    def update(self, t: np.ndarray) -> np.ndarray:
        """The outages of ``t`` (see :func:`find_outages`), ``t`` the same column as last
        time with rows added at its end."""
        if len(t) < self._checked:
            self.reset()
        if len(t) - self._checked >= 1 and len(t) >= 2:
            start = max(self._checked - 1, 0)  # the step from the last scanned row on
            new = t[start:]
            found = find_outages(new, outage_threshold(t))
            if len(found):
                self._found.append(found)
            self._checked = len(t)
        return np.concatenate(self._found) if self._found else np.empty((0, 2))
