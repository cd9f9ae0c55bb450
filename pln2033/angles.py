"""The one angle wrap, shared by the drivers and the pose math (pure Python: the board runs it).

:mod:`mm_pc.core.angles` re-uses it (element-wise for numpy arrays).
"""

from __future__ import annotations

import math

TWO_PI = 2.0 * math.pi


def wrap_pi(angle: float) -> float:
    """``angle`` (rad) wrapped to (-pi, pi], the range of ``atan2``: -pi maps to +pi.

    ``fmod`` is exact, so an angle already in range comes back unchanged. ValueError for a
    non-finite angle.

    Why this range serves the OTOS too: its heading registers hold int16 LSBs of pi/32768
    rad, so they span [-pi, pi), and its firmware wraps its float heading to [-pi, pi)
    (``transformPose``: h >= pi -> h - 2 pi). The closed end does not reach the chip: +pi
    is 32768 LSB, which the int16 encoding (:func:`pln2033.otos.regs.int16_bytes`, the
    firmware's cast) turns into 0x8000 = -32768 = -pi, the same bytes as -pi, so the chip
    reads back -pi either way (tests/pln2033/test_otos_driver.py asserts both edges).
    """
    a = float(angle)
    if not math.isfinite(a):
        raise ValueError(f"angle must be finite numbers (no NaN or inf), got {angle!r}")
    r = math.fmod(a, TWO_PI)
    if r > math.pi:
        return r - TWO_PI
    return r + TWO_PI if r <= -math.pi else r
