"""The I2C bus the I2C sensor drivers (the SparkFun OTOS) talk through.

Anything with :class:`I2cBus`'s two methods is a bus: the real :class:`Smbus2Bus`
(Linux i2c-dev through the ``smbus2`` package's combined ``i2c_rdwr`` transfer, Debian
package python3-smbus2) or a register-level emulator. ``write_read`` is one combined
transaction: a write (the register pointer) and a read with a repeated start between,
as a register-pointer chip expects.
"""

from __future__ import annotations

import errno
import re
from typing import Any, Protocol, runtime_checkable

from .errors import (
    DeviceNotFoundError,
    DevicePermissionError,
    SensorError,
    SensorNotRespondingError,
)

_DEVICE_RE = re.compile(r"^/dev/i2c-(\d+)$")

OVERLAY_HINT = (
    "Enable the I2C bus: on a BeagleBone Black /dev/i2c-2 (P9_19 SCL, P9_20 SDA) is on by "
    "default, /dev/i2c-1 (P9_17/P9_18) needs an overlay (uboot_overlay_addr4=BB-I2C1-00A0.dtbo "
    "in /boot/uEnv.txt, reboot); on a Raspberry Pi run 'sudo raspi-config nonint do_i2c 0' "
    "or add dtparam=i2c_arm=on to /boot/firmware/config.txt; elsewhere 'sudo modprobe "
    "i2c-dev'. 'ls /dev/i2c-*' lists the buses. See docs/hardware-setup.md"
)
PERMISSION_HINT = (
    "Run as a member of the 'i2c' group (sudo usermod -aG i2c $USER, then log in again) or "
    'add a udev rule: SUBSYSTEM=="i2c-dev", GROUP="i2c", MODE="0660". '
    "See docs/hardware-setup.md"
)


class I2cError(SensorError):
    """An I2C transfer failed (the kernel returned an error)."""


class I2cDeviceNotFoundError(I2cError, DeviceNotFoundError):
    """The /dev/i2c-N file does not exist (also a DeviceNotFoundError, as for SPI)."""


class I2cPermissionError(I2cError, DevicePermissionError):
    """The /dev/i2c-N file exists but this user may not open it."""


class I2cNoAckError(I2cError, SensorNotRespondingError):
    """Nothing acknowledged the chip's address: no chip there, or it is not powered."""


@runtime_checkable
class I2cBus(Protocol):
    """One I2C adapter (several chips may share it, each by its 7-bit address)."""

    def write_read(self, addr: int, write: bytes, read_len: int) -> bytes:
        """Write ``write`` then read ``read_len`` bytes, one transaction (repeated start)."""
        ...

    def write(self, addr: int, data: bytes) -> None:
        """One write transaction (register pointer and the bytes to store)."""
        ...

    def close(self) -> None: ...


def parse_device(path: str) -> int:
    """``/dev/i2c-1`` -> adapter number 1."""
    m = _DEVICE_RE.match(path)
    if not m:
        raise ValueError(f"'{path}' is not an i2c-dev device path (expected /dev/i2c-N)")
    return int(m.group(1))


def _import_smbus2() -> Any:
    try:
        import smbus2
    except ImportError as exc:
        raise I2cError(
            "the 'smbus2' Python package is missing; install it with "
            "'sudo apt install python3-smbus2' or 'pip install smbus2' "
            "(pip install .[beagle] brings it)"
        ) from exc
    return smbus2


class Smbus2Bus:
    """The real bus: Linux i2c-dev through ``smbus2`` (``i2c_msg`` + ``i2c_rdwr``).

    ``path`` is the adapter's device file (``/dev/i2c-1``). The bus clock is the adapter's
    (set in the device tree, typically 100 or 400 kHz): i2c-dev cannot change it.
    ``smbus2`` may be injected (tests); by default the package is imported here, so a
    board without I2C sensors never needs it.

    Hot path: the messages of a ``write_read`` with the same (address, bytes, length)
    are built once and reused; i2c_rdwr refills the read buffer in place.
    """

    def __init__(self, path: str, smbus2: Any = None) -> None:
        self.path = path
        self._smbus2 = smbus2 if smbus2 is not None else _import_smbus2()
        try:
            self._bus = self._smbus2.SMBus(path)
        except FileNotFoundError as exc:
            raise I2cDeviceNotFoundError(f"{path} does not exist. {OVERLAY_HINT}") from exc
        except PermissionError as exc:
            raise I2cPermissionError(f"no permission to open {path}. {PERMISSION_HINT}") from exc
        except OSError as exc:
            if exc.errno == errno.ENOTTY:
                raise I2cError(
                    f"{path} is not an I2C adapter (the I2C_FUNCS ioctl failed): give a "
                    "/dev/i2c-N path. " + OVERLAY_HINT
                ) from exc
            raise I2cError(f"cannot open {path}: {exc.strerror or exc}") from exc
        self._messages: dict[tuple[int, bytes, int], tuple[Any, Any]] = {}

    def messages(self, addr: int, write: bytes, read_len: int) -> tuple[Any, Any]:
        """The (write, read) ``i2c_msg`` pair of a ``write_read``, built once per shape."""
        key = (addr, bytes(write), read_len)
        pair = self._messages.get(key)
        if pair is None:
            msg = self._smbus2.i2c_msg
            pair = (msg.write(addr, key[1]), msg.read(addr, read_len))
            self._messages[key] = pair
        return pair

    def write_read(self, addr: int, write: bytes, read_len: int) -> bytes:
        w, r = self.messages(addr, write, read_len)
        self._rdwr(addr, w, r)
        return bytes(r)

    def write(self, addr: int, data: bytes) -> None:
        self._rdwr(addr, self._smbus2.i2c_msg.write(addr, bytes(data)))

    def _rdwr(self, addr: int, *msgs: Any) -> None:
        try:
            self._bus.i2c_rdwr(*msgs)
        except OSError as exc:
            raise transfer_error(self.path, addr, exc) from exc

    def close(self) -> None:
        self._bus.close()


def transfer_error(path: str, addr: int, exc: OSError) -> I2cError:
    """The typed error (with what to do) for a failed transfer to ``addr`` on ``path``."""
    if exc.errno in (errno.ENXIO, errno.EREMOTEIO):
        bus = path.rsplit("-", 1)[-1]
        return I2cNoAckError(
            f"no chip acknowledges address {addr:#04x} on {path}: check the Qwiic cable "
            f"(SDA/SCL), the 3.3 V supply and the address; 'i2cdetect -y {bus}' lists the "
            "chips the bus sees"
        )
    if exc.errno == errno.ENODEV:
        return I2cDeviceNotFoundError(f"{path} disappeared. {OVERLAY_HINT}")
    if exc.errno in (errno.ETIMEDOUT, errno.EAGAIN):
        return I2cError(
            f"I2C transfer on {path} timed out (a chip holds SDA low or arbitration was "
            "lost): check pull-ups (one pair per bus) and cable length, then power-cycle"
        )
    return I2cError(f"I2C transfer on {path} failed: {exc.strerror or exc}")
