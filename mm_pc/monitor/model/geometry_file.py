"""The robot-geometry file the geometry dialog saves and loads (YAML, SI units, versioned).

Kept apart from the dialog so the format is readable and testable without Qt.
"""

from __future__ import annotations

import math

import yaml

from mm_pc.core.geometry import RobotGeometry, SensorMount

__all__ = ["YAML_VERSION", "geometry_from_yaml", "geometry_to_yaml"]

YAML_VERSION = 1



def geometry_to_yaml(geometry: RobotGeometry, sensor: int) -> str:
    """YAML text of a geometry (SI units, unit-suffixed keys)."""
    data = {
        "version": YAML_VERSION,
        "axis_length_m": float(geometry.axis_length),
        "sensor": int(sensor),
        "mounts": [
            {"x_m": float(m.x), "y_m": float(m.y), "yaw_rad": float(m.yaw)}
            for m in geometry.mounts
        ],
    }
    return yaml.safe_dump(data, sort_keys=False)


def geometry_from_yaml(text: str) -> tuple[RobotGeometry, int]:
    """Inverse of :func:`geometry_to_yaml`; ValueError saying what is wrong."""
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as e:
        raise ValueError(f"geometry: not valid YAML: {e}") from None
    if not isinstance(data, dict):
        raise ValueError("geometry: expected a mapping with version, axis_length_m, sensor, mounts")
    if data.get("version") != YAML_VERSION:
        raise ValueError(
            f"geometry: unsupported version {data.get('version')!r}, expected {YAML_VERSION}"
        )
    mounts_data = data.get("mounts")
    if not isinstance(mounts_data, list) or not mounts_data:
        raise ValueError("geometry: 'mounts' must be a non-empty list of {x_m, y_m, yaw_rad}")
    mounts = []
    for i, m in enumerate(mounts_data):
        if not isinstance(m, dict) or set(m) != {"x_m", "y_m", "yaw_rad"}:
            raise ValueError(f"geometry: mount {i} must have exactly x_m, y_m, yaw_rad, got {m!r}")
        vals = [_yaml_number(m[k], f"mount {i} {k}") for k in ("x_m", "y_m", "yaw_rad")]
        mounts.append(SensorMount(*vals))
    axis = _yaml_number(data.get("axis_length_m"), "axis_length_m")
    sensor = data.get("sensor", 0)
    if isinstance(sensor, bool) or not isinstance(sensor, int):
        raise ValueError(f"geometry: sensor must be an integer index, got {sensor!r}")
    return RobotGeometry(tuple(mounts), axis), sensor


def _yaml_number(value, what: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ValueError(f"geometry: {what} must be a finite number, got {value!r}")
    return float(value)
