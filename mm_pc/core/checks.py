"""Input checks every pure module shares: a finite number, finite numbers.

One wording for the messages ("<name> must be a number, got ...", "<name> must be finite,
got ...") so a refusal reads the same wherever it comes from; ``error`` lets a caller raise
its own ValueError subclass (a refused ROS message, a trilateration input).
"""

from __future__ import annotations

import math
import numbers

import numpy as np

__all__ = ["finite", "finite_array", "positive", "xy_pair"]


def finite(name: str, value, error: type[ValueError] = ValueError, *, real: bool = False) -> float:
    """``value`` as a finite float, else ``error`` naming ``name``.

    ``real=True`` accepts only real numbers (no bool, no numeric string), for values read
    from files where a quoted "1.0" is a mistake worth reporting.
    """
    if real and (isinstance(value, bool) or not isinstance(value, numbers.Real)):
        raise error(f"{name} must be a number, got {value!r} ({type(value).__name__})")
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise error(f"{name} must be a number, got {value!r}") from None
    if not math.isfinite(v):
        raise error(f"{name} must be finite, got {v}")
    return v


def finite_array(name: str, value, error: type[ValueError] = ValueError) -> np.ndarray:
    """``value`` as a float array with only finite entries, else ``error`` naming ``name``."""
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise error(f"{name} must be finite numbers, got {value!r}") from None
    if not np.all(np.isfinite(arr)):
        raise error(f"{name} must be finite numbers (no NaN or inf), got {value!r}")
    return arr


def positive(name: str, value, error: type[ValueError] = ValueError) -> float:
    """A finite number > 0, else ``error`` naming ``name``."""
    v = finite(name, value, error)
    if v <= 0:
        raise error(f"{name} must be > 0, got {value!r}")
    return v


def xy_pair(name: str, value, error: type[ValueError] = ValueError) -> tuple[float, float]:
    """A finite (x, y) pair in metres."""
    try:
        x, y = value
    except (TypeError, ValueError):
        raise error(f"{name} must be an (x, y) pair in metres, got {value!r}") from None
    return finite(f"{name} x", x, error), finite(f"{name} y", y, error)
