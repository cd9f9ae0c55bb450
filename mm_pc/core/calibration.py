"""Mounting-angle and scale calibration from a straight run.

Pure math: numpy and PyYAML, no Qt, no ROS.

Derivations and measurements: docs/pose-math.md,
section "mm_pc.core.calibration in detail".
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, replace
from functools import cached_property
from pathlib import Path

import numpy as np
import yaml

from mm_pc.core.angles import wrap_pi
from mm_pc.core.checks import finite
from mm_pc.core.geometry import SensorMount
from mm_pc.core.user_file import read_user_text
from mm_pc.core.yaml_text import parse_yaml

__all__ = [
    "CALIBRATION_METHODS",
    "DEFAULT_MIN_DISTANCE_M",
    "Calibration",
    "SensorCalibration",
    "calibrate_straight_run",
]

#: Shortest straight run accepted for a calibration (m). Below this the
#: angle is dominated by count quantisation and noise.
DEFAULT_MIN_DISTANCE_M = 0.05

#: Version written into the YAML file; version 1 files (one scale, no
#: position) still load.
YAML_VERSION = 2
READABLE_VERSIONS = (1, 2)

#: Names of the ways a calibration was made (the file's ``method``).
CALIBRATION_METHODS = ("straight-run", "fit")


def _finite_number(name: str, value) -> float:
    """``value`` as a float, or ValueError if it is not a finite real number."""
    return finite(name, value, real=True)


#: Optional per-sensor keys of a version-2 file (value None = not estimated):
#: YAML key -> attribute.
_OPTIONAL_KEYS = {
    "angle_offset_se_rad": "angle_offset_se",
    "scale_x_se": "scale_x_se",
    "scale_y_se": "scale_y_se",
    "x_m": "x",
    "y_m": "y",
    "x_se_m": "x_se",
    "y_se_m": "y_se",
}


@dataclass(frozen=True)
class SensorCalibration:
    """The calibration of one sensor.

    Attributes:
        angle_offset: correction angle in rad, (-pi, pi]; equals the
            sensor's mounting yaw error (see the module docstring).
        distance: length |(X, Y)| of the raw summed straight run(s) in m
            (0 for the identity calibration: no run).
        scale: the forward (sensor Y) scale; the one scale of a version-1
            file. With ``scale_y`` given it is set to ``scale_y``.
        scale_x, scale_y: factors applied to the sensor's own X and Y
            counts before the rotation, > 0 (true / measured); None = ``scale``.
        x, y: the sensor's position in base_link (m) relative to the turning
            centre, as fitted from spins; None = use the configured mount.
        angle_offset_se, scale_x_se, scale_y_se, x_se, y_se: standard errors
            of the fitted values (rad, 1, 1, m, m); None = not estimated.

    Correction (sensor frame, X right, Y forward)::

        (x', y') = R(angle_offset) @ (scale_x * x, scale_y * y)
    """

    angle_offset: float = 0.0
    distance: float = 0.0
    scale: float = 1.0
    scale_x: float | None = None
    scale_y: float | None = None
    x: float | None = None
    y: float | None = None
    angle_offset_se: float | None = None
    scale_x_se: float | None = None
    scale_y_se: float | None = None
    x_se: float | None = None
    y_se: float | None = None

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
        sx = s if self.scale_x is None else _finite_number("scale_x", self.scale_x)
        sy = s if self.scale_y is None else _finite_number("scale_y", self.scale_y)
        for name, v in (("scale_x", sx), ("scale_y", sy)):
            if v <= 0:
                raise ValueError(f"{name} must be > 0, got {v}")
        if (self.x is None) != (self.y is None):
            raise ValueError("a position needs both x and y (m), or neither")
        object.__setattr__(self, "angle_offset", a)
        object.__setattr__(self, "distance", d)
        object.__setattr__(self, "scale", sy)
        object.__setattr__(self, "scale_x", sx)
        object.__setattr__(self, "scale_y", sy)
        for attr in _OPTIONAL_KEYS.values():
            v = getattr(self, attr)
            if v is not None:
                v = _finite_number(attr, v)
                if attr.endswith("_se") and v < 0:
                    raise ValueError(f"{attr} must be >= 0, got {v}")
                object.__setattr__(self, attr, v)

    @property
    def scales(self) -> tuple[float, float]:
        """(scale_x, scale_y): both set by ``__post_init__`` (None given means ``scale``)."""
        sx, sy = self.scale_x, self.scale_y
        return (self.scale if sx is None else sx), (self.scale if sy is None else sy)

    @cached_property
    def _m(self) -> tuple[float, float, float, float]:
        """The correction matrix R(offset) @ diag(scale_x, scale_y), row major, computed once."""
        c, s = math.cos(self.angle_offset), math.sin(self.angle_offset)
        sx, sy = self.scales
        return c * sx, -s * sy, s * sx, c * sy

    @classmethod
    def identity(cls) -> SensorCalibration:
        """No rotation, scale 1."""
        return cls(0.0, 0.0, 1.0)

    @property
    def angle_offset_deg(self) -> float:
        """The correction angle in degrees (for display)."""
        return math.degrees(self.angle_offset)

    @property
    def position(self) -> tuple[float, float] | None:
        """The fitted base_link position (x, y) in m, or None."""
        return None if self.x is None or self.y is None else (self.x, self.y)

    def apply(self, dx, dy):
        """Correct raw sensor-frame displacement(s) (m, or counts: linear).

        ``dx``, ``dy``: scalars or numpy arrays of the same shape (sensor X
        right, Y forward). Returns ``(dx', dy')`` as floats / float arrays:
        scaled per axis, then rotated by ``+angle_offset``, both components
        from the unrotated input.
        """
        a, b, c, d = self._m
        if type(dx) is float and type(dy) is float:  # the per-reply path: no arrays
            return a * dx + b * dy, c * dx + d * dy
        x = np.asarray(dx, dtype=float)
        y = np.asarray(dy, dtype=float)
        xr = a * x + b * y
        yr = c * x + d * y
        if xr.ndim == 0:
            return float(xr), float(yr)
        return xr, yr

    def to_dict(self) -> dict[str, float]:
        """Plain dict with unit-suffixed keys (the version-2 YAML layout of one sensor)."""
        sx, sy = self.scales
        out = {
            "angle_offset_rad": self.angle_offset,
            "distance_m": self.distance,
            "scale_x": sx,
            "scale_y": sy,
        }
        for key, attr in _OPTIONAL_KEYS.items():
            if getattr(self, attr) is not None:
                out[key] = getattr(self, attr)
        return out

    @classmethod
    def from_dict(
        cls, data, where: str = "sensor", version: int = YAML_VERSION
    ) -> SensorCalibration:
        """Inverse of :meth:`to_dict` (``version`` 1: the old layout with one
        ``scale``); ValueError naming ``where`` on bad input."""
        if not isinstance(data, Mapping):
            raise ValueError(f"{where}: expected a mapping, got {type(data).__name__}")
        keys = set(data)
        if version == 1:
            required = {"angle_offset_rad", "distance_m", "scale"}
            allowed = set(required)
        else:
            required = {"angle_offset_rad", "distance_m", "scale_x", "scale_y"}
            allowed = required | set(_OPTIONAL_KEYS)
        if keys - allowed:
            raise ValueError(
                f"{where}: unknown key(s) {sorted(map(str, keys - allowed))}; "
                f"allowed: {sorted(allowed)}"
            )
        if required - keys:
            raise ValueError(f"{where}: missing key(s) {sorted(required - keys)}")
        try:
            if version == 1:
                return cls(data["angle_offset_rad"], data["distance_m"], data["scale"])
            extra = {attr: data[key] for key, attr in _OPTIONAL_KEYS.items() if key in data}
            return cls(
                data["angle_offset_rad"],
                data["distance_m"],
                scale_x=data["scale_x"],
                scale_y=data["scale_y"],
                **extra,
            )
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


#: the calibration of a sensor without one (immutable, so one object serves all)
_IDENTITY = SensorCalibration.identity()


class Calibration:
    """One :class:`SensorCalibration` per sensor id (the SPI device path).

    Sensors without an entry are treated as identity by :meth:`get` and
    :meth:`apply`. ``method``: how it was made (one of
    :data:`CALIBRATION_METHODS`, or "" for none/hand-made); ``date``: when
    (ISO 8601 text, "" = unknown). Serialises to YAML (version 2)::

        version: 2
        method: fit
        date: '2026-12-01T19:30:00+00:00'
        sensors:
          /dev/spidev1.0: {angle_offset_rad: 0.087, distance_m: 1.0, scale_x: 1.0,
                           scale_y: 1.0, x_m: 0.049, y_m: -0.0395, ...}

    Version-1 files (``version: 1``, ``sensors`` with one ``scale`` each)
    still load.
    """

    def __init__(
        self,
        sensors: Mapping[str, SensorCalibration] | None = None,
        method: str = "",
        date: str = "",
    ) -> None:
        if method not in ("", *CALIBRATION_METHODS):
            raise ValueError(
                f"calibration method must be one of {list(CALIBRATION_METHODS)} or empty, "
                f"got {method!r}"
            )
        if not isinstance(date, str):
            raise ValueError(f"calibration date must be text (ISO 8601), got {date!r}")
        self.method = method
        self.date = date
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
        return (
            isinstance(other, Calibration)
            and self._sensors == other._sensors
            and (self.method, self.date) == (other.method, other.date)
        )

    def __repr__(self) -> str:
        return f"Calibration({self._sensors!r}, method={self.method!r}, date={self.date!r})"

    @property
    def sensors(self) -> dict[str, SensorCalibration]:
        """A copy of the per-sensor calibrations."""
        return dict(self._sensors)

    @property
    def is_identity(self) -> bool:
        """True when applying it changes nothing (no sensor, or all identity)."""
        ident = SensorCalibration.identity()
        return all(c == ident for c in self._sensors.values())

    def get(self, sensor_id: str) -> SensorCalibration:
        """The sensor's calibration, identity if it has none."""
        return self._sensors.get(sensor_id) or _IDENTITY

    def apply(self, sensor_id: str, dx, dy):
        """Correct raw displacement(s) of ``sensor_id``; see :meth:`SensorCalibration.apply`."""
        return self.get(sensor_id).apply(dx, dy)

    def mounts(self, devices: Sequence[str], default_mounts: Sequence[SensorMount]):
        """The mounts the odometry uses with this calibration in force.

        One :class:`SensorMount` per device (``devices`` in mount order): the
        fitted position (x, y) where this calibration has one, else the
        default mount's; the yaw is the default mount's (the calibration's
        angle is applied to the samples, not to the mount).
        """
        devices, default_mounts = list(devices), tuple(default_mounts)
        if len(default_mounts) < len(devices):
            raise ValueError(
                f"{len(devices)} sensors need {len(devices)} mounts, got {len(default_mounts)}"
            )
        out = []
        for dev, m in zip(devices, default_mounts, strict=False):
            pos = self.get(dev).position
            out.append(m if pos is None else replace(m, x=pos[0], y=pos[1]))
        return tuple(out)

    def built_mounts(
        self, devices: Sequence[str], default_mounts: Sequence[SensorMount]
    ) -> tuple[SensorMount, ...]:
        """The sensors as this calibration says they are built (the map draws these).

        One :class:`SensorMount` per default mount: for the i-th of ``devices``
        the fitted position (as :meth:`mounts`) and the yaw turned by the
        calibration's angle offset (base_link, m and rad); mounts without a
        device yet stay as given.
        """
        devices, default_mounts = list(devices), tuple(default_mounts)
        out = []
        for i, m in enumerate(default_mounts):
            if i >= len(devices):
                out.append(m)
                continue
            c = self.get(devices[i])
            pos = c.position
            xy = (m.x, m.y) if pos is None else (pos[0], pos[1])
            out.append(replace(m, x=xy[0], y=xy[1], yaw=wrap_pi(m.yaw + c.angle_offset)))
        return tuple(out)

    @classmethod
    def identity(cls, sensor_ids: Iterable[str] = ()) -> Calibration:
        """Identity calibration for the given sensor ids (none: empty, all identity)."""
        return cls({sid: SensorCalibration.identity() for sid in sensor_ids})

    # --- YAML --------------------------------------------------------------------------

    def to_dict(self) -> dict:
        return {
            "version": YAML_VERSION,
            "method": self.method,
            "date": self.date,
            "sensors": {sid: cal.to_dict() for sid, cal in self._sensors.items()},
        }

    @classmethod
    def from_dict(cls, data) -> Calibration:
        if not isinstance(data, Mapping):
            raise ValueError(
                "calibration: expected a mapping with 'version' and 'sensors', "
                f"got {type(data).__name__}"
            )
        version = data.get("version")
        if "version" in data and (isinstance(version, bool) or version not in READABLE_VERSIONS):
            raise ValueError(
                f"calibration: unsupported version {version!r}, expected one of "
                f"{list(READABLE_VERSIONS)}"
            )
        required = {"version", "sensors"}
        allowed = required | ({"method", "date"} if version == 2 else set())
        keys = set(data)
        if keys - allowed:
            raise ValueError(
                f"calibration: unknown key(s) {sorted(map(str, keys - allowed))}; "
                f"allowed: {sorted(allowed)}"
            )
        if required - keys:
            raise ValueError(f"calibration: missing key(s) {sorted(required - keys)}")
        version_n: int = data["version"]  # one of READABLE_VERSIONS: checked above
        method = data.get("method") or ""
        date = data.get("date") or ""
        if not isinstance(date, str):
            date = str(date)  # YAML reads an unquoted ISO date as a datetime
        sensors = data["sensors"]
        if sensors is None:
            sensors = {}
        if not isinstance(sensors, Mapping):
            raise ValueError(
                f"calibration: 'sensors' must be a mapping of sensor id to calibration, "
                f"got {type(sensors).__name__}"
            )
        try:
            out = cls(method=method, date=date)
        except ValueError as e:
            raise ValueError(f"calibration: {e}") from None
        for sid, entry in sensors.items():
            if not isinstance(sid, str) or not sid:
                raise ValueError(f"calibration: sensor id must be a non-empty string, got {sid!r}")
            out[sid] = SensorCalibration.from_dict(
                entry, where=f"calibration of {sid}", version=version_n
            )
        return out

    def to_yaml(self) -> str:
        """YAML text; floats are written with full precision (round-trips exactly)."""
        return yaml.safe_dump(self.to_dict(), sort_keys=False)

    @classmethod
    def from_yaml(cls, text: str) -> Calibration:
        """Parse :meth:`to_yaml` output; ValueError with a message on any bad input."""
        try:
            data = parse_yaml(text)
        except ValueError as e:
            raise ValueError(f"calibration: {e}") from None
        return cls.from_dict(data)

    def save(self, path: str | Path) -> None:
        """Write the YAML to ``path`` (atomically: a temporary file, then rename)."""
        path = Path(path)
        tmp = path.with_name(path.name + ".tmp")
        tmp.write_text(self.to_yaml(), encoding="utf-8")
        tmp.replace(path)

    @classmethod
    def load(cls, path: str | Path) -> Calibration:
        """Read a file written by :meth:`save` (or a version-1 file).

        OSError if unreadable (also not a regular file, e.g. a FIFO that would block the
        start for ever, or larger than 1 MiB), ValueError if bad; both messages name the file.
        """
        path = Path(path)
        try:
            text = read_user_text(path)
        except UnicodeDecodeError as e:
            raise ValueError(f"calibration file {path}: not a text file ({e})") from None
        except OSError as e:
            raise OSError(f"calibration file {path}: {e.strerror or e}") from None
        try:
            return cls.from_yaml(text)
        except ValueError as e:
            raise ValueError(f"calibration file {path}: {e}") from None
