"""Wheel odometry and absolute fixes for a lawn-mower robot (seed 004).

Seed 004 (W. Stocker, "Positionserkennung mittels Odometrie und GPS") builds
the position on wheel odometry, because it is always available, and corrects
it where it can: heading from a compass, position from GPS, and single
coordinates from the perimeter wire. This module is that, as pure math (no ROS,
no Qt), in SI units and REP 103 frames.

Frames and the one place where the seed's angles are converted
---------------------------------------------------------------
The seed puts the origin at the plot's south-west corner, x west -> east,
y south -> north. That is already an ENU plane, the REP 103 world frame, so
positions need no conversion. Only the angles differ: the seed counts
compass-style, 0 = north = +y, clockwise positive (north 0, east pi/2,
south pi, west 3*pi/2; the seed's "west = 3*pi/4 (270 deg)" is a typo, 270 deg
is 3*pi/2). REP 103 yaw is 0 = east = +x, counter-clockwise positive. So

    yaw = pi/2 - heading        heading = pi/2 - yaw

(an involution), wrapped to (-pi, pi] for yaw and [0, 2*pi) for a heading.
:func:`mm_pc.core.angles.compass_to_rep103` and ``rep103_to_compass`` are the only
places that apply it; everything else in this module is REP 103. The seed's turn
angle "Drehwinkel" = (left - right) / track is clockwise positive; ours is
(right - left) / track, CCW positive: the same turn.

Wheel odometry: where the seed approximates
-------------------------------------------
For a differential drive, wheel travels d_l, d_r (m) and track width b give
the body increment forward a = (d_l + d_r)/2, lateral 0, turn
c = (d_r - d_l)/b (:func:`body_increment`). If the two wheel speeds keep their
ratio over the step, the axle centre moves on a circular arc, and the exact
displacement is the chord a*sinc(c/2) along the mid-step heading yaw + c/2
(:func:`mm_pc.core.odometry.arc_poses`, reused here). That one formula is exact for
straight lines, gentle curves, spins on the spot, and the seed's pivot about a
standing wheel (d_l = 0: the centre moves on a circle of radius b/2 about the
left wheel, chord b*sin(c/2) = a*sinc(c/2)).

The seed's "straight and gentle curves" step (:func:`seed_gentle_step`) moves
the full arc length ``weg`` along one heading: no chord shortening and the
heading off by c/2, an O(a*c/2) sideways error per step; its text writes
sin/cos of the *turn increment*, which is only the heading for a robot
pointing north (we read it as the heading after the turn). The seed knows this
is unfit for turns and adds a two-step pivot (:func:`seed_pivot_step`): find
the standing wheel (Radstand/2 to the side, correct), then rotate the position
about it. Its rotation matrix is the CCW one, but it feeds it the clockwise
compass "Drehwinkel" and also adds that to the compass heading; both cannot be
right at once. Taken literally a left pivot swings the centre backwards
(tests show it). :meth:`WheelOdometry.pivot` rotates about the standing wheel
in one consistent sense and agrees with :meth:`WheelOdometry.update` to
rounding. The seed's tick size (180 mm wheel, 12 ticks per turn -> 47 mm) is
:func:`tick_length`.

Compass
-------
:func:`blend_heading` is a complementary blend on the circle:
yaw + w * wrap(compass - yaw). It steps the short way round (correct across
the +-pi seam) and keeps the odometry yaw's branch, so a continuous yaw
(:class:`~mm_pc.core.odometry.Pose2D` counts turns) stays continuous.

GPS
---
:class:`LocalGrid` maps latitude/longitude to plot metres by a local
equirectangular (tangent-plane) projection about the south-west corner:
x = dlon * k_lon, y = dlat * k_lat. The scales are either WGS84's local radii
of curvature at the origin (meridional M and prime-vertical N*cos(lat)) or,
as the seed does, measured: :meth:`LocalGrid.from_plot` divides the known plot
width/height by the corners' longitude/latitude differences. Over a garden
(< 1 km) the projection error is millimetres, far under GPS noise. Full
degrees in float64 carry ~1e-9 m resolution, so the seed's trick of keeping
only the decimals of the minutes is not needed.

The seed's correction rule (:func:`gps_correction`): the GPS accuracy is about
HDOP * UERE (UERE 2.5 m: the seed's "+-2.5 m in good conditions"); correct the
odometry only if the fix is trustworthy (fix type, HDOP, number of satellites:
:func:`gps_fix_usable`) *and* the estimate is further from it than that
accuracy; a closer estimate is as good as the fix and stays. NMEA GGA and GLL
(the sentences the seed uses) are parsed with checksum verification
(:func:`parse_gga`, :func:`parse_gll`).

Perimeter wire
--------------
A wire segment running along a line x = const (or y = const) fixes that one
coordinate when the wire sensor fires: heading west onto the west wire means
x = 0, nothing is learnt about y. :func:`perimeter_correction` sets it,
allowing for a sensor mounted off the robot's centre (the seed's extension
with left-front and right-front sensors); :func:`nearest_segment` picks which
wire was hit from the sensor's estimated position.

Bad input (NaN, infinities, negative widths, HDOP < 0, latitudes beyond +-90,
malformed NMEA, ...) raises ValueError with a message saying what was wrong,
and changes no state.
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from mm_pc.core.angles import compass_to_rep103, wrap_pi
from mm_pc.core.checks import finite as _finite
from mm_pc.core.checks import finite_array as _finite_array
from mm_pc.core.odometry import Pose2D, arc_poses

__all__ = [
    "USABLE_FIX_TYPES",
    "GgaFix",
    "GllFix",
    "GpsQuality",
    "LocalGrid",
    "PerimeterSegment",
    "WheelOdometry",
    "blend_heading",
    "body_increment",
    "correct_at_wire",
    "gps_accuracy_m",
    "gps_correction",
    "gps_fix_usable",
    "nearest_segment",
    "nmea_checksum",
    "parse_gga",
    "parse_gll",
    "perimeter_correction",
    "rectangle_perimeter",
    "seed_gentle_step",
    "seed_pivot_step",
    "sensor_position",
    "tick_length",
    "wgs84_m_per_deg",
]

_TWO_PI = 2.0 * math.pi

# --- input checks ------------------------------------------------------------------------


def _positive(name: str, value) -> float:
    v = _finite(name, value)
    if v <= 0:
        raise ValueError(f"{name} must be > 0, got {value!r}")
    return v


def _xy(name: str, value) -> tuple[float, float]:
    """A finite (x, y) pair in metres."""
    try:
        x, y = value
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be an (x, y) pair in metres, got {value!r}") from None
    return _finite(f"{name} x", x), _finite(f"{name} y", y)


def _pair(a: np.ndarray, b: np.ndarray):
    """Two results as floats if both are scalars, else as broadcast arrays."""
    if np.ndim(a) == 0 and np.ndim(b) == 0:
        return float(a), float(b)
    a2, b2 = np.broadcast_arrays(a, b)
    return a2.copy(), b2.copy()


def _like_input(value, result: np.ndarray):
    """A Python float for scalar input, the array otherwise."""
    return float(result) if np.ndim(value) == 0 else result


# --- angles ------------------------------------------------------------------------------


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


# --- wheel odometry ----------------------------------------------------------------------


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


def seed_gentle_step(
    x: float, y: float, heading: float, d_left: float, d_right: float, track_width: float
) -> tuple[float, float, float]:
    """The seed's step "for straight lines and gentle curves", in the seed's frame.

    x east, y north (m), ``heading`` compass (0 = north, clockwise+, rad).
    weg = (l + r)/2, Drehwinkel = (l - r)/Radstand; the position moves the
    full ``weg`` along heading + Drehwinkel (the text writes sin/cos of the
    turn alone, which equals that only for a start heading of north). Kept to
    compare with :meth:`WheelOdometry.update`; returns (x, y, heading).
    """
    b = _positive("track width (m)", track_width)
    dl, dr = _finite("left wheel travel (m)", d_left), _finite("right wheel travel (m)", d_right)
    h = _finite("heading", heading)
    weg, turn = 0.5 * (dl + dr), (dl - dr) / b
    h_new = h + turn
    return _finite("x", x) + weg * math.sin(h_new), _finite("y", y) + weg * math.cos(h_new), h_new


def seed_pivot_step(
    x: float, y: float, heading: float, d_left: float, d_right: float, track_width: float
) -> tuple[float, float, float]:
    """The seed's pivot about a standing wheel, literally, in the seed's frame.

    x east, y north (m), ``heading`` compass (rad). A left curve (left wheel
    stands, ``d_left`` = 0) pivots about (x - b/2*cos h, y + b/2*sin h), a
    right curve about the mirror point; then the seed's CCW rotation matrix is
    applied with the clockwise Drehwinkel = (l - r)/b, and Richtung +=
    Drehwinkel. Kept only to show the inconsistency (the centre swings the
    wrong way); returns (x, y, heading).
    """
    b = _positive("track width (m)", track_width)
    dl, dr = _finite("left wheel travel (m)", d_left), _finite("right wheel travel (m)", d_right)
    px, py, h = _finite("x", x), _finite("y", y), _finite("heading", heading)
    if dl != 0.0 and dr != 0.0:
        raise ValueError("the seed's pivot needs one standing wheel (d_left or d_right = 0)")
    turn = (dl - dr) / b
    side = 1.0 if dl == 0.0 else -1.0  # left curve: pivot on the left wheel
    tx = px - side * (b / 2) * math.cos(h)
    ty = py + side * (b / 2) * math.sin(h)
    ct, st = math.cos(turn), math.sin(turn)
    nx = tx + (px - tx) * ct - (py - ty) * st
    ny = ty + (py - ty) * ct + (px - tx) * st
    return nx, ny, h + turn


# --- GPS: local metric grid ---------------------------------------------------------------

_WGS84_A = 6378137.0
_WGS84_F = 1 / 298.257223563
_WGS84_E2 = _WGS84_F * (2 - _WGS84_F)
_DEG = math.pi / 180


def _wrap_lon(dlon):
    """Longitude difference(s) wrapped to [-180, 180) deg."""
    return np.mod(np.asarray(dlon, dtype=float) + 180.0, 360.0) - 180.0


def _check_lat(name: str, lat) -> np.ndarray:
    arr = _finite_array(name, lat)
    if np.any(np.abs(arr) > 90.0):
        raise ValueError(f"{name} must be within [-90, 90] deg, got {lat!r}")
    return arr


def _check_lon(name: str, lon) -> np.ndarray:
    arr = _finite_array(name, lon)
    if np.any(np.abs(arr) > 180.0):
        raise ValueError(f"{name} must be within [-180, 180] deg, got {lon!r}")
    return arr


def wgs84_m_per_deg(lat_deg: float) -> tuple[float, float]:
    """(metres per degree of latitude, of longitude) at ``lat_deg`` on the WGS84 ellipsoid."""
    lat = float(_check_lat("latitude (deg)", lat_deg)) * _DEG
    s2 = math.sin(lat) ** 2
    m = _WGS84_A * (1 - _WGS84_E2) / (1 - _WGS84_E2 * s2) ** 1.5
    n = _WGS84_A / math.sqrt(1 - _WGS84_E2 * s2)
    return m * _DEG, n * math.cos(lat) * _DEG


@dataclass(frozen=True)
class LocalGrid:
    """Plot metres from GPS degrees: x east, y north, origin at the plot's SW corner.

    ``origin_lat``/``origin_lon``: the corner (deg). ``m_per_deg_lat`` /
    ``m_per_deg_lon``: the scales (m per deg); None means WGS84's local values
    at the origin. Local equirectangular projection, for areas up to ~1 km.
    """

    origin_lat: float
    origin_lon: float
    m_per_deg_lat: float | None = None
    m_per_deg_lon: float | None = None

    def __post_init__(self) -> None:
        lat = float(_check_lat("origin latitude (deg)", self.origin_lat))
        if abs(lat) >= 89.0:
            raise ValueError(f"origin latitude must be within (-89, 89) deg, got {lat}")
        lon = float(_check_lon("origin longitude (deg)", self.origin_lon))
        k_lat, k_lon = wgs84_m_per_deg(lat)
        if self.m_per_deg_lat is not None:
            k_lat = _positive("metres per degree of latitude", self.m_per_deg_lat)
        if self.m_per_deg_lon is not None:
            k_lon = _positive("metres per degree of longitude", self.m_per_deg_lon)
        object.__setattr__(self, "origin_lat", lat)
        object.__setattr__(self, "origin_lon", lon)
        object.__setattr__(self, "m_per_deg_lat", k_lat)
        object.__setattr__(self, "m_per_deg_lon", k_lon)

    @classmethod
    def from_plot(
        cls,
        sw_lat: float,
        sw_lon: float,
        ne_lat: float,
        ne_lon: float,
        width_m: float,
        height_m: float,
    ) -> LocalGrid:
        """Grid whose scales come from the plot's known size (the seed's method).

        ``width_m``: west-east extent, ``height_m``: south-north extent of a
        north-aligned rectangular plot whose SW and NE corners were surveyed
        (deg). Scale = size / degree difference.
        """
        dlat = float(_check_lat("NE latitude (deg)", ne_lat)) - float(
            _check_lat("SW latitude (deg)", sw_lat)
        )
        dlon = float(
            _wrap_lon(
                float(_check_lon("NE longitude (deg)", ne_lon))
                - float(_check_lon("SW longitude (deg)", sw_lon))
            )
        )
        if dlat <= 0:
            raise ValueError(f"NE corner must be north of the SW corner, got dlat = {dlat} deg")
        if dlon <= 0:
            raise ValueError(f"NE corner must be east of the SW corner, got dlon = {dlon} deg")
        w = _positive("plot width (m)", width_m)
        h = _positive("plot height (m)", height_m)
        return cls(sw_lat, sw_lon, h / dlat, w / dlon)

    def to_local(self, lat, lon):
        """(x east, y north) in m for latitude/longitude in deg; scalars or arrays."""
        la = _check_lat("latitude (deg)", lat)
        lo = _check_lon("longitude (deg)", lon)
        x = _wrap_lon(lo - self.origin_lon) * self.m_per_deg_lon
        y = (la - self.origin_lat) * self.m_per_deg_lat
        return _pair(x, y)

    def to_geodetic(self, x, y):
        """(latitude, longitude) in deg for plot metres (x east, y north); scalars or arrays."""
        xa = _finite_array("x (m)", x)
        ya = _finite_array("y (m)", y)
        lat = self.origin_lat + ya / self.m_per_deg_lat
        if np.any(np.abs(lat) > 90.0):
            raise ValueError(f"y = {y!r} m lies beyond a pole from this origin")
        lon = _wrap_lon(self.origin_lon + xa / self.m_per_deg_lon)
        return _pair(lat, lon)


# --- GPS: quality and the correction rule --------------------------------------------------

#: GGA fix types that are a real position: 1 GPS, 2 DGPS, 3 PPS, 4 RTK fixed,
#: 5 RTK float. 0 invalid, 6 dead reckoning, 7 manual, 8 simulation are not.
USABLE_FIX_TYPES = frozenset({1, 2, 3, 4, 5})


def _int_in(name: str, value, lo: int, hi: int | None = None) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer):
        raise ValueError(f"{name} must be an integer, got {value!r}")
    if value < lo or (hi is not None and value > hi):
        allowed = f">= {lo}" if hi is None else f"in {lo}..{hi}"
        raise ValueError(f"{name} must be {allowed}, got {value!r}")
    return int(value)


@dataclass(frozen=True)
class GpsQuality:
    """What a fix says about itself: HDOP (>= 0), satellites used, GGA fix type (0..8)."""

    hdop: float
    satellites: int
    fix_type: int

    def __post_init__(self) -> None:
        h = _finite("HDOP", self.hdop)
        if h < 0:
            raise ValueError(f"HDOP must be >= 0, got {self.hdop!r}")
        object.__setattr__(self, "hdop", h)
        _int_in("satellites", self.satellites, 0)
        _int_in("fix type", self.fix_type, 0, 8)


def gps_fix_usable(q: GpsQuality, max_hdop: float = 2.0, min_satellites: int = 5) -> bool:
    """True if the fix is a real position, HDOP in (0, max_hdop], satellites >= min_satellites.

    HDOP 0 is impossible geometry (some receivers send it for "unknown"), so it
    does not count as good.
    """
    mh = _positive("max HDOP", max_hdop)
    ms = _int_in("min satellites", min_satellites, 0)
    return q.fix_type in USABLE_FIX_TYPES and 0.0 < q.hdop <= mh and q.satellites >= ms


def gps_accuracy_m(q: GpsQuality, uere_m: float = 2.5) -> float:
    """Horizontal accuracy estimate (m): HDOP * UERE (range error; seed: 2.5 m)."""
    return q.hdop * _positive("UERE (m)", uere_m)


def gps_correction(
    estimate_xy: Sequence[float],
    gps_xy: Sequence[float],
    quality: GpsQuality,
    *,
    max_hdop: float = 2.0,
    min_satellites: int = 5,
    uere_m: float = 2.5,
    mode: str = "gps",
) -> tuple[float, float] | None:
    """The seed's rule: the corrected (x, y) in m, or None to keep the estimate.

    Correct only if :func:`gps_fix_usable` and the estimate lies further than
    :func:`gps_accuracy_m` from the GPS position. ``mode="gps"`` (the seed)
    jumps to the GPS position; ``mode="boundary"`` moves the estimate just
    inside the accuracy circle (the smallest change the fix demands).
    """
    ex, ey = _xy("estimate", estimate_xy)
    gx, gy = _xy("GPS position", gps_xy)
    if mode not in ("gps", "boundary"):
        raise ValueError(f"mode must be 'gps' or 'boundary', got {mode!r}")
    if not isinstance(quality, GpsQuality):
        raise ValueError(f"quality must be a GpsQuality, got {type(quality).__name__}")
    accuracy = gps_accuracy_m(quality, uere_m)
    usable = gps_fix_usable(quality, max_hdop, min_satellites)
    deviation = math.hypot(ex - gx, ey - gy)
    if not usable or deviation <= accuracy:
        return None
    if mode == "gps":
        return gx, gy
    k = accuracy / deviation
    return gx + k * (ex - gx), gy + k * (ey - gy)


# --- NMEA GGA / GLL --------------------------------------------------------------------------


@dataclass(frozen=True)
class GgaFix:
    """A parsed GGA sentence: UTC seconds of day, position (deg, north/east +), quality."""

    time_s: float
    lat: float
    lon: float
    fix_type: int
    satellites: int
    hdop: float
    altitude_m: float | None = None
    talker: str = "GP"

    @property
    def quality(self) -> GpsQuality:
        """The fix's :class:`GpsQuality`."""
        return GpsQuality(self.hdop, self.satellites, self.fix_type)


