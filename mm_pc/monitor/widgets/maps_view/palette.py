"""The Maps tab's colours: a colour-blind-safe palette (Okabe-Ito) for the seed's cell codes.

The seed (001) draws unmowed dark green and mowed light green, perimeter red,
mower blue, obstacle magenta, unknown white (``COLORS_RGB`` in
:mod:`mm_pc.core.maps.coverage_map`, kept there as the seed's). Two greens
and red/green are what colour-blind eyes confuse, so the monitor draws the
same codes in Okabe-Ito colours that keep each meaning's hue where it can:
unknown white, perimeter vermillion (red), unmowed bluish green (green),
mower blue, obstacle reddish purple (magenta). The one departure: **mowed is
yellow**, not light green -- unmowed and mowed must differ in lightness, not
only in hue (docs/monitor.md says so too).

The paths differ in more than colour: truth thin solid black, fused a wide
sky-blue line under it, raw mouse odometry dashed orange.
"""

from __future__ import annotations

import numpy as np
from PySide6.QtCore import Qt

from mm_pc.core.maps.coverage_map import CODE_NAMES

__all__ = ["DISPLAY_RGB8", "OKABE_ITO", "PATH_STYLES", "luminance"]

#: Okabe & Ito (2008), "Color Universal Design"
OKABE_ITO = {
    "black": (0, 0, 0), "orange": (230, 159, 0), "sky blue": (86, 180, 233),
    "bluish green": (0, 158, 115), "yellow": (240, 228, 66), "blue": (0, 114, 178),
    "vermillion": (213, 94, 0), "reddish purple": (204, 121, 167),
}
_BY_CODE = {
    "unknown": (255, 255, 255), "perimeter": OKABE_ITO["vermillion"],
    "unmowed": OKABE_ITO["bluish green"], "mowed": OKABE_ITO["yellow"],
    "mower": OKABE_ITO["blue"], "obstacle": OKABE_ITO["reddish purple"],
}
#: uint8 RGB per cell code (row = code, as ``COLORS_RGB8``), read-only
DISPLAY_RGB8 = np.array([_BY_CODE[name] for name in CODE_NAMES], dtype=np.uint8)
DISPLAY_RGB8.flags.writeable = False

#: path key -> (colour, width px, Qt pen style, drawn order: higher on top)
PATH_STYLES = {
    "fused": ("#{:02x}{:02x}{:02x}".format(*OKABE_ITO["sky blue"]), 4, Qt.PenStyle.SolidLine, 0),
    "raw": ("#{:02x}{:02x}{:02x}".format(*OKABE_ITO["orange"]), 2, Qt.PenStyle.DashLine, 1),
    "truth": ("#000000", 1, Qt.PenStyle.SolidLine, 2),
}


def luminance(rgb8) -> float:
    """Relative luminance (0 black .. 1 white, WCAG) of an RGB colour in 0..255."""
    c = np.asarray(rgb8, float) / 255
    lin = np.where(c <= 0.03928, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)
    return float(lin @ (0.2126, 0.7152, 0.0722))
