"""What the monitor's widgets share: colours, the error style and number parsing.

Widgets never import each other; whatever two of them must agree on (a sensor's
colour on the map and in its direction widget, the red of a refused input) is here.
Every field validates before anything changes; a refused value is shown in red
next to the field with a message that says what is allowed.
"""

from __future__ import annotations

import math

__all__ = [
    "ERROR_STYLE",
    "GAP_COLOUR",
    "ROBOT_COLOUR",
    "SENSOR_COLOURS",
    "parse_number",
    "sensor_colour",
]

#: style sheet of the red message shown next to a field that refused its input
ERROR_STYLE = "color: #b00020"

#: Colours on the white map and in the direction widgets.
ROBOT_COLOUR = "#1f3a93"
#: a stretch of the path without its single polls (drawn dashed over the path)
GAP_COLOUR = "#e0102f"
SENSOR_COLOURS = ("#e67e22", "#2e8b57", "#8e44ad", "#c0392b")


def sensor_colour(k: int) -> str:
    """Colour of sensor ``k`` (0-based) on the map and in the direction widgets."""
    return SENSOR_COLOURS[k % len(SENSOR_COLOURS)]


def parse_number(text: str, what: str) -> float:
    """A finite number typed by the user; ValueError naming ``what`` otherwise."""
    try:
        v = float(text.strip())
    except ValueError:
        raise ValueError(f"{what} must be a number, got {text.strip()!r}") from None
    if not math.isfinite(v):
        raise ValueError(f"{what} must be a finite number, got {text.strip()!r}")
    return v