@dataclass(frozen=True)
class GllFix:
    """A parsed GLL sentence: position (deg), UTC seconds of day, validity, mode letter."""

    lat: float
    lon: float
    time_s: float
    valid: bool
    mode: str | None = None
    talker: str = "GP"


def nmea_checksum(body: str) -> int:
    """XOR of the characters between '$' and '*' (an int 0..255)."""
    cs = 0
    for ch in body:
        cs ^= ord(ch)
    return cs


_TIME_RE = re.compile(r"^(\d{2})(\d{2})(\d{2}(?:\.\d+)?)$")
_LAT_RE = re.compile(r"^(\d{2})(\d{2}(?:\.\d+)?)$")
_LON_RE = re.compile(r"^(\d{3})(\d{2}(?:\.\d+)?)$")


def _nmea_fields(sentence: str, kind: str) -> tuple[str, list[str]]:
    """Check framing and checksum; return (talker, fields after the address)."""
    if not isinstance(sentence, str):
        raise ValueError(f"NMEA sentence must be a str, got {type(sentence).__name__}")
    s = sentence.strip()
    if not s.isascii():
        raise ValueError(f"NMEA sentence must be ASCII: {s!r}")
    if not s.startswith("$"):
        raise ValueError(f"NMEA sentence must start with '$': {s!r}")
    body, star, given = s[1:].rpartition("*")
    if not star:
        raise ValueError(f"NMEA sentence has no '*hh' checksum: {s!r}")
    if not re.fullmatch(r"[0-9A-Fa-f]{2}", given):
        raise ValueError(f"NMEA checksum must be two hex digits, got {given!r}")
    computed = nmea_checksum(body)
    if int(given, 16) != computed:
        raise ValueError(
            f"NMEA checksum mismatch: sentence says {given.upper()}, computed {computed:02X}"
        )
    fields = body.split(",")
    address = fields[0]
    if not re.fullmatch(r"[A-Z]{2}" + kind, address):
        raise ValueError(f"expected a {kind} sentence (e.g. GP{kind}), got {address!r}")
    return address[:2], fields[1:]


