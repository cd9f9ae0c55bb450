"""How uncertain the gap-filled counts a pose used are: the lift-fill variance per step batch.

Pure numpy, no ROS. A lifted poll's counts are replaced by the window estimate of
:mod:`pln2033.lift_fill` (the one rule the board's poller and
:class:`mm_pc.core.polls.PollTracker` fill with); that rule also gives each gap's
1-sigma uncertainty: the window means' rounding plus a uniform spread between the
rates before and after the gap, ``(G * (m_b - m_a))^2 / 12`` (one-sided:
``(G * m)^2 / 12``), so it grows with the distance filled. The rule runs per unit of
time on the steps' own intervals (``dt``), as the tracker fills. mm-mouse's SensorData has
no field for it; a client with the polls (mm-odometry) recomputes it here from the
polls' own lift flags and counts, with the same rule.

Only filled counts the pose really used count: a method that drops a lifted sensor
(``two-sensor``) or switches away from it (``exact``) never integrates the estimate.
Which sensors a step used is read from the method's ``body_map(lifted)`` (a sensor
whose columns are 0 is not used); a gap of G polls of which k were used adds
``(k / G)^2 * sigma^2`` (the estimate is one straight line, so the used part's error
is that share of the total's).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np

from mm_pc.core.filters import fill_lift_gaps
from mm_pc.core.polls import LIFT_CONTEXT_POLLS, PollSteps

__all__ = ["FillVariance"]


class FillVariance:
    """Per batch of :class:`~mm_pc.core.polls.PollSteps`, the variance (m², per axis) of
    the filled counts each sensor's steps carried into the pose.

    Keeps the last :data:`~mm_pc.core.polls.LIFT_CONTEXT_POLLS` steps as the windows'
    left context, as the tracker does (a gap step from the totals starts afresh).
    """

    def __init__(self, n_sensors: int) -> None:
        self.n = int(n_sensors)
        #: variance added so far (m², per axis, summed over the sensors)
        self.total_var_m2 = 0.0
        self.reset()

    def reset(self) -> None:
        """Forget the context (a new baseline); the running total stays."""
        self._ctx_counts = np.zeros((0, self.n, 2), np.int64)
        self._ctx_lifted = np.zeros((0, self.n), bool)
        self._ctx_dt = np.zeros(0)

    def of_steps(
        self,
        steps: PollSteps,
        body_map: Callable[[tuple[bool, ...]], np.ndarray],
        unit_m: Sequence[float],
    ) -> np.ndarray:
        """(n,) variance per sensor (m² per axis; the larger of its X and Y) of the
        filled counts these steps hand to the pose. ``body_map``: the odometry's
        ``body_map(lifted)``; ``unit_m``: each sensor's metres per count."""
        out = np.zeros(self.n)
        if not len(steps):
            return out
        if len(steps) == 1 and steps.gap[0] and not steps.counts.any():
            self.reset()  # a gap step from the totals: the tracker took a new baseline
            return out
        c0 = len(self._ctx_counts)
        counts = np.concatenate([self._ctx_counts, steps.counts])
        lifted = np.concatenate([self._ctx_lifted, steps.lifted])
        dt = np.concatenate([self._ctx_dt, steps.dt])
        uses: dict[tuple[bool, ...], np.ndarray] = {}
        for i in range(self.n):
            if not steps.lifted[:, i].any():
                continue
            _, gaps = fill_lift_gaps(counts[:, i, :], lifted[:, i], unit=1.0, dt=dt)
            for start, stop, sigma in gaps:
                if start < c0 or not np.all(np.isfinite(sigma)):
                    continue  # integrated before / nothing to estimate from (filled with 0)
                used = 0
                for row in lifted[start:stop]:
                    key = tuple(bool(v) for v in row)
                    if key not in uses:
                        m = body_map(key)
                        uses[key] = np.array(
                            [bool(m[:, 2 * k : 2 * k + 2].any()) for k in range(self.n)]
                        )
                    used += bool(uses[key][i])
                share = used / (stop - start)
                out[i] += share * share * float(np.max(sigma)) ** 2 * float(unit_m[i]) ** 2
        self._ctx_counts = counts[-LIFT_CONTEXT_POLLS:]
        self._ctx_lifted = lifted[-LIFT_CONTEXT_POLLS:]
        self._ctx_dt = dt[-LIFT_CONTEXT_POLLS:]
        total = float(out.sum())
        if math.isfinite(total):
            self.total_var_m2 += total
        return out
