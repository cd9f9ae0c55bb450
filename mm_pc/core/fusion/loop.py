"""ROS messages <-> the fusion's math types, and the time-ordered front end of the filter.

Pure Python and numpy: no ROS import. Messages are read duck-typed (only
their field names are used), so the same functions take real
``sensor_msgs``/``nav_msgs`` objects in mm-fusion and plain stand-ins in
tests. What each message means here:

``nav_msgs/Odometry`` (mouse odometry, wheel odometry)
    The pose of ``child_frame_id`` (must be the robot's base frame) in
    ``header.frame_id`` (any non-empty name, but constant: a change starts a
    new baseline). Only poses are used; consecutive poses give the body
    increment (fwd, left, dtheta) of :func:`mm_pc.core.fusion.ekf.pose_increment`.
``sensor_msgs/NavSatFix`` (GPS)
    ``status.status`` FIX, SBAS_FIX or GBAS_FIX is a position; NO_FIX and
    UNKNOWN are readings without one (*unusable*); any other value is
    *invalid*. Latitude/longitude go to plot metres by
    :class:`mm_pc.core.fixes.field_fixes.LocalGrid`. ``position_covariance`` is ENU
    (m^2, row-major east, north, up), so its upper-left 2x2 block is the
    covariance of the plot's (x east, y north); with
    ``COVARIANCE_TYPE_UNKNOWN`` a default sigma is used, with APPROXIMATED or
    DIAGONAL_KNOWN only the diagonal. A fix whose larger standard deviation
    exceeds ``max_sigma`` is unusable (HDOP 2 at 2.5 m UERE, the seed's
    limit, is 3.54 m per axis). NavSatFix has no satellite count: a driver
    that knows the fix is too weak must say NO_FIX.
``sensor_msgs/Imu`` (compass)
    Orientation per REP 103/145: ENU world, yaw CCW from east; an Imu never
    needs the seed's compass conversion. ``orientation_covariance[0] == -1``
    means no orientation (unusable); element 8 (yaw, rad^2) is the variance
    when it is > 0, else the default.
``std_msgs/Float64`` (compass, alternative)
    A heading in the seed's convention (rad, 0 = north, clockwise), turned
    into REP 103 by :func:`mm_pc.core.fixes.field_fixes.compass_to_rep103`. It has no
    stamp: it is applied when it arrives, to the newest estimate.
``sensor_msgs/Range`` (one topic per beacon)
    The slant range (m) from the robot's range antenna to that beacon. REP
    117: -inf (too close) and +inf (nothing) are readings without a range
    (unusable); NaN or a value outside [min_range, max_range] is invalid.
    ``radiation_type`` and ``field_of_view`` are not used.
``geometry_msgs/PointStamped`` (perimeter-wire contact)
    The wire sensor fired. There is no standard message for "one coordinate
    is known", so: ``point.x`` finite and ``point.y`` NaN = a wire on the line
    x = point.x (the x of the robot's centre is known); ``point.y`` finite and
    ``point.x`` NaN = a wire on y = point.y; both NaN = the sensor fired but
    which wire is not known: the nearest configured wire within a maximum
    distance of the estimate is taken (as seed 004's robot must). Both
    finite is invalid (a wire fixes one coordinate). ``point.z`` is ignored.
    Finite coordinates must be in the map frame. (A
    PoseWithCovarianceStamped with a huge variance on the unmeasured axis
    would say the same with a variance, but a reader that ignores the
    covariance would take the 0 placeholder as a coordinate; NaN cannot be
    mistaken.)

Every converter either returns an input record or raises
:class:`InputError` (``kind`` "invalid": the message is malformed;
:class:`UnusableInputError`, ``kind`` "unusable": well-formed but carries no usable
reading). Nothing else is changed.

:class:`FusionCore` then feeds the records to a :class:`mm_pc.core.fusion.ekf.PoseEKF`
in time-stamp order (see its docstring): odometry moves the estimate, the
other inputs correct it, wheel odometry stands in while the mouse odometry
is silent, and every input is counted per source.
"""

