"""Angles: the one wrap, compass <-> REP 103, and yaw <-> quaternion.

Convention: a wrapped angle is in (-pi, pi], the range of ``atan2`` (every yaw read from a
vector or a quaternion is already there); a compass heading (the seeds': 0 = north,
clockwise) is in [0, 2 pi). Poses keep their yaw continuous (:class:`.odometry.Pose2D`) and
wrap only for display or an innovation. Functions take scalars or numpy arrays and refuse
non-finite input with a ValueError.
"""

from __future__ import annotations

import math

import numpy as np

from mm_pc.core.checks import finite, finite_array
from pln2033.angles import TWO_PI
from pln2033.angles import wrap_pi as _wrap_scalar

__all__ = [
    "TWO_PI",
    "compass_to_rep103",
    "quaternion_yaw",
    "rep103_to_compass",
    "wrap_pi",
    "yaw_to_quaternion",
]


def _like_input(value, result: np.ndarray):
    """A Python float for scalar input, the array otherwise."""
    return float(result) if np.ndim(value) == 0 else result


_wrap_each = np.frompyfunc(_wrap_scalar, 1, 1)


def wrap_pi(angle_rad):
    """Angle(s) wrapped to (-pi, pi] (rad): :func:`pln2033.angles.wrap_pi`, the one wrap (the
    OTOS driver's too; why its range suits the chip: there), element-wise for an array."""
    if isinstance(angle_rad, (float, int)) and not isinstance(angle_rad, bool):
        return _wrap_scalar(angle_rad)  # the hot path (innovations, increments): no numpy
    a = finite_array("angle", angle_rad)
    return _like_input(angle_rad, np.asarray(_wrap_each(a), dtype=float))


def _wrap_2pi(angle: np.ndarray) -> np.ndarray:
    w = np.mod(angle, TWO_PI)
    return np.where(w >= TWO_PI, 0.0, w)


def compass_to_rep103(heading_rad):
    """Compass heading (0 = north = +y, clockwise+) -> REP 103 yaw (0 = east = +x, CCW+).

    Result in (-pi, pi] rad. North -> pi/2, east -> 0, south -> -pi/2, west -> pi.
    """
    h = finite_array("compass heading", heading_rad)
    return wrap_pi(_like_input(heading_rad, math.pi / 2 - h))


def rep103_to_compass(yaw_rad):
    """REP 103 yaw (0 = east, CCW+) -> compass heading (0 = north, clockwise+) in [0, 2*pi)."""
    y = finite_array("yaw", yaw_rad)
    return _like_input(yaw_rad, _wrap_2pi(math.pi / 2 - y))


def yaw_to_quaternion(yaw: float) -> tuple[float, float, float, float]:
    """(x, y, z, w) of a rotation by ``yaw`` (rad) about +z."""
    return 0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2)


def quaternion_yaw(x: float, y: float, z: float, w: float) -> float:
    """Yaw (rad, (-pi, pi]) of a quaternion (x, y, z, w) of any length > 0.

    The rotation's heading about +z (z-y-x Euler yaw), so a tilted compass or IMU still
    gives its heading. ValueError for a non-finite or (near) zero quaternion.
    """
    q = [finite(f"quaternion {n}", v) for n, v in zip("xyzw", (x, y, z, w), strict=True)]
    norm2 = sum(c * c for c in q)
    if not norm2 > 1e-12:
        raise ValueError(f"quaternion {tuple(q)} has (near) zero length; it must be a rotation")
    qx, qy, qz, qw = q
    return math.atan2(2.0 * (qw * qz + qx * qy), norm2 - 2.0 * (qy * qy + qz * qz))
