"""Wheel odometry of a differential drive (seed 004), exact on the arc, and the compass blend.

:class:`WheelOdometry` integrates wheel travel with the same arc as the mouse odometry
(:func:`mm_pc.core.odometry.arc_poses`) and blends compass headings on the circle. Why the
seed's own steps are not used (they are kept in :mod:`.seed_rules`): docs/maps-and-fixes.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from mm_pc.core.angles import compass_to_rep103, wrap_pi
from mm_pc.core.checks import finite as _finite
from mm_pc.core.checks import finite_array as _finite_array
from mm_pc.core.checks import positive as _positive
from mm_pc.core.odometry import Pose2D, arc_poses

__all__ = [
    "WheelOdometry",
    "blend_heading",
    "body_increment",
    "tick_length",
]


def blend_heading(odom_yaw, compass_yaw, weight: float):
    """Complementary blend of two REP 103 yaws (rad): odom + weight*wrap(compass - odom).

    ``weight`` in [0, 1]: 0 keeps the odometry yaw, 1 takes the compass. The
    step goes the short way round the circle and the result stays on the
    odometry yaw's branch (not wrapped), so a continuous yaw stays continuous.
    Convert a compass reading with :func:`compass_to_rep103` first.
    """
    w = _finite("weight", weight)
    if not 0.0 <= w <= 1.0:
        raise ValueError(f"weight must be in [0, 1], got {weight!r}")
    o = _finite_array("odometry yaw", odom_yaw)
    c = _finite_array("compass yaw", compass_yaw)
    out = o + w * np.asarray(wrap_pi(c - o))
    return float(out) if out.ndim == 0 else out


def tick_length(wheel_diameter_m: float, ticks_per_rev: int) -> float:
    """Wheel travel per encoder tick (m): pi * diameter / ticks per revolution.

    The seed's wheel: 0.18 m, 12 ticks -> 0.0471 m ("47 mm").
    """
    d = _positive("wheel diameter (m)", wheel_diameter_m)
    if isinstance(ticks_per_rev, bool) or not isinstance(ticks_per_rev, int | np.integer):
        raise ValueError(f"ticks per revolution must be an integer >= 1, got {ticks_per_rev!r}")
    if ticks_per_rev < 1:
        raise ValueError(f"ticks per revolution must be an integer >= 1, got {ticks_per_rev!r}")
    return math.pi * d / int(ticks_per_rev)


def body_increment(d_left: float, d_right: float, track_width: float) -> tuple[float, float, float]:
    """Differential-drive body increment: (forward m, left m, dtheta rad, CCW+).

    ``d_left``/``d_right``: wheel travel in m (forward positive);
    ``track_width``: distance between the wheels' contact points (m). The
    lateral part is 0 (wheels do not slip sideways).
    """
    dl = _finite("left wheel travel (m)", d_left)
    dr = _finite("right wheel travel (m)", d_right)
    b = _positive("track width (m)", track_width)
    return 0.5 * (dl + dr), 0.0, (dr - dl) / b


def _check_pose(pose) -> Pose2D:
    if not isinstance(pose, Pose2D):
        raise ValueError(f"pose must be a mm_pc.core.odometry.Pose2D, got {type(pose).__name__}")
    for name in ("x", "y", "yaw"):
        _finite(f"pose {name}", getattr(pose, name))
    return pose


@dataclass
class WheelOdometry:
    """Pose of a differential-drive robot from wheel travel, REP 103, arc-exact.

    ``track_width``: m between the wheels. ``metres_per_tick``: wheel travel
    per encoder tick (m, see :func:`tick_length`), only needed for
    :meth:`update_ticks`. ``pose``: odom/plot frame, x east, y north (m), yaw
    CCW+ from east (rad, continuous).
    """

    track_width: float
    metres_per_tick: float | None = None
    pose: Pose2D = field(default_factory=Pose2D)

    def __post_init__(self) -> None:
        self.track_width = _positive("track width (m)", self.track_width)
        if self.metres_per_tick is not None:
            self.metres_per_tick = _positive("metres per tick", self.metres_per_tick)
        _check_pose(self.pose)

    def body_increment(self, d_left: float, d_right: float) -> tuple[float, float, float]:
        """(forward m, left m, dtheta rad) for wheel travels in m; see :func:`body_increment`."""
        return body_increment(d_left, d_right, self.track_width)

    def update(self, d_left: float, d_right: float) -> Pose2D:
        """Advance by one step of wheel travel (m); returns the new pose.

        Exact when the wheel speed ratio is constant over the step (straight,
        curves, spins, pivots about one wheel).
        """
        a, _, c = self.body_increment(d_left, d_right)
        x, y, yaw = arc_poses(self._start(), np.array([a]), None, np.array([c]))[0]
        self.pose = Pose2D(float(x), float(y), float(yaw))
        return self.pose

    def update_ticks(self, ticks_left: float, ticks_right: float) -> Pose2D:
        """:meth:`update` with encoder ticks, scaled by ``metres_per_tick``."""
        if self.metres_per_tick is None:
            raise ValueError("update_ticks needs metres_per_tick; set it (see tick_length)")
        tl = _finite("left ticks", ticks_left)
        tr = _finite("right ticks", ticks_right)
        return self.update(tl * self.metres_per_tick, tr * self.metres_per_tick)

    def integrate(self, d_left, d_right) -> np.ndarray:
        """Many steps at once: arrays of wheel travel (m) -> (N, 3) poses after each step.

        The last row becomes :attr:`pose`.
        """
        dl = _finite_array("left wheel travels (m)", d_left).ravel()
        dr = _finite_array("right wheel travels (m)", d_right).ravel()
        if dl.shape != dr.shape:
            raise ValueError(f"left and right travels differ in length: {dl.size} vs {dr.size}")
        if dl.size == 0:
            return np.empty((0, 3))
        out = arc_poses(self._start(), 0.5 * (dl + dr), None, (dr - dl) / self.track_width)
        self.pose = Pose2D(*(float(v) for v in out[-1]))
        return out

    def pivot(self, d_wheel: float, about: str) -> Pose2D:
        """Turn about one standing wheel: the other wheel travels ``d_wheel`` (m, forward +).

        ``about="left"``: the left wheel stands, the right drives; forward
        travel turns the robot left (CCW) by d_wheel/track_width. The centre
        rotates about the standing wheel (the seed's two steps, with one
        consistent sense of rotation).
        """
        d = _finite("pivot wheel travel (m)", d_wheel)
        if about not in ("left", "right"):
            raise ValueError(f"about must be 'left' or 'right', got {about!r}")
        side = 1.0 if about == "left" else -1.0
        x, y, yaw = self._start()
        half = 0.5 * self.track_width
        # Standing wheel: half a track to the robot's left (side +1) or right (-1).
        wx, wy = x - side * half * math.sin(yaw), y + side * half * math.cos(yaw)
        c = side * d / self.track_width
        cc, sc = math.cos(c), math.sin(c)
        rx, ry = x - wx, y - wy
        self.pose = Pose2D(wx + cc * rx - sc * ry, wy + sc * rx + cc * ry, yaw + c)
        return self.pose

    def blend_compass(self, compass_heading: float, weight: float) -> Pose2D:
        """Blend a compass heading (rad, 0 = north, clockwise+) into the yaw; returns the pose."""
        yaw = blend_heading(self.pose.yaw, compass_to_rep103(compass_heading), weight)
        self.pose = Pose2D(self.pose.x, self.pose.y, yaw)
        return self.pose

    def reset(self, pose: Pose2D | None = None) -> None:
        """Set the pose (default: origin, facing east)."""
        self.pose = _check_pose(Pose2D() if pose is None else pose)

    def _start(self) -> tuple[float, float, float]:
        return self.pose.x, self.pose.y, self.pose.yaw
