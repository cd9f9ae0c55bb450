"""Units and frames: the one tested place where counts become metres and
sensor axes become base_link axes.

Sensor frame (the seed's): +y is the robot's forward direction, +x points to
the robot's right. base_link (REP 103): +x forward, +y left, yaw CCW+.
So a sensor-frame vector (X, Y) is (Y, -X) in base_link, for an ideally
mounted sensor; a mounting yaw error is handled in :mod:`mm_pc.core.geometry`.
"""

from __future__ import annotations

import numpy as np

from pln2033 import INCH_M

__all__ = ["INCH_M", "base_to_sensor", "counts_to_m", "m_to_counts", "sensor_to_base"]


def counts_to_m(counts, cpi):
    """Counts at ``cpi`` counts per inch -> metres (scalars or numpy arrays)."""
    cpi = np.asarray(cpi, dtype=float)
    if np.any(cpi <= 0) or np.any(~np.isfinite(cpi)):
        raise ValueError(f"CPI must be a positive number, got {cpi}")
    return np.asarray(counts, dtype=float) * INCH_M / cpi


def m_to_counts(metres, cpi):
    """Metres -> (fractional) counts at ``cpi``."""
    cpi = np.asarray(cpi, dtype=float)
    if np.any(cpi <= 0) or np.any(~np.isfinite(cpi)):
        raise ValueError(f"CPI must be a positive number, got {cpi}")
    return np.asarray(metres, dtype=float) * cpi / INCH_M


def sensor_to_base(x_sensor, y_sensor):
    """Sensor-frame vector (X right, Y forward) -> base_link (x forward, y left)."""
    return np.asarray(y_sensor, dtype=float), -np.asarray(x_sensor, dtype=float)


def base_to_sensor(x_base, y_base):
    """base_link vector (x forward, y left) -> sensor frame (X right, Y forward)."""
    return -np.asarray(y_base, dtype=float), np.asarray(x_base, dtype=float)
