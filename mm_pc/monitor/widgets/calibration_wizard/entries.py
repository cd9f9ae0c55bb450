"""What the distance page accepts: a straight's true length (cm) and a spin's angle (deg),
parsed to metres and radians; ValueError with what is allowed."""

from __future__ import annotations

import math


def parse_true_distance(text: str) -> float | None:
    """The true run length typed in cm -> metres; empty -> None (scale 1).

    ValueError with what is allowed for junk, NaN, inf, or a length <= 0.
    """
    t = text.strip()
    if not t:
        return None
    allowed = "a number of cm > 0, or empty for scale 1"
    try:
        cm = float(t)
    except ValueError:
        raise ValueError(f"true distance must be {allowed}, got {t!r}") from None
    if not math.isfinite(cm) or cm <= 0:
        raise ValueError(f"true distance must be {allowed}, got {t!r}")
    return cm / 100


def parse_spin_angle(text: str) -> float:
    """The angle of each spin typed in degrees -> rad; empty -> a full turn.

    ValueError with what is allowed for junk, NaN, inf, or an angle <= 0.
    """
    t = text.strip()
    if not t:
        return 2 * math.pi
    allowed = "a number of degrees > 0 (360 = one full turn), or empty for 360"
    try:
        deg = float(t)
    except ValueError:
        raise ValueError(f"spin angle must be {allowed}, got {t!r}") from None
    if not math.isfinite(deg) or deg <= 0:
        raise ValueError(f"spin angle must be {allowed}, got {t!r}")
    return math.radians(deg)