def _required(fields: list[str], i: int, name: str) -> str:
    if i >= len(fields) or fields[i] == "":
        raise ValueError(f"NMEA field '{name}' is empty")
    return fields[i]


def _parse_time(text: str) -> float:
    m = _TIME_RE.match(text)
    if not m:
        raise ValueError(f"NMEA time must be hhmmss[.ss], got {text!r}")
    h, mi, s = int(m[1]), int(m[2]), float(m[3])
    if h > 23 or mi > 59 or s >= 61:
        raise ValueError(f"NMEA time out of range: {text!r}")
    return h * 3600 + mi * 60 + s


def _parse_angle(text: str, hemi: str, kind: str) -> float:
    """ddmm.mmmm (lat) or dddmm.mmmm (lon) plus N/S or E/W -> signed degrees."""
    rx, signs, limit = (_LAT_RE, "NS", 90.0) if kind == "latitude" else (_LON_RE, "EW", 180.0)
    m = rx.match(text)
    if not m:
        width = 2 if kind == "latitude" else 3
        raise ValueError(f"NMEA {kind} must be {'d' * width}mm.mmmm, got {text!r}")
    deg, minutes = int(m[1]), float(m[2])
    if minutes >= 60:
        raise ValueError(f"NMEA {kind} minutes must be < 60, got {text!r}")
    value = deg + minutes / 60
    if value > limit:
        raise ValueError(f"NMEA {kind} must be <= {limit:g} deg, got {text!r}")
    if hemi not in signs:
        raise ValueError(f"NMEA {kind} hemisphere must be {signs[0]} or {signs[1]}, got {hemi!r}")
    return value if hemi == signs[0] else -value


