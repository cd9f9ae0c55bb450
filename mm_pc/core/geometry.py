"""Robot geometry: where the sensors sit, and the seed's derived values.

All lengths in metres, angles in radians, positions in base_link (REP 103:
x forward, y left). The seed describes a sensor by its offset to the right
(sx) and forward (sy) of the axle centre; base_link (x, y) = (sy, -sx).
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class SensorMount:
    """One sensor on the robot, base_link metres and radians.

    ``yaw`` is the mounting error: the sensor's axes are turned ``yaw`` (CCW,
    seen from above) from the ideal (sensor +Y along base_link +x), so the
    sensor reports the ideal vector turned by -yaw.
    """

    x: float
    y: float
    yaw: float = 0.0

    @property
    def right(self) -> float:
        """The seed's sx: offset to the robot's right (m)."""
        return -self.y

    @property
    def forward(self) -> float:
        """The seed's sy: offset forward of the axle centre (m)."""
        return self.x

    @property
    def radius(self) -> float:
        """Distance from the axle centre (the seed's distanceToSensor_radius)."""
        return math.hypot(self.x, self.y)

    @property
    def sensor_angle(self) -> float:
        """Angle between the robot's forward axis and the line to the sensor (rad)."""
        return math.atan2(self.y, self.x)

    @property
    def slope(self) -> float:
        """The seed's m: sensor dY/dX during a pure rotation, -sx/sy (inf if sy = 0)."""
        return -self.right / self.forward if self.forward else math.inf


@dataclass(frozen=True)
class RobotGeometry:
    """The sensor mounts and the wheel axis length of a robot."""

    mounts: tuple[SensorMount, ...]
    axis_length: float = 0.079

    def __post_init__(self) -> None:
        if not self.mounts:
            raise ValueError("a robot needs at least one sensor mount")
        if not self.axis_length > 0:
            raise ValueError(f"axle length must be > 0 m (axis_length), got {self.axis_length}")
        for m in self.mounts:
            if not all(math.isfinite(v) for v in (m.x, m.y, m.yaw)):
                raise ValueError(f"sensor mount {m} has a non-finite value")

    @property
    def distance_to_wheel(self) -> float:
        """Half the axis length (the seed's distanceToWheel)."""
        return self.axis_length / 2


#: The original robot: axis 7.9 cm; sensor 1 (/dev/spidev1.0) 3.95 cm right and
#: 4.9 cm forward of the axle centre, sensor 2 mirrored to the left.
DEFAULT_MOUNTS = (SensorMount(0.049, -0.0395), SensorMount(0.049, 0.0395))
DEFAULT_GEOMETRY = RobotGeometry(DEFAULT_MOUNTS, 0.079)
