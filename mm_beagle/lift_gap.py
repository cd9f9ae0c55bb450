"""Estimate the counts a sensor lost while lifted.

While the lift bit is set the sensor clears its counters and counts nothing.
The seed's remedy: interpolate. For a gap of G lifted polls between a good
poll with counts ``a`` before and ``b`` after, poll k of the gap (1..G) is
estimated as a + (b - a) * k / (G + 1), so the gap as a whole is G * (a + b) / 2.
The estimate is only known once the gap has closed (the poll after it).
"""

from __future__ import annotations


class LiftGapEstimator:
    """Per sensor; feed every poll in order, get an estimate when a gap closes."""

    def __init__(self) -> None:
        self.gap = 0
        self.last_x = 0
        self.last_y = 0

    def update(self, dx: int, dy: int, lifted: bool) -> tuple[float, float] | None:
        """One poll; returns the estimated (x, y) counts of a gap that just closed."""
        if lifted:
            self.gap += 1
            return None
        estimate = None
        if self.gap:
            g = self.gap
            estimate = (g * (self.last_x + dx) / 2.0, g * (self.last_y + dy) / 2.0)
            self.gap = 0
        self.last_x, self.last_y = dx, dy
        return estimate