def _parse_number(text: str, name: str, cast=float):
    try:
        v = cast(text)
    except ValueError:
        raise ValueError(f"NMEA field '{name}' is not a number: {text!r}") from None
    if cast is float and not math.isfinite(v):
        raise ValueError(f"NMEA field '{name}' is not finite: {text!r}")
    return v


def parse_gga(sentence: str) -> GgaFix:
    """Parse ``$--GGA,hhmmss.ss,ddmm.mm,N,dddmm.mm,E,q,nn,hdop,alt,M,...*hh``.

    Checks the checksum (required). Time, position, fix type, satellites and
    HDOP must be present; altitude may be empty. Raises ValueError on any
    defect (a receiver without a fix sends empty positions: no fix here).
    """
    talker, f = _nmea_fields(sentence, "GGA")
    if len(f) < 9:
        raise ValueError(f"GGA needs at least 9 fields after the address, got {len(f)}")
    time_s = _parse_time(_required(f, 0, "time"))
    lat = _parse_angle(_required(f, 1, "latitude"), _required(f, 2, "N/S"), "latitude")
    lon = _parse_angle(_required(f, 3, "longitude"), _required(f, 4, "E/W"), "longitude")
    fix_type = _parse_number(_required(f, 5, "fix quality"), "fix quality", int)
    sats = _parse_number(_required(f, 6, "satellites"), "satellites", int)
    hdop = _parse_number(_required(f, 7, "HDOP"), "HDOP", float)
    alt = _parse_number(f[8], "altitude", float) if f[8] else None
    quality = GpsQuality(hdop, sats, fix_type)  # range checks with messages
    return GgaFix(time_s, lat, lon, quality.fix_type, quality.satellites, quality.hdop, alt, talker)


