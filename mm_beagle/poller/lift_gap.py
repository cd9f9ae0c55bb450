"""Estimate the counts a sensor lost while lifted, poll by poll (the board's side).

While the lift bit is set the sensor clears its counters and counts nothing. The
rule is :mod:`pln2033.lift_fill` (the same one the PC's per-poll filter uses):
the mean of up to :data:`~pln2033.lift_fill.WINDOW` good polls before the gap and
of up to WINDOW after it, a straight line between the window centres, and a
1-sigma uncertainty of the estimate. Streaming makes one difference: the estimate
is known when the after-window is full (WINDOW good polls after the gap) or a
second lift starts inside it (then with the good polls seen so far, which are
also the next gap's before-window). Polls fed with their stamps are filled per unit
of time (each poll's interval = its stamp minus the previous one's), as the PC fills.

No numpy: this runs in the board's poller.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Iterable

from pln2033.lift_fill import WINDOW, GapFill, fill_gap

__all__ = ["WINDOW", "GapEstimate", "LiftGapEstimator"]


GapEstimate = tuple[float, float, float, float]  # (x, y, sigma x, sigma y), counts or metres


class LiftGapEstimator:
    """Per sensor; feed polls in order, get an estimate when a gap's after-window is done.

    ``busy`` is True from the first lifted poll until the estimate is out: only then
    must every poll be fed (the poller's hot path checks this one attribute). While
    not busy the estimator only needs the good polls right before a gap, which the
    poller hands over with :meth:`prime` from its ring instead of feeding each poll.
    ``unit``: one count in the values' unit, for the sigma's remainder term.
    """

    def __init__(self, window: int = WINDOW, unit: float = 1.0) -> None:
        if window < 1:
            raise ValueError(f"the lift-gap window must be >= 1 poll, got {window}")
        self.window = window
        self.unit = unit
        self.busy = False
        self.gap = 0  # lifted polls of the open gap
        # polls as (dx, dy, interval s or None: no stamps)
        self._before: deque[tuple[float, float, float | None]] = deque(maxlen=window)
        self._after: list[tuple[float, float, float | None]] = []
        self._gap_dt: list[float | None] = []
        self._last_ns: int | None = None

    def prime(self, polls: Iterable[tuple], last_stamp_ns: int | None = None) -> None:
        """The good polls right before now (oldest first), as (dx, dy) or (dx, dy,
        interval s); replaces what was seen. ``last_stamp_ns``: the newest one's stamp."""
        if not self.busy:
            self._before.clear()
            self._before.extend((p[0], p[1], p[2] if len(p) > 2 else None) for p in polls)
            self._last_ns = last_stamp_ns

    def update(
        self, dx: float, dy: float, lifted: bool, stamp_ns: int | None = None
    ) -> GapEstimate | None:
        """One poll (``stamp_ns``: its stamp, for the fill per unit of time); returns
        (x, y, sigma x, sigma y) of a gap whose estimate is complete."""
        last, self._last_ns = self._last_ns, stamp_ns
        dt = None if stamp_ns is None or last is None else (stamp_ns - last) / 1e9
        if lifted:
            out = None
            if self._after:  # a second lift inside the after-window: close the first gap
                out = self._close()
                self._before.clear()  # a window never reaches across a lift
                self._before.extend(self._after)
                self._after = []
            self.gap += 1
            self._gap_dt.append(dt)
            self.busy = True
            return out
        if not self.busy:
            self._before.append((dx, dy, dt))
            return None
        self._after.append((dx, dy, dt))
        if len(self._after) < self.window:
            return None
        out = self._close()
        self._before.clear()
        self._before.extend(self._after)
        self._after = []
        self.busy = False
        return out

    def _close(self) -> GapEstimate:
        fx, fy = self._fills()
        self.gap = 0
        self._gap_dt = []
        return fx.total, fy.total, fx.sigma, fy.sigma

    def _fills(self) -> tuple[GapFill, GapFill]:
        b, a = self._before, self._after
        bx, ax = (math.fsum(p[0] for p in w) for w in (b, a))
        by, ay = (math.fsum(p[1] for p in w) for w in (b, a))
        tb = [p[2] for p in b]
        ta = [p[2] for p in a]
        tg = self._gap_dt
        t_before = t_after = t_gap = None  # the intervals, when every poll has one
        if all(d is not None for d in tb + ta + tg):
            t_before = math.fsum(d for d in tb if d is not None)
            t_after = math.fsum(d for d in ta if d is not None)
            t_gap = [d for d in tg if d is not None]
        fx, fy = (
            fill_gap(s_b, len(b), self.gap, s_a, len(a), self.unit,  # fsum: as fill_sequence
                     t_before=t_before, t_gap=t_gap, t_after=t_after)
            for s_b, s_a in ((bx, ax), (by, ay))
        )  # fmt: skip
        return fx, fy
