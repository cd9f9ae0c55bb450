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
    "STALE_STYLE",
    "STALE_WORDS",
    "parse_number",
    "sensor_axis_colour",
    "sensor_colour",
    "stale_text",
]

#: style sheet of the red message shown next to a field that refused its input
ERROR_STYLE = "color: #b00020"

#: Colours on the white map, in the direction widgets, the graphs and the Health plots:
#: one colour per sensor everywhere (this module is the one source).
ROBOT_COLOUR = "#1f3a93"
#: a stretch of the path without its single polls (drawn dashed over the path)
GAP_COLOUR = "#e0102f"
SENSOR_COLOURS = ("#e67e22", "#2e8b57", "#8e44ad", "#c0392b")

#: why the values on screen are old, per data state of the context (others: live values)
STALE_WORDS = {"lost": "link lost", "paused": "paused"}
#: style of a value that is old (link lost, paused): grey
STALE_STYLE = "color: #808080"


def stale_text(ctx) -> str:
    """"link lost: no data since HH:MM:SS" (or "paused: …") while ``ctx`` (a
    MonitorContext) shows old values; "" while they are live."""
    words = STALE_WORDS.get(ctx.data_state)
    return f"{words}: {ctx.no_data_since()}" if words else ""


def sensor_colour(k: int) -> str:
    """Colour of sensor ``k`` (0-based): its path on the map, its direction dial, its
    graphs and its curves on the Health tab."""
    return SENSOR_COLOURS[k % len(SENSOR_COLOURS)]


#: a sensor's Y curve (sensor forward) is its colour darkened by this factor; X is its colour
Y_SHADE = 0.55


def sensor_axis_colour(k: int, axis: str) -> str:
    """Colour of sensor ``k``'s ``axis`` curve ("x": its colour, "y": a darker shade of it),
    so a plot with both axes still reads as that one sensor."""
    colour = sensor_colour(k)
    if axis == "x":
        return colour
    if axis != "y":
        raise ValueError(f"axis must be 'x' or 'y', got {axis!r}")
    r, g, b = (int(colour[i:i + 2], 16) for i in (1, 3, 5))
    return "#" + "".join(f"{round(c * Y_SHADE):02x}" for c in (r, g, b))


def parse_number(text: str, what: str) -> float:
    """A finite number typed by the user; ValueError naming ``what`` otherwise."""
    try:
        v = float(text.strip())
    except ValueError:
        raise ValueError(f"{what} must be a number, got {text.strip()!r}") from None
    if not math.isfinite(v):
        raise ValueError(f"{what} must be a finite number, got {text.strip()!r}")
    return v
