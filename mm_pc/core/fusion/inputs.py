"""The fusion's input records, and the readers that make them from ROS messages.

Pure Python and numpy: no ROS import. Messages are read duck-typed (only
their field names are used), so the same functions take real
``sensor_msgs``/``nav_msgs`` objects in mm-fusion and plain stand-ins in
tests. What each message means here:

Derivations and measurements: docs/maps-and-fixes.md,
section "mm_pc.core.fusion.inputs in detail".
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from mm_pc.core.angles import compass_to_rep103, quaternion_yaw
from mm_pc.core.checks import finite
from mm_pc.core.fixes.gps import LocalGrid
from mm_pc.core.odometry import Pose2D

__all__ = [
    "NAVSAT_STATUS_FIXES",
    "AxisInput",
    "HeadingInput",
    "InputError",
    "MotionInput",
    "PositionInput",
    "RangeInput",
    "UnusableInputError",
    "gps_inflation",
    "heading_input",
    "imu_input",
    "inflate_for_correlation",
    "navsat_input",
    "odometry_input",
    "perimeter_input",
    "range_input",
    "seconds_to_stamp",
    "stamp_seconds",
]

# sensor_msgs constants, copied so that this module needs no ROS import.
NAVSAT_STATUS_UNKNOWN, NAVSAT_STATUS_NO_FIX = -2, -1
#: NavSatStatus values that are a position: FIX, SBAS_FIX, GBAS_FIX.
NAVSAT_STATUS_FIXES = frozenset({0, 1, 2})
COVARIANCE_TYPE_UNKNOWN, COVARIANCE_TYPE_APPROXIMATED = 0, 1
COVARIANCE_TYPE_DIAGONAL_KNOWN, COVARIANCE_TYPE_KNOWN = 2, 3



class InputError(ValueError):
    """A message that cannot be used. ``kind``: 'invalid' (malformed) or 'unusable'.

    ``stamp``: the message's stamp (s) when it was readable, else None.
    """

    kind = "invalid"

    def __init__(self, message: str, stamp: float | None = None) -> None:
        super().__init__(message)
        self.stamp = stamp


class UnusableInputError(InputError):
    """A well-formed message without a usable reading (no fix, accuracy too poor, ...)."""

    kind = "unusable"


# --- records -------------------------------------------------------------------------------


@dataclass(frozen=True)
class MotionInput:
    """An odometry pose: ``source`` 'mouse' or 'wheel'; stamp s; pose in ``frame_id``."""

    stamp: float
    source: str
    frame_id: str
    pose: Pose2D


@dataclass(frozen=True)
class PositionInput:
    """A position fix (x, y) m in the map frame with its 2x2 covariance (m^2).

    ``gate_cov``: the covariance to gate with when ``cov`` is inflated for
    time-correlated errors (:meth:`mm_pc.core.fusion.ekf.PoseEKF.update_position`).
    """

    stamp: float
    source: str
    xy: tuple[float, float]
    cov: tuple[tuple[float, float], tuple[float, float]]
    gate_cov: tuple[tuple[float, float], tuple[float, float]] | None = None


@dataclass(frozen=True)
class HeadingInput:
    """An absolute REP 103 yaw (rad) with variance (rad^2); stamp None = apply on arrival."""

    stamp: float | None
    source: str
    yaw: float
    var: float


@dataclass(frozen=True)
class RangeInput:
    """A slant range (m) to one beacon (object with x, y, height in m) with sigma (m)."""

    stamp: float
    source: str
    beacon: object
    range: float
    sigma: float


@dataclass(frozen=True)
class AxisInput:
    """A wire contact: ``axis`` 'x'/'y' and ``value`` m, or both None = nearest wire."""

    stamp: float
    source: str
    axis: str | None
    value: float | None


# --- small conversions --------------------------------------------------------------------------


def _finite(name: str, value) -> float:
    return finite(name, value, InputError)


def stamp_seconds(stamp) -> float:
    """builtin_interfaces/Time -> seconds. A zero (unset) or malformed stamp is invalid."""
    try:
        sec, nsec = int(stamp.sec), int(stamp.nanosec)
    except (AttributeError, TypeError, ValueError):
        raise InputError(f"stamp must have integer sec and nanosec, got {stamp!r}") from None
    if not 0 <= nsec < 1_000_000_000:
        raise InputError(f"stamp nanosec must be in 0..999999999, got {nsec}")
    if sec < 0 or (sec == 0 and nsec == 0):
        raise InputError(f"stamp must be set (> 0), got {sec}.{nsec:09d} s")
    return sec + nsec * 1e-9


def seconds_to_stamp(t: float) -> tuple[int, int]:
    """Seconds (>= 0) -> (sec, nanosec) for builtin_interfaces/Time."""
    if not (math.isfinite(t) and t >= 0):
        raise ValueError(f"time must be finite and >= 0 s, got {t}")
    ns = round(t * 1e9)
    return ns // 1_000_000_000, ns % 1_000_000_000


def _yaw(orientation) -> float:
    """The yaw of a geometry_msgs/Quaternion; a broken one is an invalid input."""
    o = orientation
    try:
        return quaternion_yaw(o.x, o.y, o.z, o.w)
    except ValueError as exc:
        raise InputError(str(exc)) from None


def _frame(header, expected: str, what: str) -> str:
    frame = str(getattr(header, "frame_id", ""))
    if expected and frame != expected:
        raise InputError(f"{what} frame_id must be '{expected}', got '{frame}'")
    return frame


# --- message converters ---------------------------------------------------------------------


def odometry_input(msg, source: str, base_frame: str) -> MotionInput:
    """nav_msgs/Odometry -> :class:`MotionInput` (the planar pose of ``base_frame``)."""
    stamp = stamp_seconds(msg.header.stamp)
    if msg.child_frame_id != base_frame:
        raise InputError(
            f"{source} odometry child_frame_id must be '{base_frame}', got '{msg.child_frame_id}'"
        )
    if not msg.header.frame_id:
        raise InputError(f"{source} odometry has an empty frame_id")
    p, o = msg.pose.pose.position, msg.pose.pose.orientation
    x, y = _finite("odometry x", p.x), _finite("odometry y", p.y)
    yaw = _yaw(o)
    return MotionInput(stamp, source, msg.header.frame_id, Pose2D(x, y, yaw))


def navsat_input(
    msg,
    grid: LocalGrid,
    *,
    default_sigma: float,
    max_sigma: float,
    frame: str = "",
    source: str = "gps",
) -> PositionInput:
    """sensor_msgs/NavSatFix -> :class:`PositionInput` in plot metres (see the module text).

    ``default_sigma``: m per axis when the covariance type is UNKNOWN;
    ``max_sigma``: m, a larger standard deviation on either axis is unusable;
    ``frame``: the required frame_id ('' = any).
    """
    stamp = stamp_seconds(msg.header.stamp)
    _frame(msg.header, frame, "NavSatFix")
    status = int(msg.status.status)
    if status in (NAVSAT_STATUS_NO_FIX, NAVSAT_STATUS_UNKNOWN):
        raise UnusableInputError(f"NavSatFix status {status} is not a fix", stamp)
    if status not in NAVSAT_STATUS_FIXES:
        raise InputError(f"NavSatFix status must be in -2..2, got {status}")
    lat, lon = _finite("latitude", msg.latitude), _finite("longitude", msg.longitude)
    try:
        x, y = grid.to_local(lat, lon)
    except ValueError as exc:
        raise InputError(f"NavSatFix position: {exc}") from None
    cov = _navsat_covariance(msg, default_sigma)
    worst = math.sqrt(float(np.linalg.eigvalsh(np.array(cov))[-1]))
    if worst > max_sigma:
        raise UnusableInputError(
            f"GPS fix too inaccurate: sigma {worst:.2f} m > {max_sigma:g} m", stamp
        )
    return PositionInput(stamp, source, (float(x), float(y)), cov)


def _navsat_covariance(msg, default_sigma: float):
    kind = int(msg.position_covariance_type)
    if kind == COVARIANCE_TYPE_UNKNOWN:
        v = default_sigma * default_sigma
        return ((v, 0.0), (0.0, v))
    if kind not in (
        COVARIANCE_TYPE_APPROXIMATED,
        COVARIANCE_TYPE_DIAGONAL_KNOWN,
        COVARIANCE_TYPE_KNOWN,
    ):
        raise InputError(f"NavSatFix position_covariance_type must be in 0..3, got {kind}")
    c = [_finite("NavSatFix position_covariance", v) for v in msg.position_covariance]
    if len(c) != 9:
        raise InputError(f"NavSatFix position_covariance must have 9 values, got {len(c)}")
    exx, enn = c[0], c[4]
    exn = 0.5 * (c[1] + c[3]) if kind == COVARIANCE_TYPE_KNOWN else 0.0
    if not (exx > 0 and enn > 0 and exn * exn < exx * enn):
        raise InputError(
            "NavSatFix east/north covariance must be positive definite, "
            f"got [[{exx}, {exn}], [{exn}, {enn}]] m^2"
        )
    return ((exx, exn), (exn, enn))


def imu_input(
    msg, *, default_var: float, offset: float = 0.0, frame: str = "", source: str = "compass"
) -> HeadingInput:
    """sensor_msgs/Imu orientation -> REP 103 :class:`HeadingInput` (yaw + ``offset`` rad).

    ``offset``: added to the yaw (rad; magnetic declination and mounting),
    ``default_var``: rad^2 when the message gives no yaw variance.
    """
    stamp = stamp_seconds(msg.header.stamp)
    _frame(msg.header, frame, "Imu")
    cov = msg.orientation_covariance
    if float(cov[0]) == -1.0:
        raise UnusableInputError("Imu has no orientation (orientation_covariance[0] == -1)", stamp)
    o = msg.orientation
    yaw = _yaw(o) + offset
    var = _finite("Imu yaw variance", cov[8])
    if var < 0:
        raise InputError(f"Imu yaw variance must be >= 0 rad^2, got {var}")
    return HeadingInput(stamp, source, yaw, var if var > 0 else default_var)


def heading_input(
    value: float, *, var: float, offset: float = 0.0, source: str = "compass"
) -> HeadingInput:
    """A compass heading (rad, 0 = north, clockwise: the seed's) -> REP 103, unstamped."""
    h = _finite("compass heading", value)
    return HeadingInput(None, source, float(compass_to_rep103(h)) + offset, var)


def range_input(
    msg, beacon, *, sigma: float, frame: str = "", source: str = "beacon"
) -> RangeInput:
    """sensor_msgs/Range to ``beacon`` -> :class:`RangeInput` (see the module text)."""
    stamp = stamp_seconds(msg.header.stamp)
    _frame(msg.header, frame, "Range")
    r, lo, hi = float(msg.range), float(msg.min_range), float(msg.max_range)
    if math.isnan(lo) or math.isnan(hi) or lo < 0 or lo > hi:
        raise InputError(
            f"Range limits must satisfy 0 <= min_range <= max_range, got {lo:g}, {hi:g}"
        )
    if math.isinf(r):
        what = "too close" if r < 0 else "nothing detected"
        raise UnusableInputError(f"Range {r} (REP 117: {what})", stamp)
    if not lo <= r <= hi:
        raise InputError(f"Range {r:g} m outside [min_range, max_range] = [{lo:g}, {hi:g}] m")
    return RangeInput(stamp, source, beacon, r, sigma)


def perimeter_input(msg, map_frame: str, source: str = "perimeter") -> AxisInput:
    """geometry_msgs/PointStamped wire contact -> :class:`AxisInput` (see the module text)."""
    stamp = stamp_seconds(msg.header.stamp)
    x, y = float(msg.point.x), float(msg.point.y)
    if math.isinf(x) or math.isinf(y):
        raise InputError(f"perimeter contact must be finite or NaN, got ({x}, {y})")
    if math.isnan(x) and math.isnan(y):
        return AxisInput(stamp, source, None, None)
    if not (math.isnan(x) or math.isnan(y)):
        raise InputError(
            f"perimeter contact gives both x = {x} and y = {y}; a wire fixes one "
            "coordinate: set the other to NaN (or both NaN: nearest wire)"
        )
    _frame(msg.header, map_frame, "perimeter contact")
    return AxisInput(stamp, source, "y", y) if math.isnan(x) else AxisInput(stamp, source, "x", x)


# --- time-correlated errors ---------------------------------------------------------------------


def gps_inflation(interval_s: float, tau_s: float) -> float:
    """Factor on a GPS fix's variance so that a stream of them counts as what it is worth.

    For a first-order Gauss-Markov error with correlation exp(-interval/tau)
    = phi between fixes, the mean of n fixes has the variance of
    n (1 - phi) / (1 + phi) independent ones; weighting every fix by that
    fraction, i.e. inflating its variance by (1 + phi) / (1 - phi), keeps the
    filter from believing it averaged the error away.
    """
    if not (interval_s > 0 and tau_s > 0):
        raise ValueError(f"interval and tau must be > 0 s, got {interval_s}, {tau_s}")
    phi = math.exp(-interval_s / tau_s)
    return (1 + phi) / (1 - phi)


def inflate_for_correlation(fix: PositionInput, factor: float) -> PositionInput:
    """``fix`` weighted by ``factor`` (:func:`gps_inflation`), gated with its own covariance.

    A filter takes each fix as independent news; fixes every 0.5 s of an error that wanders
    over 30 s are not, and without this the filter believes it averaged the error away.
    """
    (a, b), (c, d) = fix.cov
    cov = ((factor * a, factor * b), (factor * c, factor * d))
    return replace(fix, cov=cov, gate_cov=fix.cov)