from __future__ import annotations

import heapq
import itertools
import math
import time
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from mm_pc.core.fixes.field_fixes import (
    LocalGrid,
    PerimeterSegment,
    compass_to_rep103,
    nearest_segment,
)
from mm_pc.core.fusion.ekf import GATE_1D, GATE_2D, PoseEKF, pose_increment
from mm_pc.core.odometry import Pose2D

__all__ = [
    "NAVSAT_STATUS_FIXES",
    "AxisInput",
    "FusionCore",
    "HeadingInput",
    "InputError",
    "MotionInput",
    "PositionInput",
    "RangeInput",
    "UnusableInputError",
    "WarnThrottle",
    "heading_input",
    "imu_input",
    "increment_noise",
    "navsat_input",
    "odometry_input",
    "perimeter_input",
    "planar_quaternion",
    "pose_covariance_6x6",
    "quaternion_yaw",
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

#: Variance (m^2, rad^2) put on z, roll and pitch, which a planar filter does not observe.
UNOBSERVED_VARIANCE = 1e6


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
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be a number, got {value!r}") from None
    if not math.isfinite(v):
        raise InputError(f"{name} must be finite, got {v}")
    return v


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


def quaternion_yaw(x: float, y: float, z: float, w: float) -> float:
    """Yaw (rad, (-pi, pi]) of a quaternion (x, y, z, w), any length > 0.

    The rotation's heading about +z (z-y-x Euler yaw), so a tilted compass or
    IMU still gives its heading.
    """
    q = [_finite(f"quaternion {n}", v) for n, v in zip("xyzw", (x, y, z, w), strict=True)]
    norm2 = sum(c * c for c in q)
    if not norm2 > 1e-12:
        raise InputError(f"quaternion {tuple(q)} has (near) zero length; it must be a rotation")
    qx, qy, qz, qw = q
    return math.atan2(2.0 * (qw * qz + qx * qy), norm2 - 2.0 * (qy * qy + qz * qz))


def planar_quaternion(yaw: float) -> tuple[float, float, float, float]:
    """(x, y, z, w) of a rotation by ``yaw`` (rad) about +z."""
    return 0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2)


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
    yaw = quaternion_yaw(o.x, o.y, o.z, o.w)
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
    yaw = quaternion_yaw(o.x, o.y, o.z, o.w) + offset
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


# --- outgoing ------------------------------------------------------------------------------------


def pose_covariance_6x6(p3) -> list[float]:
    """Row-major 6x6 (x, y, z, roll, pitch, yaw) from the 3x3 of (x, y, yaw)."""
    p = np.asarray(p3, dtype=float)
    c = np.zeros((6, 6))
    idx = [0, 1, 5]
    c[np.ix_(idx, idx)] = p
    c[2, 2] = c[3, 3] = c[4, 4] = UNOBSERVED_VARIANCE
    return c.reshape(-1).tolist()


def increment_noise(
    fwd: float, left: float, dtheta: float, q_pos: float, q_yaw_dist: float, q_yaw_turn: float
) -> np.ndarray:
    """3x3 covariance of an increment: the distance/turn random walk of the EKF (:mod:`.ekf`)."""
    d = math.hypot(fwd, left)
    return np.diag([q_pos * d, q_pos * d, q_yaw_dist * d + q_yaw_turn * abs(dtheta)])


class WarnThrottle:
    """Lets one message per key through every ``period_s`` seconds; counts the rest."""

    def __init__(self, period_s: float = 5.0, clock: Callable[[], float] = time.monotonic):
        self.period_s = period_s
        self._clock = clock
        self._last: dict[str, float] = {}
        self._held: dict[str, int] = {}

    def __call__(self, key: str) -> int | None:
        """None: stay quiet. Else the number of messages held back since the last one."""
        now = self._clock()
        last = self._last.get(key)
        if last is not None and now - last < self.period_s:
            self._held[key] = self._held.get(key, 0) + 1
            return None
        self._last[key] = now
        return self._held.pop(key, 0)


