"""The driver library for every chip the robot polls (no ROS): one interface, one registry.

The package keeps the name of its first chip; each chip family lives in a subpackage
(:mod:`pln2033.pln2033`, :mod:`pln2033.pmw33xx`, :mod:`pln2033.pmw3901`, :mod:`pln2033.otos`),
each with a driver and a register-level emulator. The root holds what they share:
:mod:`pln2033.sensor` the interface every driver offers, :mod:`pln2033.chips` the registry
the poller picks drivers from, :mod:`pln2033.bus` and :mod:`pln2033.i2c` the buses,
:mod:`pln2033.emulated` the motion model every emulator shares, :mod:`pln2033.errors` the
errors (base :class:`SensorError`). Importing the package loads no chip's driver.
"""

from .bus import SpiBus, SpidevBus
from .errors import (
    DeviceNotFoundError,
    DevicePermissionError,
    FirmwareError,
    InvalidCpiError,
    PatchError,
    ProductIdError,
    RegisterMapError,
    SensorError,
    SensorNotRespondingError,
    SpiError,
)
from .sensor import INCH_M, QUALITY_NONE, ChipInfo, CpiRange, Motion, SensorDriver

__all__ = [
    "INCH_M",
    "QUALITY_NONE",
    "ChipInfo",
    "CpiRange",
    "DeviceNotFoundError",
    "DevicePermissionError",
    "FirmwareError",
    "InvalidCpiError",
    "Motion",
    "PatchError",
    "ProductIdError",
    "RegisterMapError",
    "SensorDriver",
    "SensorError",
    "SensorNotRespondingError",
    "SpiBus",
    "SpiError",
    "SpidevBus",
]