def parse_gll(sentence: str) -> GllFix:
    """Parse ``$--GLL,ddmm.mm,N,dddmm.mm,E,hhmmss.ss,A[,mode]*hh``.

    ``valid``: status A (the seed's "data valid") and, if the NMEA 2.3 mode
    letter is there, not N (no fix), E (estimated), M (manual) or S (simulator).
    Checksum required; empty position/time/status raise ValueError.
    """
    talker, f = _nmea_fields(sentence, "GLL")
    if len(f) < 6:
        raise ValueError(f"GLL needs at least 6 fields after the address, got {len(f)}")
    lat = _parse_angle(_required(f, 0, "latitude"), _required(f, 1, "N/S"), "latitude")
    lon = _parse_angle(_required(f, 2, "longitude"), _required(f, 3, "E/W"), "longitude")
    time_s = _parse_time(_required(f, 4, "time"))
    status = _required(f, 5, "status")
    if status not in ("A", "V"):
        raise ValueError(f"GLL status must be A (valid) or V (invalid), got {status!r}")
    mode = f[6] if len(f) > 6 and f[6] else None
    valid = status == "A" and mode not in ("N", "E", "M", "S")
    return GllFix(lat, lon, time_s, valid, mode, talker)


# --- perimeter wire -----------------------------------------------------------------------------


