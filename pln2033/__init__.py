"""PLN2033 laser mouse sensor driver (no ROS): bus, register map, driver, emulator."""

from .bus import SpiBus, SpidevBus
from .driver import INCH_M, PLN2033, Motion, read_patch_file
from .emulator import EmulatedPLN2033
from .errors import (
    DeviceNotFoundError,
    DevicePermissionError,
    InvalidCpiError,
    PatchError,
    Pln2033Error,
    RegisterMapError,
    SensorNotRespondingError,
    SpiError,
)
from .regmap import REGISTER_NAMES, RegisterMap

__all__ = [
    "INCH_M",
    "PLN2033",
    "REGISTER_NAMES",
    "DeviceNotFoundError",
    "DevicePermissionError",
    "EmulatedPLN2033",
    "InvalidCpiError",
    "Motion",
    "PatchError",
    "Pln2033Error",
    "RegisterMap",
    "RegisterMapError",
    "SensorNotRespondingError",
    "SpiBus",
    "SpiError",
    "SpidevBus",
    "read_patch_file",
]
