"""Counts lost while the sensor was lifted: the one rule, pure Python (no numpy).

While its lift bit is set the PLN2033 clears its counters and counts nothing, so
the displacement of the lifted polls is lost and can only be estimated. Shared by
the board's poller (:mod:`mm_beagle.poller.lift_gap`, streaming, no numpy on the board)
and the PC's per-poll filter (:func:`mm_pc.core.filters.interpolate_lift_gaps`).

The rule (derivation and figures: docs/pose-math.md, "Lifts"):

* The rate before the gap is the mean of the last ``n_a`` <= :data:`WINDOW` good
  polls right before it, the rate after it the mean of the first ``n_b`` <= WINDOW
  good polls right after it. A window stops at the previous or next lifted poll
  (a second lift shortens it), so it only ever spans contiguous good polls.
* Each mean stands at the centre of its window; poll k = 1..G of the gap gets the
  straight line through both (exact for a speed that changes linearly). With one
  poll each side this is the seed's a + (b - a) * k / (G + 1).
* A gap with good polls on one side only (at the start of a recording, or still
  open at its end) holds that side's rate; with none at all it is 0.
* Rates are per unit of time when the polls' intervals are given (``dt``: each poll's
  own interval from the stamps): a window's rate is its counts over its duration, its
  centre the middle of its time span, and each lifted poll gets the straight line's
  mean over its own interval times that interval. A stalled lifted poll (30 ms where
  1 ms is usual) thus gets 30 ms of motion, not one poll's worth; a stalled good poll
  in a window weighs by its time. With equal intervals this is the per-poll rule
  above, computed as such (the same figures to the bit); without ``dt`` every poll
  counts as one interval.

Its uncertainty (counts, 1 sigma, of the gap's total): a window sum of whole
counts read with carried remainders is off by the difference of two remainders,
variance 1/6 count^2, so a window mean has variance 1/(6 n^2); and the speed may
have changed anyhow inside the gap, so the total could lie anywhere between
G * rate_before and G * rate_after: a uniform spread, variance (G * (m_b - m_a))^2 / 12.
A one-sided gap uses (G * m)^2 / 12 for that term (nothing says the rate held).
In time, G * rate is the gap's duration times the rate per unit of time, and each
window mean's weight is the part of the gap's duration it carries.

Why :data:`WINDOW` = 20 polls: one poll's +-1 count rounding, multiplied by the
gap length, was the whole error of the one-poll rule (98 mm on the 12 m tour at
1600 CPI); a window of n polls cuts it n-fold. 20 ms at 1 kHz is still short
against how fast the robot's speed changes (hundreds of ms), so the straight line
between the two window centres holds, and the estimate is known 20 polls after
the lift ends. Longer windows gain little more (the remainder term is already
below a count for gaps of a few hundred polls) and delay the estimate.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

__all__ = ["WINDOW", "GapFill", "fill_gap", "fill_sequence", "gap_runs"]

#: good polls averaged on each side of a gap (see the module docstring for why 20)
WINDOW = 20

_REMAINDER_VAR = 1.0 / 6.0  # count^2: difference of two uniform [0, 1) remainders


@dataclass(frozen=True)
class GapFill:
    """The estimate for one gap of ``polls`` lifted polls (counts or metres per poll).

    Poll k = 1..polls of the gap is ``first + step * (k - 1)`` (equal intervals), or
    ``values[k - 1]`` when the polls' intervals differ; ``total`` is their sum,
    ``sigma`` its 1-sigma uncertainty (same unit; ``math.inf`` when neither side had
    a good poll).
    """

    polls: int
    first: float
    step: float
    total: float
    sigma: float
    values: tuple[float, ...] | None = None

    def per_poll(self) -> list[float]:
        """The estimate of each lifted poll, in order."""
        if self.values is not None:
            return list(self.values)
        return [self.first + self.step * k for k in range(self.polls)]


def fill_gap(
    sum_before: float,
    n_before: int,
    gap: int,
    sum_after: float,
    n_after: int,
    unit: float = 1.0,
    *,
    t_before: float | None = None,
    t_gap: Sequence[float] | None = None,
    t_after: float | None = None,
) -> GapFill:
    """The estimate for ``gap`` lifted polls from the window sums on either side.

    ``sum_before`` / ``n_before``: sum and number of the good polls right before the
    gap (0 polls: none), ``sum_after`` / ``n_after`` those right after it. ``unit``:
    the size of one count in the values' unit (1 for counts; metres per count for
    metres), for the remainder term of ``sigma``. ``t_gap``: each lifted poll's own
    interval (any time unit, e.g. s), ``t_before`` / ``t_after``: the windows' summed
    intervals; given, the rule runs per unit of time (module docstring). Intervals
    that are all equal, or not all > 0 (no usable stamps), give the per-poll rule.
    """
    if gap <= 0:
        return GapFill(0, 0.0, 0.0, 0.0, 0.0)
    if t_gap is not None and not _per_poll(n_before, n_after, gap, t_before, t_gap, t_after):
        return _fill_in_time(
            sum_before, n_before, sum_after, n_after, unit,
            float(t_before or 0.0), [float(d) for d in t_gap], float(t_after or 0.0),
        )  # fmt: skip
    g = gap
    if n_before and n_after:
        m_a, m_b = sum_before / n_before, sum_after / n_after
        c_a = -(n_before - 1) / 2.0  # window centres, polls of the gap numbered 1..G
        c_b = g + 1 + (n_after - 1) / 2.0
        step = (m_b - m_a) / (c_b - c_a)
        first = m_a + step * (1 - c_a)
        w_b = ((g + 1) / 2.0 - c_a) / (c_b - c_a)
        w_a = 1.0 - w_b
        var_q = g * g * (w_a * w_a / n_before**2 + w_b * w_b / n_after**2) * _REMAINDER_VAR
        spread = g * (m_b - m_a)
    elif n_before or n_after:
        n = n_before or n_after
        first = (sum_before if n_before else sum_after) / n
        step = 0.0
        var_q = g * g / (n * n) * _REMAINDER_VAR
        spread = g * first
    else:
        return GapFill(g, 0.0, 0.0, 0.0, math.inf)
    total = g * first + step * g * (g - 1) / 2.0
    sigma = math.sqrt(var_q * unit * unit + spread * spread / 12.0)
    return GapFill(g, first, step, total, sigma)


def _per_poll(n_before, n_after, gap, t_before, t_gap, t_after) -> bool:
    """True when the intervals say nothing the poll count does not: all equal (the
    time rule is then the per-poll one), or some not > 0 (no usable stamps)."""
    if len(t_gap) != gap:
        raise ValueError(f"{gap} lifted polls but {len(t_gap)} intervals")
    d = t_gap[0]
    if not all(t > 0 for t in t_gap) or (n_before and not (t_before or 0) > 0):
        return True
    if n_after and not (t_after or 0) > 0:
        return True
    return (
        all(t == d for t in t_gap)
        and (not n_before or t_before == n_before * d)
        and (not n_after or t_after == n_after * d)
    )


def _fill_in_time(
    sum_before: float, n_before: int, sum_after: float, n_after: int, unit: float,
    t_before: float, t_gap: list[float], t_after: float,
) -> GapFill:  # fmt: skip
    """:func:`fill_gap` per unit of time: rates are counts over the windows' durations,
    each lifted poll gets the line's mean over its own interval times the interval."""
    g = len(t_gap)
    t_g = math.fsum(t_gap)
    starts = [0.0]
    for d in t_gap[:-1]:
        starts.append(starts[-1] + d)
    if n_before and n_after:
        m_a, m_b = sum_before / t_before, sum_after / t_after  # per unit of time
        c_a, c_b = -t_before / 2.0, t_g + t_after / 2.0  # window centres, gap from 0 to t_g
        lam = [(s + d / 2.0 - c_a) / (c_b - c_a) for s, d in zip(starts, t_gap, strict=True)]
        values = tuple(d * (m_a + (m_b - m_a) * w) for d, w in zip(t_gap, lam, strict=True))
        # the gap's time carried by each window mean
        w_b = math.fsum(d * w for d, w in zip(t_gap, lam, strict=True))
        w_a = t_g - w_b
        var_q = (w_a * w_a / t_before**2 + w_b * w_b / t_after**2) * _REMAINDER_VAR
        spread = t_g * (m_b - m_a)
    elif n_before or n_after:
        m, t = (sum_before, t_before) if n_before else (sum_after, t_after)
        values = tuple(d * m / t for d in t_gap)
        var_q = (t_g / t) ** 2 * _REMAINDER_VAR
        spread = t_g * m / t
    else:
        return GapFill(g, 0.0, 0.0, 0.0, math.inf)
    sigma = math.sqrt(var_q * unit * unit + spread * spread / 12.0)
    return GapFill(g, values[0], 0.0, math.fsum(values), sigma, values)