@dataclass(frozen=True)
class PerimeterSegment:
    """An axis-aligned stretch of perimeter wire in plot metres.

    ``axis="x"``: the wire lies on the line x = ``value`` (runs south-north)
    and fixes x; it spans y in [``start``, ``end``]. ``axis="y"``: on y =
    ``value``, fixes y, spans x in [start, end]. Default extent: the whole line.
    """

    axis: str
    value: float
    start: float = -math.inf
    end: float = math.inf

    def __post_init__(self) -> None:
        if self.axis not in ("x", "y"):
            raise ValueError(f"perimeter axis must be 'x' or 'y', got {self.axis!r}")
        object.__setattr__(self, "value", _finite("wire coordinate (m)", self.value))
        lo, hi = float(self.start), float(self.end)
        if math.isnan(lo) or math.isnan(hi) or lo > hi:
            raise ValueError(f"segment extent must satisfy start <= end, got [{lo}, {hi}]")
        object.__setattr__(self, "start", lo)
        object.__setattr__(self, "end", hi)

    def distance(self, point_xy: Sequence[float]) -> float:
        """Distance (m) from a point to this segment."""
        px, py = _xy("point", point_xy)
        across, along = (px, py) if self.axis == "x" else (py, px)
        nearest = min(max(along, self.start), self.end)
        return math.hypot(across - self.value, along - nearest)


