"""Estimate the counts a sensor lost while lifted, poll by poll (the board's side).

While the lift bit is set the sensor clears its counters and counts nothing. The
rule is :mod:`pln2033.lift_fill` (the same one the PC's per-poll filter uses):
the mean of up to :data:`~pln2033.lift_fill.WINDOW` good polls before the gap and
of up to WINDOW after it, a straight line between the window centres, and a
1-sigma uncertainty of the estimate. Streaming makes one difference: the estimate
is known when the after-window is full (WINDOW good polls after the gap) or a
second lift starts inside it (then with the good polls seen so far, which are
also the next gap's before-window).

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
        self._before: deque[tuple[float, float]] = deque(maxlen=window)
        self._after: list[tuple[float, float]] = []

    def prime(self, polls: Iterable[tuple[float, float]]) -> None:
        """The good polls right before now (oldest first); replaces what was seen."""
        if not self.busy:
            self._before.clear()
            self._before.extend(polls)

    def update(self, dx: float, dy: float, lifted: bool) -> GapEstimate | None:
        """One poll; returns (x, y, sigma x, sigma y) of a gap whose estimate is complete."""
        if lifted:
            out = None
            if self._after:  # a second lift inside the after-window: close the first gap
                out = self._close()
                self._before.clear()  # a window never reaches across a lift
                self._before.extend(self._after)
                self._after = []
            self.gap += 1
            self.busy = True
            return out
        if not self.busy:
            self._before.append((dx, dy))
            return None
        self._after.append((dx, dy))
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
        return fx.total, fy.total, fx.sigma, fy.sigma

    def _fills(self) -> tuple[GapFill, GapFill]:
        b, a = self._before, self._after
        bx, by, ax, ay = (math.fsum(p[k] for p in w) for w in (b, a) for k in (0, 1))
        fx = fill_gap(bx, len(b), self.gap, ax, len(a), self.unit)  # fsum: as fill_sequence
        fy = fill_gap(by, len(b), self.gap, ay, len(a), self.unit)
        return fx, fy
