"""Ground-truth simulator: a differential-drive robot on scripted paths.

Pure numpy, no ROS, no Qt. A path is a sequence of body twists (v, omega)
held for ``dt`` each (v in m/s along base_link x, omega in rad/s CCW+). From
it the simulator computes what each mounted sensor measures: mouse sensors
integrate the surface velocity in their own (rotating) frame, so for a twist
held constant over a step the sensor-frame displacement of that step is
exact -- no pose integration is involved in the counts.

Frames: base_link per REP 103 (x forward, y left, yaw CCW+). The sensor's own
axes follow the seed: sensor +y = robot forward, sensor +x = robot right.
"""

from __future__ import annotations

import math

import numpy as np

from .geometry import DEFAULT_MOUNTS, SensorMount

__all__ = ["DEFAULT_MOUNTS", "SensorMount"]

DT = 0.001  # s, one 1 kHz poll


DEFAULT_AXIS_LENGTH = 0.079


def sensor_displacements(
    v: np.ndarray, omega: np.ndarray, dt: float, mount: SensorMount
) -> tuple[np.ndarray, np.ndarray]:
    """Per-step sensor-frame displacement (dX right, dY forward) in metres.

    The sensor at base_link (px, py) moves with body velocity
    (v - omega*py, omega*px); in sensor axes (X = -base_link y, Y = base_link x)
    that is X = -omega*px, Y = v - omega*py, then turned by the mounting error.
    """
    ideal_x = -omega * mount.x * dt
    ideal_y = (v - omega * mount.y) * dt
    c, s = math.cos(mount.yaw), math.sin(mount.yaw)
    return c * ideal_x + s * ideal_y, -s * ideal_x + c * ideal_y


def integrate_pose(v: np.ndarray, omega: np.ndarray, dt: float) -> np.ndarray:
    """Exact poses (x, y, yaw) after each step of constant twist, start at 0."""
    yaw_end = np.cumsum(omega * dt)
    yaw_start = yaw_end - omega * dt
    dtheta = omega * dt
    # Chord of the arc: length v*dt*sinc(dtheta/2), heading yaw_start + dtheta/2.
    chord = v * dt * np.sinc(dtheta / (2 * np.pi))
    heading = yaw_start + dtheta / 2
    x = np.cumsum(chord * np.cos(heading))
    y = np.cumsum(chord * np.sin(heading))
    return np.stack([x, y, yaw_end], axis=1)


# --- scripted paths (v, omega per step) ------------------------------------------------


def _segments(parts: list[tuple[float, float, float]], dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Concatenate (duration s, v, omega) segments into per-step arrays."""
    v_parts, w_parts = [], []
    for duration, v, w in parts:
        n = round(duration / dt)
        v_parts.append(np.full(n, v))
        w_parts.append(np.full(n, w))
    return np.concatenate(v_parts), np.concatenate(w_parts)


def straight(speed: float = 0.2, distance: float = 1.0, dt: float = DT):
    return _segments([(distance / abs(speed), speed, 0.0)], dt)


def still(duration: float = 10.0, dt: float = DT):
    return _segments([(duration, 0.0, 0.0)], dt)


def figure_eight(speed: float = 0.2, radius: float = 0.4, dt: float = DT):
    """Two full circles, left then right: ends where it started."""
    w = speed / radius
    lap = 2 * math.pi / w
    return _segments([(lap, speed, w), (lap, speed, -w)], dt)


def square(speed: float = 0.2, side: float = 0.5, turn_rate: float = 1.0, dt: float = DT):
    """Drive a square with pivot turns on the spot (left turns)."""
    parts = []
    for _ in range(4):
        parts.append((side / speed, speed, 0.0))
        parts.append(((math.pi / 2) / turn_rate, 0.0, turn_rate))
    return _segments(parts, dt)


def round_trip(speed: float = 0.2, distance: float = 1.0, turn_rate: float = 1.0, dt: float = DT):
    """The seed's round trip: out, turn on the spot, back."""
    return _segments(
        [
            (distance / speed, speed, 0.0),
            (math.pi / turn_rate, 0.0, turn_rate),
            (distance / speed, speed, 0.0),
        ],
        dt,
    )


TRAJECTORIES = {
    "still": still,
    "straight": straight,
    "figure_eight": figure_eight,
    "square": square,
    "round_trip": round_trip,
}


def trajectory(name: str, speed: float = 0.2, dt: float = DT) -> tuple[np.ndarray, np.ndarray]:
    """A named scripted path at ``speed`` m/s (see TRAJECTORIES)."""
    try:
        fn = TRAJECTORIES[name]
    except KeyError:
        raise ValueError(f"unknown trajectory '{name}'; known: {sorted(TRAJECTORIES)}") from None
    if name == "still":
        return fn(dt=dt)
    if not speed > 0:
        raise ValueError(f"speed must be > 0 m/s, got {speed}")
    return fn(speed=speed, dt=dt)


def cumulative_sensor_path(
    v: np.ndarray, omega: np.ndarray, dt: float, mount: SensorMount
) -> tuple[np.ndarray, np.ndarray]:
    """Cumulative sensor-frame position (starting at 0) at every step boundary."""
    dx, dy = sensor_displacements(v, omega, dt, mount)
    return np.concatenate([[0.0], np.cumsum(dx)]), np.concatenate([[0.0], np.cumsum(dy)])