def rectangle_perimeter(width_m: float, height_m: float) -> tuple[PerimeterSegment, ...]:
    """A rectangular plot's wire from the SW origin: west, east, south, north segments."""
    w = _positive("plot width (m)", width_m)
    h = _positive("plot height (m)", height_m)
    return (
        PerimeterSegment("x", 0.0, 0.0, h),
        PerimeterSegment("x", w, 0.0, h),
        PerimeterSegment("y", 0.0, 0.0, w),
        PerimeterSegment("y", h, 0.0, w),
    )


def sensor_position(
    estimate_xy: Sequence[float], yaw: float = 0.0, sensor_xy: Sequence[float] = (0.0, 0.0)
) -> tuple[float, float]:
    """Plot position (m) of a sensor at base_link ``sensor_xy`` (x forward, y left, m).

    ``estimate_xy``: the robot centre; ``yaw``: REP 103 (rad).
    """
    ex, ey = _xy("estimate", estimate_xy)
    sx, sy = _xy("sensor offset", sensor_xy)
    t = _finite("yaw", yaw)
    c, s = math.cos(t), math.sin(t)
    return ex + c * sx - s * sy, ey + s * sx + c * sy


def perimeter_correction(
    estimate_xy: Sequence[float],
    contact: PerimeterSegment | tuple[str, float],
    yaw: float = 0.0,
    sensor_xy: Sequence[float] = (0.0, 0.0),
) -> tuple[float, float]:
    """Robot centre (x, y) in m after the wire sensor fired on ``contact``.

    Only the coordinate the wire fixes changes: the sensor (at base_link
    ``sensor_xy``; default the centre, as in the seed's examples) is on the
    wire, so centre = wire coordinate - the sensor's offset along that axis.
    ``contact``: a segment or an (axis, value) pair, e.g. ("x", 0.0).
    """
    seg = contact
    if not isinstance(seg, PerimeterSegment):
        try:
            axis, value = contact
        except (TypeError, ValueError):
            raise ValueError(
                f"contact must be a PerimeterSegment or an (axis, value) pair, got {contact!r}"
            ) from None
        seg = PerimeterSegment(axis, value)
    ex, ey = _xy("estimate", estimate_xy)
    sx, sy = sensor_position((0.0, 0.0), yaw, sensor_xy)
    if seg.axis == "x":
        return seg.value - sx, ey
    return ex, seg.value - sy


