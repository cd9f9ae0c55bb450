"""Where ``mm-monitor --sim`` mounts the emulated sensors (no Qt, no ROS).

``--sim-mounts "X,Y,YAW;X,Y,YAW"``: per sensor its base_link position (m) and
mounting yaw (degrees), sensors separated by ``;`` -- the node's ``sim_mounts``
(x, y, yaw in rad, flattened). ``--sim calibration_run`` without it mounts them
with :data:`CALIBRATION_SIM_MOUNTS`, a known error against the monitor's default
geometry (:data:`mm_pc.core.geometry.DEFAULT_MOUNTS`, (49, ∓39.5) mm, yaw 0), so that
the calibration wizard has something to find and shows it next to the truth.
"""

from __future__ import annotations

import math

from mm_pc.core.geometry import SensorMount

__all__ = ["CALIBRATION_SIM_MOUNTS", "describe_sim_mounts", "parse_sim_mounts", "to_parameter"]

#: --sim calibration_run's default: yaw +3 deg / -2 deg, positions 1-2 mm off the design
CALIBRATION_SIM_MOUNTS: tuple[SensorMount, ...] = (
    SensorMount(0.051, -0.0385, math.radians(3.0)),
    SensorMount(0.047, 0.0410, math.radians(-2.0)),
)


def parse_sim_mounts(text: str) -> tuple[SensorMount, ...]:
    """``"0.051,-0.0385,3;0.047,0.041,-2"`` -> mounts (m, m, yaw in rad); ValueError
    saying the format for anything else (not 3 numbers per sensor, non-finite, a
    position over 1 m, a yaw over 180 deg)."""
    form = "X,Y,YAW per sensor (m, m, degrees), sensors separated by ';'"
    mounts = []
    for k, part in enumerate(text.split(";")):
        try:
            x, y, yaw = (float(v) for v in part.split(","))
        except ValueError:
            raise ValueError(f"--sim-mounts needs {form}; sensor {k} is {part.strip()!r}") from None
        if not all(math.isfinite(v) for v in (x, y, yaw)) or max(abs(x), abs(y)) > 1 or abs(
            yaw
        ) > 180:
            raise ValueError(
                f"--sim-mounts: sensor {k} ({part.strip()}) needs |x|, |y| <= 1 m and "
                "|yaw| <= 180 deg"
            )
        mounts.append(SensorMount(x, y, math.radians(yaw)))
    return tuple(mounts)


def to_parameter(mounts) -> list[float]:
    """The node's ``sim_mounts`` parameter: x, y, yaw (rad) per sensor, flattened."""
    return [float(v) for m in mounts for v in (m.x, m.y, m.yaw)]


def describe_sim_mounts(mounts) -> str:
    """One line for the console: "(51.0, -38.5) mm +3.00 deg; ..."."""
    return "; ".join(
        f"({m.x * 1000:.1f}, {m.y * 1000:.1f}) mm {math.degrees(m.yaw):+.2f} deg" for m in mounts
    )
