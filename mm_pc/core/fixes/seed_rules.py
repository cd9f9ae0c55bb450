"""The seeds' own rules, literally, kept to compare ours with (tests and docs show the gaps).

Seed 004's wheel steps "for straight lines and gentle curves" and "pivot about a standing
wheel", and its GPS correction rule. They are reference implementations, not used by the
fusion: :mod:`.wheels` and :mod:`mm_pc.core.fusion` do it exactly; docs/maps-and-fixes.md
says where the seed approximates.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from mm_pc.core.checks import finite as _finite
from mm_pc.core.checks import positive as _positive
from mm_pc.core.checks import xy_pair as _xy
from mm_pc.core.fixes.gps import GpsQuality, gps_accuracy_m, gps_fix_usable

__all__ = [
    "gps_correction",
    "seed_gentle_step",
    "seed_pivot_step",
]


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
