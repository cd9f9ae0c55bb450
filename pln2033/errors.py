"""Typed errors of the sensor drivers (every chip), each with a message that says what to do.

The names keep the PLN2033's prefix for the base class (the first driver); ``SensorError``
is the same class under a name that fits every chip.
"""

from __future__ import annotations


class Pln2033Error(Exception):
    """Base class of every error this package raises."""


class SpiError(Pln2033Error):
    """An SPI transfer failed (the kernel returned an error)."""


class DeviceNotFoundError(SpiError):
    """The spidev device file does not exist."""


class DevicePermissionError(SpiError):
    """The spidev device file exists but this user may not open it."""


SensorError = Pln2033Error


class SensorNotRespondingError(Pln2033Error):
    """The transfer worked but no sensor answered sensibly."""


class ProductIdError(SensorNotRespondingError):
    """A chip answered with another product id than the driver expects."""


class InvalidCpiError(Pln2033Error, ValueError):
    """A resolution outside what the sensor's encoding supports."""


class FirmwareError(Pln2033Error):
    """Firmware (patch code, SROM) failed to read, upload or verify, or the chip takes none."""


class PatchError(FirmwareError):
    """The PLN2033's vendor patch code could not be read, loaded or verified."""


class RegisterMapError(Pln2033Error, ValueError):
    """A register map (YAML override) is malformed."""
