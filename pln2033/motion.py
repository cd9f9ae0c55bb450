"""Motion sources: the true displacement the emulated sensor sees over time.

Positions are in metres in the sensor's own frame (+x to the robot's right,
+y forward); times in seconds on the emulator's clock. A source answers
``displacement(t0, t1)``; the emulator turns that into counts.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Protocol


class MotionSource(Protocol):
    def displacement(self, t0: float, t1: float) -> tuple[float, float]:
        """Sensor-frame displacement (x, y) in metres between times t0 <= t1."""
        ...


class Stationary:
    """A sensor that never moves."""

    def displacement(self, t0: float, t1: float) -> tuple[float, float]:
        return 0.0, 0.0


class ConstantVelocity:
    """Constant velocity (vx, vy) in m/s in the sensor frame."""

    def __init__(self, vx: float, vy: float) -> None:
        self.vx, self.vy = vx, vy

    def displacement(self, t0: float, t1: float) -> tuple[float, float]:
        dt = t1 - t0
        return self.vx * dt, self.vy * dt


class SampledPath:
    """Cumulative sensor-frame position sampled every ``dt`` seconds from ``t_start``.

    Between samples the position is interpolated linearly. Past the end the
    position holds (the robot stands still), or with ``loop=True`` the path
    repeats, each lap starting where the previous one ended.

    Scalar lookups use plain lists: this runs twice per 1 kHz poll.
    """

    def __init__(
        self,
        x: Sequence[float],
        y: Sequence[float],
        dt: float,
        t_start: float = 0.0,
        loop: bool = False,
    ) -> None:
        if len(x) != len(y) or len(x) < 2:
            raise ValueError("SampledPath needs two equally long position lists of length >= 2")
        if not dt > 0:
            raise ValueError(f"dt must be > 0, got {dt}")
        self._x = [float(v) - float(x[0]) for v in x]
        self._y = [float(v) - float(y[0]) for v in y]
        self.dt = dt
        self.t_start = t_start
        self.loop = loop
        self._n = len(self._x) - 1  # number of intervals
        self.duration = self._n * dt
        self._cache: tuple[float, float, float] = (t_start, 0.0, 0.0)  # consecutive calls share a t

    def position(self, t: float) -> tuple[float, float]:
        """Cumulative position at time t (metres, sensor frame)."""
        s = (t - self.t_start) / self.dt
        if s <= 0.0:
            return 0.0, 0.0
        laps = 0
        if s >= self._n:
            if not self.loop:
                return self._x[-1], self._y[-1]
            laps = int(s // self._n)
            s -= laps * self._n
        i = int(s)
        f = s - i
        x0, y0 = self._x[i], self._y[i]
        if f:
            x0 += (self._x[i + 1] - x0) * f
            y0 += (self._y[i + 1] - y0) * f
        if laps:
            x0 += laps * self._x[-1]
            y0 += laps * self._y[-1]
        return x0, y0

    def displacement(self, t0: float, t1: float) -> tuple[float, float]:
        ct, cx, cy = self._cache
        x0, y0 = (cx, cy) if ct == t0 else self.position(t0)
        x1, y1 = self.position(t1)
        self._cache = (t1, x1, y1)
        return x1 - x0, y1 - y0


class Rotated:
    """Another source seen through a sensor mounted ``yaw`` radians off.

    Models a mounting error: the sensor's axes are turned by ``yaw`` (CCW,
    seen from above) relative to the ideal axes, so the reported vector is
    the ideal one turned by -yaw.
    """

    def __init__(self, source: MotionSource, yaw: float) -> None:
        self.source = source
        self._c, self._s = math.cos(yaw), math.sin(yaw)

    def displacement(self, t0: float, t1: float) -> tuple[float, float]:
        dx, dy = self.source.displacement(t0, t1)
        return self._c * dx + self._s * dy, -self._s * dx + self._c * dy
