"""The sensor drivers (no ROS): the PLN2033 here, other chips in subpackages, one interface.

:mod:`pln2033.sensor` is the interface every driver offers, :mod:`pln2033.chips` the
registry the poller picks drivers from, :mod:`pln2033.emulated` the motion model every
register-level emulator shares.
"""

from .bus import SpiBus, SpidevBus
from .driver import INCH_M, PLN2033, Motion, read_patch_file
from .emulator import EmulatedPLN2033
from .errors import (
    DeviceNotFoundError,
    DevicePermissionError,
    FirmwareError,
    InvalidCpiError,
    PatchError,
    Pln2033Error,
    ProductIdError,
    RegisterMapError,
    SensorError,
    SensorNotRespondingError,
    SpiError,
)
from .regmap import REGISTER_NAMES, RegisterMap
from .sensor import QUALITY_NONE, ChipInfo, CpiRange, SensorDriver

__all__ = [
    "INCH_M",
    "PLN2033",
    "QUALITY_NONE",
    "REGISTER_NAMES",
    "ChipInfo",
    "CpiRange",
    "DeviceNotFoundError",
    "DevicePermissionError",
    "EmulatedPLN2033",
    "FirmwareError",
    "InvalidCpiError",
    "Motion",
    "PatchError",
    "Pln2033Error",
    "ProductIdError",
    "RegisterMap",
    "RegisterMapError",
    "SensorDriver",
    "SensorError",
    "SensorNotRespondingError",
    "SpiBus",
    "SpiError",
    "SpidevBus",
    "read_patch_file",
]
