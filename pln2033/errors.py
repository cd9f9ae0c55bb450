"""Typed errors of the sensor drivers (every chip), each with a message that says what to do.

:class:`SensorError` is the base of every error the drivers raise; the chip-specific ones
(:class:`PatchError`, :class:`RegisterMapError` of the PLN2033, the OTOS's and PMW3901's
setting errors) derive from it, so a caller catches one class for every chip.
"""

from __future__ import annotations


class SensorError(Exception):
    """Base class of every error this package raises."""


class SpiError(SensorError):
    """An SPI transfer failed (the kernel returned an error)."""


class DeviceNotFoundError(SpiError):
    """The spidev device file does not exist."""


class DevicePermissionError(SpiError):
    """The spidev device file exists but this user may not open it."""


class SensorNotRespondingError(SensorError):
    """The transfer worked but no sensor answered sensibly."""


class ProductIdError(SensorNotRespondingError):
    """A chip answered with another product id than the driver expects."""


class InvalidCpiError(SensorError, ValueError):
    """A resolution outside what the sensor's encoding supports."""


class FirmwareError(SensorError):
    """Firmware (patch code, SROM) failed to read, upload or verify, or the chip takes none."""


class PatchError(FirmwareError):
    """The PLN2033's vendor patch code could not be read, loaded or verified."""


class RegisterMapError(SensorError, ValueError):
    """A register map (YAML override) is malformed."""
