"""The optical-flow scale: metres per count from the height above the floor (pure, no I/O).

An optical-flow chip counts image motion, not floor motion: a lens of field of view
``fov`` images the floor on ``pixels`` pixels, and the chip reports ``counts_per_pixel``
counts per pixel of image motion. Seen from ``height_m`` (lens to floor) the field of
view covers ``2 * height_m * tan(fov / 2)`` metres of floor (pinhole model), so

    metres per count = height_m * 2 * tan(fov / 2) / (pixels * counts_per_pixel)

and the effective resolution is ``INCH_M / metres per count`` counts per inch. The counts
scale inversely with the height: a driver configured for 0.10 m on a sensor that sits at
0.12 m reports 0.10 / 0.12 of the true distance, and the calibration fit's per-axis scale
(``mm_pc.core.calibration_fit``) measures the factor 1.2 that corrects it. The model is the
starting value; the fit gives the true scale (docs/sensors.md, "Optical-flow scale").

The constants disagree between sources (docs/sensors.md):

- Bitcraze (crazyflie-firmware ``src/modules/src/kalman_core/mm_flow.c``, PMW3901 flow deck):
  ``pixelNbr = 30``, ``thetapix = 4.2 deg``, predicted counts = dt * 30 / thetapix * v / z,
  i.e. 2.44 mrad per count (small-angle form of the model above with 1 count per pixel).
- adityakamath/optical_flow_ros (tested on a PAA5100): ``FOV_DEG = 42``, ``RES_PIX = 35``,
  ``motion_scale = 5`` (default), metres = z * 2 tan(FOV/2) / (RES_PIX * motion_scale) * counts
  (4.39 mrad per count).
- PX4 (``PMW3901.cpp``: counts / 500 or / 385 rad) and ArduPilot (``AP_OpticalFlow_Pixart``:
  1.26 mrad per count) use yet other constants.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..sensor import INCH_M


@dataclass(frozen=True)
class FlowOptics:
    """A field-of-view model: ``fov_deg`` over ``pixels`` pixels, ``counts_per_pixel`` counts each.

    All three only enter as ``2 tan(fov/2) / (pixels * counts_per_pixel)`` (rad per count
    for small angles); ``source`` says where the numbers come from.
    """

    fov_deg: float
    pixels: float
    counts_per_pixel: float = 1.0
    source: str = ""

    def __post_init__(self) -> None:
        for name in ("fov_deg", "pixels", "counts_per_pixel"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
                raise ValueError(f"optical-flow {name} must be a finite number, got {v!r}")
        if not 0 < self.fov_deg < 180:
            raise ValueError(f"field of view must be 0..180 degrees, got {self.fov_deg}")
        if self.pixels <= 0 or self.counts_per_pixel <= 0:
            raise ValueError(
                f"pixels and counts per pixel must be > 0, got {self.pixels}, "
                f"{self.counts_per_pixel}"
            )

    @property
    def rad_per_count(self) -> float:
        """Image angle per count at the centre of the view (rad)."""
        return (
            2.0 * math.tan(math.radians(self.fov_deg) / 2.0) / (self.pixels * self.counts_per_pixel)
        )

    def metres_per_count(self, height_m: float) -> float:
        """Floor distance of one count seen from ``height_m`` (m; no range check here)."""
        return height_m * self.rad_per_count

    def cpi(self, height_m: float) -> float:
        """Effective counts per inch at ``height_m`` (float; the driver rounds it)."""
        return INCH_M / self.metres_per_count(height_m)

    def height_for_cpi(self, cpi: float) -> float:
        """The height at which the chip counts ``cpi`` counts per inch (m)."""
        return INCH_M / (cpi * self.rad_per_count)


#: [bitcraze] mm_flow.c, flight-tested with the PMW3901 (Flow deck v1/v2).
BITCRAZE_PMW3901 = FlowOptics(4.2, 30, 1.0, "bitcraze/crazyflie-firmware mm_flow.c")
#: [optical_flow_ros] optical_flow_publisher.py, its author's PAA5100 tests (motion_scale 5).
OPTICAL_FLOW_ROS_PAA5100 = FlowOptics(42.0, 35, 5.0, "adityakamath/optical_flow_ros")


def scale_table() -> str:
    """The figures docs/sensors.md quotes: ``python -m pln2033.pmw3901``."""
    from .driver import PAA5100, PMW3901

    lines = ["chip     source                                  mrad/count  height_m  mm/count  CPI"]
    for cls in (PMW3901, PAA5100):
        lo, hi = cls.HEIGHT_RANGE_M
        for h in (lo, cls.HEIGHT_DEFAULT_M, hi):
            o = cls.OPTICS
            lines.append(
                f"{cls.CHIP:8} {o.source:39} {o.rad_per_count * 1e3:10.3f}  {h:8.3f}  "
                f"{o.metres_per_count(h) * 1e3:8.4f}  {o.cpi(h):6.1f}"
            )
    for name, o in (("bitcraze", BITCRAZE_PMW3901), ("optical_flow_ros", OPTICAL_FLOW_ROS_PAA5100)):
        lines.append(f"{name} at 0.10 m: {o.cpi(0.10):.1f} CPI; at 0.025 m: {o.cpi(0.025):.1f} CPI")
    return "\n".join(lines)
