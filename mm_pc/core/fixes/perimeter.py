"""The perimeter wire: segments along x = const or y = const, and what a contact fixes.

A contact fixes one coordinate (the robot's, allowing for a sensor off its centre);
which wire was hit is taken from the estimate (:func:`nearest_segment`), as a robot must.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from mm_pc.core.checks import finite as _finite
from mm_pc.core.checks import positive as _positive
from mm_pc.core.checks import xy_pair as _xy

__all__ = [
    "PerimeterSegment",
    "correct_at_wire",
    "nearest_segment",
    "perimeter_correction",
    "rectangle_perimeter",
    "sensor_position",
]


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
            axis, value = seg
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
