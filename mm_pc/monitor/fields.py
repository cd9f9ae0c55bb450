"""What the monitor's input fields share: the error colour and number parsing.

Every field validates before anything changes; a refused value is shown in
red next to the field with a message that says what is allowed.
"""

from __future__ import annotations

import math

__all__ = ["ERROR_STYLE", "parse_number"]

#: style sheet of the red message shown next to a field that refused its input
ERROR_STYLE = "color: #b00020"


def parse_number(text: str, what: str) -> float:
    """A finite number typed by the user; ValueError naming ``what`` otherwise."""
    try:
        v = float(text.strip())
    except ValueError:
        raise ValueError(f"{what} must be a number, got {text.strip()!r}") from None
    if not math.isfinite(v):
        raise ValueError(f"{what} must be a finite number, got {text.strip()!r}")
    return v