def nearest_segment(
    point_xy: Sequence[float],
    segments: Sequence[PerimeterSegment],
    max_distance: float = math.inf,
) -> PerimeterSegment | None:
    """The segment nearest ``point_xy`` (m; the first one on a tie).

    None if even that one is further than ``max_distance`` (m): the estimate
    is too far off to tell which wire was hit.
    """
    if not segments:
        raise ValueError("need at least one perimeter segment")
    md = float(max_distance)
    if math.isnan(md) or md < 0:
        raise ValueError(f"max distance must be >= 0 m, got {max_distance!r}")
    p = _xy("point", point_xy)
    dist = [s.distance(p) for s in segments]
    best = int(np.argmin(dist))
    return segments[best] if dist[best] <= md else None


def correct_at_wire(
    estimate_xy: Sequence[float],
    segments: Sequence[PerimeterSegment],
    yaw: float = 0.0,
    sensor_xy: Sequence[float] = (0.0, 0.0),
    max_distance: float = math.inf,
) -> tuple[float, float] | None:
    """The sensor fired: correct against the wire nearest the sensor, or None if none is near."""
    seg = nearest_segment(sensor_position(estimate_xy, yaw, sensor_xy), segments, max_distance)
    return None if seg is None else perimeter_correction(estimate_xy, seg, yaw, sensor_xy)