# --- the time-ordered front end -----------------------------------------------------------------

_COUNT_KINDS = ("accepted", "rejected", "invalid", "unusable", "stale", "reacquired")
_PRIORITY = {"mouse": 0, "wheel": 1}


@dataclass
class SourceCounts:
    """Per-source counts. ``rejected``: failed the filter's gate; ``reacquired``: applied
    ungated after too many rejections in a row (also counted in ``accepted``)."""

    accepted: int = 0
    rejected: int = 0
    invalid: int = 0
    unusable: int = 0
    stale: int = 0
    reacquired: int = 0
    last_reason: str = ""
    in_a_row: int = field(default=0, repr=False)

    def as_dict(self) -> dict[str, int]:
        return {k: getattr(self, k) for k in _COUNT_KINDS}


class FusionCore:
    """Feeds input records to a :class:`PoseEKF` in stamp order and counts what happened.

    Order. Records are queued and processed in stamp order, each once no
    periodic source (odometry, GPS, compass, beacons) can still deliver an
    older one: source s, last heard at stamp t_s with an average interval
    p_s, is not expected before t_s + p_s, so a record at stamp t goes in
    when t < t_s + 0.9 p_s for every such source (0.1 p_s for jitter; t <= t_s
    for a source heard only once, whose interval is not known yet). A
    measurement is thus applied after the prediction to its time and before
    the next, whichever topic's queue runs ahead (at a fast replay they drift
    apart by seconds of stamp time; on a robot a fix comes some 100 ms late).
    The output lags by the slowest source's latency plus a tenth of its
    interval. A source not heard for ``max_delay_s`` beyond its interval
    (behind the newest odometry stamp) is no longer waited for, and a record
    of it that still comes more than ``max_delay_s`` behind the processed
    odometry is *stale* and dropped. Wire contacts (events, no
    interval) and unstamped headings are never waited for; a late contact
    is applied on arrival. With no odometry at all, or after :meth:`flush`
    (the caller's "no odometry for a while"), records are processed on
    arrival. An odometry increment faster than ``max_speed`` (m/s) is
    *invalid* and starts a new baseline (a reset or corrupt odometry).

    Motion model. Mouse odometry is the motion model; wheel odometry is a
    stand-in used only when the mouse odometry has been silent for more than
    ``stale_s`` seconds of stamp time (a lifted sensor, a stopped mm-odometry):
    the wheels then cover from their pose at the mouse's last stamp, so no
    stretch is lost, with the noise ``wheel_noise`` (q_pos m^2/m,
    q_yaw_dist rad^2/m, q_yaw_turn rad^2/rad). When mouse odometry returns it
    starts from a new baseline (its increment over the silence is not
    trusted). A frame change or a stamp running backwards three times in a
    row also starts a new baseline.

    Corrections: GPS and trilateration-like positions (gate :data:`GATE_2D`),
    headings and single ranges (:data:`GATE_1D`), wire contacts (ungated, the
    wire found with :func:`mm_pc.core.fixes.field_fixes.nearest_segment` when the
    contact does not name it). After ``reacquire_after`` gate rejections in
    a row from one source, its next reading is applied ungated (the filter
    is taken to be lost, as in :func:`mm_pc.sim.field_run.run_fusion`; 0 = never).

    ``notices`` collects (key, text) lines worth logging (motion model
    switches, re-acquisitions, stale or backwards stamps); the caller drains it.
    """

    def __init__(
        self,
        ekf: PoseEKF,
        *,
        wheel_noise: Sequence[float] = (0.03**2, 0.03**2, 0.03**2),
        stale_s: float = 0.5,
        max_delay_s: float = 1.0,
        reacquire_after: int = 10,
        wires: Sequence[PerimeterSegment] = (),
        wire_var: float = 0.03**2,
        wire_max_distance: float = 2.0,
        max_speed: float = 5.0,
        max_queue: int = 10000,
    ) -> None:
        if len(wheel_noise) != 3 or not all(math.isfinite(q) and q >= 0 for q in wheel_noise):
            raise ValueError(f"wheel_noise must be three numbers >= 0, got {list(wheel_noise)}")
        for name, v in (("stale_s", stale_s), ("max_delay_s", max_delay_s)):
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be a finite number of seconds > 0, got {v}")
        if not (math.isfinite(max_speed) and max_speed > 0):
            raise ValueError(f"max_speed must be a finite number of m/s > 0, got {max_speed}")
        if reacquire_after < 0 or max_queue < 1:
            raise ValueError("reacquire_after must be >= 0 and max_queue >= 1")
        self.ekf = ekf
        self.wheel_noise = tuple(float(q) for q in wheel_noise)
        self.stale_s = float(stale_s)
        self.max_delay_s = float(max_delay_s)
        self.reacquire_after = int(reacquire_after)
        self.wires = tuple(wires)
        self.wire_var = float(wire_var)
        self.wire_max_distance = float(wire_max_distance)
        self.max_speed = float(max_speed)
        self.max_queue = int(max_queue)
        self.counts: dict[str, SourceCounts] = {}
        self.notices: list[tuple[str, str]] = []
        #: 'mouse', 'wheel' or None (no increment applied yet).
        self.motion_source: str | None = None
        #: stamp (s) of the newest processed record, None before any.
        self.stamp: float | None = None
        #: the last applied increment (fwd m, left m, dtheta rad, dt s), for the twist.
        self.last_increment: tuple[float, float, float, float] | None = None
        self._queue: list = []
        self._seq = itertools.count()
        self._pushed: dict[str, float] = {}  # newest stamp pushed per odometry source
        self._heard: dict[str, float] = {}  # newest stamp per periodic source
        self._period: dict[str, float] = {}  # average interval (s) per periodic source
        self._backwards: dict[str, int] = {}
        self._idle = False
        self._mouse_prev: MotionInput | None = None
        self._mouse_seen: float | None = None  # newest processed mouse stamp
        self._wheel_hist: deque[MotionInput] = deque()
        self._motion_stamp: float | None = None  # newest processed odometry stamp

    # -- bookkeeping ------------------------------------------------------------------------

    def count(self, source: str, kind: str, reason: str = "") -> None:
        """Count one input of ``source`` as ``kind`` (one of the SourceCounts fields)."""
        c = self.counts.setdefault(source, SourceCounts())
        setattr(c, kind, getattr(c, kind) + 1)
        if reason:
            c.last_reason = reason

    @property
    def idle(self) -> bool:
        """True after :meth:`flush` until the next odometry record (records go in on arrival)."""
        return self._idle

    @property
    def pending(self) -> int:
        """Records waiting for the odometry to reach their stamp."""
        return len(self._queue)

    # -- input ------------------------------------------------------------------------------

    def push(self, record) -> None:
        """Queue one record and process everything that can no longer be overtaken."""
        if isinstance(record, MotionInput):
            if not self._accept_motion_stamp(record):
                return
            self._idle = False
        elif record.stamp is None:
            self._measure(record)
            return
        elif (
            self._motion_stamp is not None and record.stamp < self._motion_stamp - self.max_delay_s
        ):
            reason = (
                f"stamp {self._motion_stamp - record.stamp:.2f} s older than the odometry "
                f"(> max_delay {self.max_delay_s:g} s)"
            )
            self.count(record.source, "stale", reason)
            self.notices.append((f"stale {record.source}", f"{record.source}: {reason}"))
            return
        if not isinstance(record, AxisInput):
            self.heard(record.source, record.stamp)
        prio = _PRIORITY.get(record.source, 2)
        # same stamp: odometry first, then the fixes by source name (not by arrival: the
        # result must not depend on which topic came first)
        key = (record.stamp, prio, record.source, next(self._seq))
        heapq.heappush(self._queue, (*key, record))
        self._drain()
        while len(self._queue) > self.max_queue:
            self._process(heapq.heappop(self._queue)[-1])

    def heard(self, source: str, stamp: float | None) -> None:
        """Periodic ``source`` delivered something stamped ``stamp`` s (used or not).

        Also for readings that were not usable (a GPS without fix still ticks),
        so that the source's next record is expected at the right time.
        """
        if stamp is None or not math.isfinite(stamp):
            return
        last = self._heard.get(source)
        if last is not None and stamp <= last:
            return
        if last is not None:
            gap = stamp - last
            p = self._period.get(source)
            self._period[source] = gap if p is None else 0.8 * p + 0.2 * gap
        self._heard[source] = stamp

    def interval(self, source: str) -> float | None:
        """Average interval (s) between ``source``'s messages, None before its second."""
        return self._period.get(source)

    def flush(self) -> None:
        """Process everything queued; until the next odometry record, process on arrival."""
        self._idle = True
        self._drain(everything=True)

    def _accept_motion_stamp(self, rec: MotionInput) -> bool:
        last = self._pushed.get(rec.source)
        if last is not None and rec.stamp < last:
            n = self._backwards.get(rec.source, 0) + 1
            self._backwards[rec.source] = n
            if n < 3:
                reason = f"stamp went backwards by {last - rec.stamp:.3f} s"
                self.count(rec.source, "invalid", reason)
                self.notices.append((f"backwards {rec.source}", f"{rec.source}: {reason}"))
                return False
            self.notices.append(
                (f"restart {rec.source}", f"{rec.source}: time jumped back; new baseline")
            )
            self._drain(everything=True)
            self._forget(rec.source)
        self._backwards[rec.source] = 0
        self._pushed[rec.source] = rec.stamp
        return True

    def _forget(self, source: str) -> None:
        if source == "mouse":
            self._mouse_prev, self._mouse_seen = None, None
        else:
            self._wheel_hist.clear()
        self._motion_stamp = None
        self._heard.clear()
        self._period.clear()

    def _horizon(self) -> tuple[float, float]:
        """(once, strict): a record at stamp t can no longer be overtaken if t <= once
        (sources heard only once: their last stamp) and t < strict (the others:
        t_s + 0.9 p_s)."""
        if self._idle or not self._pushed:
            return math.inf, math.inf
        newest = max(self._pushed.values())
        once = strict = math.inf
        for source, t in self._heard.items():
            p = self._period.get(source)
            if t + (p or 0.0) + self.max_delay_s < newest:
                continue  # gone quiet: not waited for
            if p is None:
                once = min(once, t)
            else:
                strict = min(strict, t + 0.9 * p)
        return once, strict

    def _drain(self, everything: bool = False) -> None:
        once, strict = (math.inf, math.inf) if everything else self._horizon()
        q = self._queue
        while q and q[0][0] <= once and (q[0][0] < strict or everything):
            self._process(heapq.heappop(q)[-1])

    def _process(self, rec) -> None:
        if isinstance(rec, MotionInput):
            if rec.source == "mouse":
                self._mouse(rec)
            else:
                self._wheel(rec)
            self._motion_stamp = max(self._motion_stamp or rec.stamp, rec.stamp)
        else:
            self._measure(rec)
        if rec.stamp is not None:
            self.stamp = rec.stamp if self.stamp is None else max(self.stamp, rec.stamp)

    # -- motion -----------------------------------------------------------------------------

    def _predict(self, rec: MotionInput, before: MotionInput, q=None) -> None:
        try:
            inc = pose_increment(before.pose, rec.pose)
            dt = rec.stamp - before.stamp
            moved = math.hypot(inc[0], inc[1])
            if moved > self.max_speed * dt + 0.05:
                raise ValueError(
                    f"odometry jumped {moved:.2f} m in {dt:.3f} s (> max_speed "
                    f"{self.max_speed:g} m/s); new baseline"
                )
            self.ekf.predict(*inc, q=q(inc) if q else None)
        except ValueError as exc:
            self.count(rec.source, "invalid", str(exc))
            self.notices.append((f"jump {rec.source}", f"{rec.source}: {exc}"))
            return
        self.last_increment = (*inc, dt)
        self.count(rec.source, "accepted")

    def _mouse(self, rec: MotionInput) -> None:
        prev = self._mouse_prev
        self._mouse_prev = rec
        self._mouse_seen = rec.stamp
        if prev is None or prev.frame_id != rec.frame_id or self.motion_source == "wheel":
            if self.motion_source == "wheel":
                self.notices.append(("motion", "mouse odometry is back: it is the motion model"))
            self.motion_source = "mouse"
            self.count(rec.source, "accepted")
            return
        self._predict(rec, prev)

    def _wheel(self, rec: MotionInput) -> None:
        hist = self._wheel_hist
        if hist and hist[-1].frame_id != rec.frame_id:
            hist.clear()
        seen = self._mouse_seen
        mouse_alive = seen is not None and rec.stamp - seen <= self.stale_s
        if mouse_alive or not hist:
            self.count(rec.source, "accepted")
        else:
            if self.motion_source == "wheel":
                anchor = hist[-1]
            else:
                before = [h for h in hist if seen is not None and h.stamp <= seen]
                anchor = before[-1] if before else (hist[0] if seen is not None else hist[-1])
                self.motion_source = "wheel"
                silent = "never heard" if seen is None else f"silent {rec.stamp - seen:.2f} s"
                self.notices.append(
                    ("motion", f"mouse odometry {silent}: wheel odometry is the motion model")
                )
            self._predict(rec, anchor, q=lambda inc: increment_noise(*inc, *self.wheel_noise))
        hist.append(rec)
        keep_from = rec.stamp - self.stale_s - 1.0
        while hist and hist[0].stamp < keep_from:
            hist.popleft()

    # -- corrections ------------------------------------------------------------------------

    def _measure(self, rec) -> None:
        c = self.counts.setdefault(rec.source, SourceCounts())
        ungated = self.reacquire_after > 0 and c.in_a_row >= self.reacquire_after
        try:
            outcome = self._apply(rec, ungated)
        except ValueError as exc:
            self.count(rec.source, "invalid", str(exc))
            return
        if outcome == "unusable":
            self.count(rec.source, "unusable", "no perimeter wire near the estimate")
            return
        if outcome:
            c.accepted += 1
            c.in_a_row = 0
            if ungated:
                c.reacquired += 1
                self.notices.append(
                    (f"reacquire {rec.source}", f"{rec.source}: applied ungated to re-acquire")
                )
        else:
            c.rejected += 1
            c.in_a_row += 1
            d2 = self.ekf.last_distance2
            c.last_reason = f"failed the gate (Mahalanobis^2 {d2:.3g})" if d2 is not None else ""

    def _apply(self, rec, ungated: bool):
        ekf = self.ekf
        if isinstance(rec, PositionInput):
            return ekf.update_position(
                rec.xy, rec.cov, gate=None if ungated else GATE_2D, gate_cov=rec.gate_cov
            )
        if isinstance(rec, HeadingInput):
            return ekf.update_heading(rec.yaw, rec.var, gate=None if ungated else GATE_1D)
        if isinstance(rec, RangeInput):
            return ekf.update_ranges(
                [rec.beacon], [rec.range], rec.sigma, gate=None if ungated else GATE_1D
            )
        if isinstance(rec, AxisInput):
            axis, value = rec.axis, rec.value
            if axis is None:
                s = ekf.state
                if not self.wires:
                    return "unusable"
                wire = nearest_segment((s[0], s[1]), self.wires, self.wire_max_distance)
                if wire is None:
                    return "unusable"
                axis, value = wire.axis, wire.value
            return ekf.update_axis(axis, value, self.wire_var)
        raise ValueError(f"unknown input record {rec!r}")
