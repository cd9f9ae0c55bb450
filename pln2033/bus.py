"""The SPI bus the driver talks through.

Anything with spidev's ``xfer2(list[int]) -> list[int]`` is a bus: the real
:class:`SpidevBus` or the register-level emulator. ``xfer2`` keeps chip
select asserted for the whole list, as spidev does.
"""

from __future__ import annotations

import errno
import re
from collections.abc import Sequence
from typing import Protocol, runtime_checkable

from .errors import DeviceNotFoundError, DevicePermissionError, SpiError

#: SPI mode 1 (CPOL=0, CPHA=1), 8 bits per word, MSB first, as the original.
SPI_MODE = 1
SPI_BITS_PER_WORD = 8
DEFAULT_SPEED_HZ = 3_000_000
MAX_SPEED_HZ = 8_000_000
MIN_SPEED_HZ = 100_000

_DEVICE_RE = re.compile(r"^/dev/spidev(\d+)\.(\d+)$")

OVERLAY_HINT = (
    "On a BeagleBone Black enable SPI1 through a device-tree overlay "
    "(uboot_overlay_addr4=BB-SPIDEV1-00A0.dtbo in /boot/uEnv.txt) and turn HDMI off, "
    "whose audio pins are SPI1's (disable_uboot_overlay_audio=1, "
    "disable_uboot_overlay_video=1); reboot; then, after each boot, make P9_42 the "
    "second chip select (config-pin P9_42 spi_cs). See docs/hardware-setup.md"
)
PERMISSION_HINT = (
    "Run as a member of the 'spi' group (sudo usermod -aG spi $USER, then log in "
    'again) or add a udev rule: SUBSYSTEM=="spidev", GROUP="spi", MODE="0660". '
    "See docs/hardware-setup.md"
)


@runtime_checkable
class SpiBus(Protocol):
    """One SPI device (one chip select)."""

    def xfer2(self, data: list[int]) -> list[int]:
        """Send ``data`` (bytes 0..255) and return the bytes clocked in meanwhile."""
        ...

    def close(self) -> None: ...


@runtime_checkable
class SegmentedSpiBus(SpiBus, Protocol):
    """A bus that can pause inside one chip-select frame (PMW3360: tSRAD after an address byte).

    On Linux one ``SPI_IOC_MESSAGE(n)`` ioctl, one ``spi_ioc_transfer`` per segment with its
    ``delay_usecs``; emulators check the delays.
    """

    def xfer_segments(self, segments: Sequence[tuple[list[int], int]]) -> list[list[int]]:
        """Send each (bytes, delay_us after them) under one chip select; the bytes clocked in
        per segment."""
        ...


def parse_device(path: str) -> tuple[int, int]:
    """``/dev/spidev1.0`` -> (bus 1, chip select 0)."""
    m = _DEVICE_RE.match(path)
    if not m:
        raise ValueError(f"'{path}' is not a spidev device path (expected /dev/spidevB.C)")
    return int(m.group(1)), int(m.group(2))


class SpidevBus:
    """The real bus: Linux spidev through the ``spidev`` package.

    Mode 1, 8 bits per word, MSB first; ``speed_hz`` 100 kHz..8 MHz
    (3 MHz default, as the original).
    """

    def __init__(self, path: str, speed_hz: int = DEFAULT_SPEED_HZ) -> None:
        bus, cs = parse_device(path)
        if not MIN_SPEED_HZ <= speed_hz <= MAX_SPEED_HZ:
            raise ValueError(
                f"SPI speed {speed_hz} Hz is out of range ({MIN_SPEED_HZ}..{MAX_SPEED_HZ} Hz)"
            )
        try:
            import spidev  # type: ignore[import-not-found]
        except ImportError as exc:
            raise SpiError(
                "the 'spidev' Python package is missing; install it with "
                "'./compile mm_b' or 'pip install spidev'"
            ) from exc
        self.path = path
        self._dev = spidev.SpiDev()
        try:
            self._dev.open(bus, cs)
        except FileNotFoundError as exc:
            raise DeviceNotFoundError(f"{path} does not exist. {OVERLAY_HINT}") from exc
        except PermissionError as exc:
            raise DevicePermissionError(f"no permission to open {path}. {PERMISSION_HINT}") from exc
        except OSError as exc:
            raise SpiError(f"cannot open {path}: {exc.strerror or exc}") from exc
        try:
            self._dev.mode = SPI_MODE
            self._dev.bits_per_word = SPI_BITS_PER_WORD
            self._dev.lsbfirst = False
            self._dev.max_speed_hz = speed_hz
        except OSError as exc:
            self._dev.close()
            raise SpiError(
                f"cannot configure {path} (mode 1, 8 bit): {exc.strerror or exc}"
            ) from exc

    def xfer2(self, data: list[int]) -> list[int]:
        try:
            return self._dev.xfer2(data)
        except OSError as exc:
            if exc.errno == errno.ENODEV:
                raise DeviceNotFoundError(f"{self.path} disappeared. {OVERLAY_HINT}") from exc
            raise SpiError(f"SPI transfer on {self.path} failed: {exc.strerror or exc}") from exc

    def close(self) -> None:
        self._dev.close()
