"""GPS in plot metres: the local grid (latitude/longitude <-> x east, y north) and fix quality.

:class:`LocalGrid` is a local equirectangular projection about the plot's south-west
corner, scaled by WGS84 or, as the seed does, by the surveyed corners; millimetres of
projection error over a garden. :func:`gps_fix_usable` and :func:`gps_accuracy_m` are the
seed's quality limits (HDOP, satellites, HDOP * UERE).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from mm_pc.core.checks import finite as _finite
from mm_pc.core.checks import finite_array as _finite_array
from mm_pc.core.checks import positive as _positive

__all__ = [
    "USABLE_FIX_TYPES",
    "GpsQuality",
    "LocalGrid",
    "gps_accuracy_m",
    "gps_fix_usable",
    "wgs84_m_per_deg",
]


def _pair(a: np.ndarray, b: np.ndarray):
    """Two results as floats if both are scalars, else as broadcast arrays."""
    if np.ndim(a) == 0 and np.ndim(b) == 0:
        return float(a), float(b)
    a2, b2 = np.broadcast_arrays(a, b)
    return a2.copy(), b2.copy()


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