def gap_runs(lifted: Sequence[bool]) -> list[tuple[int, int]]:
    """The (start, stop) index ranges of consecutive lifted polls."""
    runs = []
    start = None
    for i, flag in enumerate(lifted):
        if flag and start is None:
            start = i
        elif not flag and start is not None:
            runs.append((start, i))
            start = None
    if start is not None:
        runs.append((start, len(lifted)))
    return runs


def fill_sequence(
    values: Sequence[float],
    lifted: Sequence[bool],
    window: int = WINDOW,
    unit: float = 1.0,
    dt: Sequence[float] | None = None,
) -> tuple[list[float], list[tuple[int, GapFill]]]:
    """Every lifted poll of a recorded sequence replaced by its estimate.

    ``dt``: each poll's own interval (from the stamps, e.g. s): the rule then runs
    per unit of time (:func:`fill_gap`); None: every poll one interval.
    Returns the filled values (a new list; good polls unchanged) and, per gap,
    (its first index, its :class:`GapFill`).
    """
    if len(values) != len(lifted):
        raise ValueError(f"{len(values)} values but {len(lifted)} lift flags")
    if dt is not None and len(dt) != len(values):
        raise ValueError(f"{len(values)} values but {len(dt)} intervals")
    out = [float(v) for v in values]
    runs = gap_runs(lifted)
    gaps = []
    prev_stop = 0
    for j, (start, stop) in enumerate(runs):
        next_start = runs[j + 1][0] if j + 1 < len(runs) else len(out)
        lo = max(prev_stop, start - window)
        hi = min(next_start, stop + window)
        t_a = t_b = None
        if dt is not None:
            t_a, t_b = math.fsum(dt[lo:start]), math.fsum(dt[stop:hi])
        fill = fill_gap(
            math.fsum(values[lo:start]), start - lo, stop - start,
            math.fsum(values[stop:hi]), hi - stop, unit,
            t_before=t_a, t_gap=None if dt is None else dt[start:stop], t_after=t_b,
        )  # fmt: skip
        out[start:stop] = [0.0] * fill.polls if fill.sigma == math.inf else fill.per_poll()
        gaps.append((start, fill))
        prev_stop = stop
    return out, gaps
