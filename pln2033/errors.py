"""Typed errors of the PLN2033 driver, each with a message that says what to do."""

from __future__ import annotations


class Pln2033Error(Exception):
    """Base class of every error this package raises."""


class SpiError(Pln2033Error):
    """An SPI transfer failed (the kernel returned an error)."""


class DeviceNotFoundError(SpiError):
    """The spidev device file does not exist."""


class DevicePermissionError(SpiError):
    """The spidev device file exists but this user may not open it."""


class SensorNotRespondingError(Pln2033Error):
    """The SPI transfer worked but no PLN2033 answered sensibly."""


class InvalidCpiError(Pln2033Error, ValueError):
    """A resolution outside what the sensor's encoding supports."""


class PatchError(Pln2033Error):
    """The vendor patch code could not be read, loaded or verified."""


class RegisterMapError(Pln2033Error, ValueError):
    """A register map (YAML override) is malformed."""
