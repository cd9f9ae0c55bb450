"""The SPI bus the driver talks through.

Anything with spidev's ``xfer2(list[int]) -> list[int]`` is a bus: the real
:class:`SpidevBus` or the register-level emulator. ``xfer2`` keeps chip
select asserted for the whole list, as spidev does.
"""

from __future__ import annotations

import ctypes
import errno
import re
from collections.abc import Sequence
from pathlib import Path
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
    (3 MHz default, as the original). ``mode`` is the chip's SPI mode
    (:attr:`~pln2033.sensor.ChipInfo.spi_mode`: 3 for the PMW3360/PMW3389, which
    also want ``speed_hz`` <= 2 MHz).
    """

    def __init__(self, path: str, speed_hz: int = DEFAULT_SPEED_HZ, mode: int = SPI_MODE) -> None:
        bus, cs = parse_device(path)
        if mode not in (0, 1, 2, 3):
            raise ValueError(f"SPI mode {mode} does not exist (0..3)")
        if not MIN_SPEED_HZ <= speed_hz <= MAX_SPEED_HZ:
            raise ValueError(
                f"SPI speed {speed_hz} Hz is out of range ({MIN_SPEED_HZ}..{MAX_SPEED_HZ} Hz)"
            )
        try:
            import spidev
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
            self._dev.mode = mode
            self._dev.bits_per_word = SPI_BITS_PER_WORD
            self._dev.lsbfirst = False
            self._dev.max_speed_hz = speed_hz
        except OSError as exc:
            self._dev.close()
            raise SpiError(
                f"cannot configure {path} (mode {mode}, 8 bit): {exc.strerror or exc}"
            ) from exc

    def xfer2(self, data: list[int]) -> list[int]:
        try:
            return self._dev.xfer2(data)
        except OSError as exc:
            if exc.errno == errno.ENODEV:
                raise DeviceNotFoundError(f"{self.path} disappeared. {OVERLAY_HINT}") from exc
            raise SpiError(f"SPI transfer on {self.path} failed: {exc.strerror or exc}") from exc

    def xfer_segments(self, segments: Sequence[tuple[list[int], int]]) -> list[list[int]]:
        """Each (bytes, delay_us after them) under one chip select: ``SPI_IOC_MESSAGE(n)``.

        One ``spi_ioc_transfer`` per segment with its ``delay_usecs`` (the kernel waits that
        long after the segment's last bit, chip select still asserted). A frame longer than
        one ioctl can carry (:data:`MAX_SEGMENTS_PER_IOCTL` transfers, the spidev buffer size
        in bytes) goes out as several ioctls, each but the last ending with ``cs_change=1``,
        which asks the controller to keep chip select asserted until the next message (the
        kernel's "hint"; the syscall between them only lengthens that gap).
        """
        return spi_message(self._dev.fileno(), segments, self.path, _spidev_bufsiz())

    def close(self) -> None:
        self._dev.close()


# --- SPI_IOC_MESSAGE (linux/spi/spidev.h) ------------------------------------------------


class SpiIocTransfer(ctypes.Structure):
    """``struct spi_ioc_transfer`` of linux/spi/spidev.h: 32 bytes, no padding."""

    _fields_ = [
        ("tx_buf", ctypes.c_uint64),
        ("rx_buf", ctypes.c_uint64),
        ("len", ctypes.c_uint32),
        ("speed_hz", ctypes.c_uint32),
        ("delay_usecs", ctypes.c_uint16),
        ("bits_per_word", ctypes.c_uint8),
        ("cs_change", ctypes.c_uint8),
        ("tx_nbits", ctypes.c_uint8),
        ("rx_nbits", ctypes.c_uint8),
        ("word_delay_usecs", ctypes.c_uint8),
        ("pad", ctypes.c_uint8),
    ]


SPI_IOC_MAGIC = ord("k")
_IOC_WRITE = 1
_IOC_SIZEBITS = 14
MAX_SEGMENTS_PER_IOCTL = ((1 << _IOC_SIZEBITS) - 1) // ctypes.sizeof(SpiIocTransfer)  # 511
MAX_DELAY_US = 0xFFFF  # delay_usecs is a __u16
SPIDEV_BUFSIZ = 4096  # the spidev module's default 'bufsiz' (bytes per message)


def spi_ioc_message(n: int) -> int:
    """The ioctl request number ``SPI_IOC_MESSAGE(n)`` (asm-generic encoding: x86, ARM).

    ``_IOW(SPI_IOC_MAGIC, 0, char[n * 32])``: direction write (1) in bits 30-31, the
    size in bits 16-29, the magic 'k' in bits 8-15, number 0.
    """
    size = n * ctypes.sizeof(SpiIocTransfer)
    if n < 1 or size >= 1 << _IOC_SIZEBITS:
        raise ValueError(f"SPI_IOC_MESSAGE takes 1..{MAX_SEGMENTS_PER_IOCTL} transfers, got {n}")
    return (_IOC_WRITE << 30) | (size << 16) | (SPI_IOC_MAGIC << 8)


def _spidev_bufsiz() -> int:
    try:
        return int(Path("/sys/module/spidev/parameters/bufsiz").read_text())
    except (OSError, ValueError):
        return SPIDEV_BUFSIZ


def _chunks(segments: Sequence[tuple[list[int], int]], bufsiz: int) -> list[list[int]]:
    """Indices of the segments of each ioctl: <= 511 transfers and <= bufsiz bytes each."""
    out: list[list[int]] = [[]]
    size = 0
    for i, (data, _delay) in enumerate(segments):
        n = len(data)
        if n > bufsiz:
            raise ValueError(f"one SPI segment of {n} bytes exceeds spidev's bufsiz ({bufsiz})")
        if len(out[-1]) == MAX_SEGMENTS_PER_IOCTL or size + n > bufsiz:
            out.append([])
            size = 0
        out[-1].append(i)
        size += n
    return out


def spi_message(
    fd: int,
    segments: Sequence[tuple[list[int], int]],
    path: str = "spidev",
    bufsiz: int = SPIDEV_BUFSIZ,
) -> list[list[int]]:
    """Run ``segments`` on the spidev file descriptor ``fd`` (see SpidevBus.xfer_segments)."""
    import fcntl

    for data, delay in segments:
        if not 0 <= delay <= MAX_DELAY_US:
            raise ValueError(f"SPI segment delay {delay} us is out of range (0..{MAX_DELAY_US})")
        if any(not 0 <= b <= 0xFF for b in data):
            raise ValueError("SPI bytes must be 0..255")
    rx_out: list[list[int]] = [[] for _ in segments]
    chunks = _chunks(segments, bufsiz) if segments else []
    for c, idx in enumerate(chunks):
        xfers = (SpiIocTransfer * len(idx))()
        bufs = []
        for k, i in enumerate(idx):
            data, delay = segments[i]
            tx = (ctypes.c_uint8 * max(len(data), 1))(*data)
            rx = (ctypes.c_uint8 * max(len(data), 1))()
            bufs.append((tx, rx))
            t = xfers[k]
            t.tx_buf = ctypes.addressof(tx)
            t.rx_buf = ctypes.addressof(rx)
            t.len = len(data)
            t.delay_usecs = delay
        if c < len(chunks) - 1:
            xfers[len(idx) - 1].cs_change = 1  # keep chip select asserted into the next ioctl
        try:
            fcntl.ioctl(fd, spi_ioc_message(len(idx)), xfers)
        except OSError as exc:
            if exc.errno == errno.ENODEV:
                raise DeviceNotFoundError(f"{path} disappeared. {OVERLAY_HINT}") from exc
            raise SpiError(f"SPI transfer on {path} failed: {exc.strerror or exc}") from exc
        for k, i in enumerate(idx):
            rx_out[i] = list(bufs[k][1])[: len(segments[i][0])]
    return rx_out
