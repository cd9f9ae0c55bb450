"""Mounting-angle and scale calibration from a straight run.

Pure math: numpy and PyYAML, no Qt, no ROS.

Derivations and measurements: docs/pose-math.md,
section "mm_pc.core.calibration in detail".
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np
import yaml

from mm_pc.core.angles import wrap_pi
from mm_pc.core.checks import finite

__all__ = [
    "DEFAULT_MIN_DISTANCE_M",
    "Calibration",
    "SensorCalibration",
    "calibrate_straight_run",
]

#: Shortest straight run accepted for a calibration (m). Below this the
#: angle is dominated by count quantisation and noise.
DEFAULT_MIN_DISTANCE_M = 0.05

#: Version written into and required from the YAML file.
YAML_VERSION = 1


def _finite_number(name: str, value) -> float:
    """``value`` as a float, or ValueError if it is not a finite real number."""
    return finite(name, value, real=True)


@dataclass(frozen=True)
class SensorCalibration:
    """The calibration of one sensor.

    Attributes:
        angle_offset: correction angle in rad, (-pi, pi]; equals the
            sensor's mounting yaw error (see the module docstring).
        distance: length |(X, Y)| of the raw summed calibration run in m
            (0 for the identity calibration: no run).
        scale: factor applied to every corrected sample, > 0 (true distance /
            measured distance; 1 when no true distance was entered).
    """

    angle_offset: float = 0.0
    distance: float = 0.0
    scale: float = 1.0

    def __post_init__(self) -> None:
        a = _finite_number("angle_offset", self.angle_offset)
        d = _finite_number("distance", self.distance)
        s = _finite_number("scale", self.scale)
        if not -math.pi < a <= math.pi:
            raise ValueError(f"angle_offset must be in (-pi, pi] rad, got {a}")
        if d < 0:
            raise ValueError(f"distance must be >= 0 m, got {d}")
        if s <= 0:
            raise ValueError(f"scale must be > 0, got {s}")
        object.__setattr__(self, "angle_offset", a)
        object.__setattr__(self, "distance", d)
        object.__setattr__(self, "scale", s)

    @cached_property
    def _cs(self) -> tuple[float, float]:
        """(scale * cos, scale * sin) of the offset, computed once."""
        return self.scale * math.cos(self.angle_offset), self.scale * math.sin(self.angle_offset)

    @classmethod
    def identity(cls) -> SensorCalibration:
        """No rotation, scale 1."""
        return cls(0.0, 0.0, 1.0)

    @property
    def angle_offset_deg(self) -> float:
        """The correction angle in degrees (for display)."""
        return math.degrees(self.angle_offset)

    def apply(self, dx, dy):
        """Correct raw sensor-frame displacement(s) (m, or counts: linear).

        ``dx``, ``dy``: scalars or numpy arrays of the same shape (sensor X
        right, Y forward). Returns ``(dx', dy')`` as floats / float arrays:
        rotated by ``+angle_offset``, both from the unrotated input, times
        ``scale``.
        """
        x = np.asarray(dx, dtype=float)
        y = np.asarray(dy, dtype=float)
        c, s = self._cs
        xr = c * x - s * y
        yr = s * x + c * y
        if xr.ndim == 0:
            return float(xr), float(yr)
        return xr, yr

    def to_dict(self) -> dict[str, float]:
        """Plain dict with unit-suffixed keys (the YAML layout of one sensor)."""
        return {
            "angle_offset_rad": self.angle_offset,
            "distance_m": self.distance,
            "scale": self.scale,
        }

    @classmethod
    def from_dict(cls, data, where: str = "sensor") -> SensorCalibration:
        """Inverse of :meth:`to_dict`; ValueError naming ``where`` on bad input."""
        if not isinstance(data, Mapping):
            raise ValueError(f"{where}: expected a mapping, got {type(data).__name__}")
        keys = set(data)
        allowed = {"angle_offset_rad", "distance_m", "scale"}
        if keys - allowed:
            raise ValueError(
                f"{where}: unknown key(s) {sorted(map(str, keys - allowed))}; "
                f"allowed: {sorted(allowed)}"
            )
        if allowed - keys:
            raise ValueError(f"{where}: missing key(s) {sorted(allowed - keys)}")
        try:
            return cls(data["angle_offset_rad"], data["distance_m"], data["scale"])
        except ValueError as e:
            raise ValueError(f"{where}: {e}") from None


def calibrate_straight_run(
    x: float,
    y: float,
    true_distance: float | None = None,
    min_distance: float = DEFAULT_MIN_DISTANCE_M,
) -> SensorCalibration:
    """Calibrate one sensor from its summed raw displacement over a straight run.

    Args:
        x, y: summed raw sensor-frame displacement (m) over a straight
            forward or backward run (X right, Y forward, no calibration
            applied).
        true_distance: the run's true length in m as measured by the user,
            or None for scale 1.
        min_distance: shortest accepted run in m (default 5 cm).

    Returns:
        A :class:`SensorCalibration` whose ``angle_offset`` is the mounting
        yaw error (seed formula, see module docstring), ``distance`` =
        |(x, y)|, ``scale`` = true_distance / distance.

    Raises:
        ValueError: NaN/inf input, a run shorter than ``min_distance``, a
        run with Y == 0 (direction undefined: the sensor moved exactly
        sideways), or a true distance <= 0 / NaN.
    """
    x = _finite_number("X displacement", x)
    y = _finite_number("Y displacement", y)
    min_distance = _finite_number("min_distance", min_distance)
    if min_distance < 0:
        raise ValueError(f"min_distance must be >= 0 m, got {min_distance}")
    distance = math.hypot(x, y)
    if distance < min_distance or distance == 0.0:
        raise ValueError(
            f"calibration run too short: {distance * 100:.2f} cm travelled, "
            f"at least {min_distance * 100:.2f} cm needed; drive further straight ahead"
        )
    if y == 0.0:
        raise ValueError(
            f"calibration run has Y = 0 (X = {x:.4g} m): the sensor moved exactly sideways, "
            "so forward/backward is undefined; the mounting error must be below 90 degrees "
            "and the run straight forward or backward"
        )
    atan_real = math.pi / 2 if y > 0 else -math.pi / 2
    offset = wrap_pi(atan_real - math.atan2(y, x))
    scale = 1.0
    if true_distance is not None:
        td = _finite_number("true distance", true_distance)
        if td <= 0:
            raise ValueError(f"true distance must be > 0 m, got {td}")
        scale = td / distance
    return SensorCalibration(offset, distance, scale)


class Calibration:
    """One :class:`SensorCalibration` per sensor id (the SPI device path).

    Sensors without an entry are treated as identity by :meth:`get` and
    :meth:`apply`. Serialises to YAML::

        version: 1
        sensors:
          /dev/spidev1.0: {angle_offset_rad: 0.087, distance_m: 1.0, scale: 1.0}
    """

    def __init__(self, sensors: Mapping[str, SensorCalibration] | None = None) -> None:
        self._sensors: dict[str, SensorCalibration] = {}
        for sid, cal in (sensors or {}).items():
            self[sid] = cal

    # --- mapping-like access -------------------------------------------------------

    def __setitem__(self, sensor_id: str, cal: SensorCalibration) -> None:
        if not isinstance(sensor_id, str) or not sensor_id:
            raise ValueError(f"sensor id must be a non-empty string, got {sensor_id!r}")
        if not isinstance(cal, SensorCalibration):
            raise ValueError(f"expected a SensorCalibration for {sensor_id}, got {cal!r}")
        self._sensors[sensor_id] = cal

    def __getitem__(self, sensor_id: str) -> SensorCalibration:
        return self._sensors[sensor_id]

    def __contains__(self, sensor_id: object) -> bool:
        return sensor_id in self._sensors

    def __iter__(self):
        return iter(self._sensors)

    def __len__(self) -> int:
        return len(self._sensors)

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Calibration) and self._sensors == other._sensors

    def __repr__(self) -> str:
        return f"Calibration({self._sensors!r})"

    @property
    def sensors(self) -> dict[str, SensorCalibration]:
        """A copy of the per-sensor calibrations."""
        return dict(self._sensors)

    def get(self, sensor_id: str) -> SensorCalibration:
        """The sensor's calibration, identity if it has none."""
        return self._sensors.get(sensor_id) or SensorCalibration.identity()

    def apply(self, sensor_id: str, dx, dy):
        """Correct raw displacement(s) of ``sensor_id``; see :meth:`SensorCalibration.apply`."""
        return self.get(sensor_id).apply(dx, dy)

    @classmethod
    def identity(cls, sensor_ids: Iterable[str] = ()) -> Calibration:
        """Identity calibration for the given sensor ids (none: empty, all identity)."""
        return cls({sid: SensorCalibration.identity() for sid in sensor_ids})

    # --- YAML --------------------------------------------------------------------------

    def to_dict(self) -> dict:
        return {
            "version": YAML_VERSION,
            "sensors": {sid: cal.to_dict() for sid, cal in self._sensors.items()},
        }

    @classmethod
    def from_dict(cls, data) -> Calibration:
        if not isinstance(data, Mapping):
            raise ValueError(
                "calibration: expected a mapping with 'version' and 'sensors', "
                f"got {type(data).__name__}"
            )
        allowed = {"version", "sensors"}
        keys = set(data)
        if keys - allowed:
            raise ValueError(
                f"calibration: unknown key(s) {sorted(map(str, keys - allowed))}; "
                f"allowed: {sorted(allowed)}"
            )
        if allowed - keys:
            raise ValueError(f"calibration: missing key(s) {sorted(allowed - keys)}")
        version = data["version"]
        if isinstance(version, bool) or version != YAML_VERSION:
            raise ValueError(
                f"calibration: unsupported version {version!r}, expected {YAML_VERSION}"
            )
        sensors = data["sensors"]
        if sensors is None:
            sensors = {}
        if not isinstance(sensors, Mapping):
            raise ValueError(
                f"calibration: 'sensors' must be a mapping of sensor id to calibration, "
                f"got {type(sensors).__name__}"
            )
        out = cls()
        for sid, entry in sensors.items():
            if not isinstance(sid, str) or not sid:
                raise ValueError(f"calibration: sensor id must be a non-empty string, got {sid!r}")
            out[sid] = SensorCalibration.from_dict(entry, where=f"calibration of {sid}")
        return out

    def to_yaml(self) -> str:
        """YAML text; floats are written with full precision (round-trips exactly)."""
        return yaml.safe_dump(self.to_dict(), sort_keys=False)

    @classmethod
    def from_yaml(cls, text: str) -> Calibration:
        """Parse :meth:`to_yaml` output; ValueError with a message on any bad input."""
        try:
            data = yaml.safe_load(text)
        except yaml.YAMLError as e:
            raise ValueError(f"calibration: not valid YAML: {e}") from None
        return cls.from_dict(data)

    def save(self, path: str | Path) -> None:
        """Write the YAML to ``path`` (atomically: a temporary file, then rename)."""
        path = Path(path)
        tmp = path.with_name(path.name + ".tmp")
        tmp.write_text(self.to_yaml(), encoding="utf-8")
        tmp.replace(path)

    @classmethod
    def load(cls, path: str | Path) -> Calibration:
        """Read a file written by :meth:`save`. OSError if unreadable, ValueError if bad."""
        return cls.from_yaml(Path(path).read_text(encoding="utf-8"))
