"""The SPI bus: the real spidev backend's checks and error messages.

No SPI hardware here: a path that does not exist exercises the real
``spidev`` package; the kernel's other answers (permission, failed ioctl,
vanished device) are injected by replacing ``spidev.SpiDev`` with a small
stand-in, since only the translation into typed errors is under test.
"""

from __future__ import annotations

import errno
import sys
from typing import ClassVar

import pytest
import spidev

from pln2033 import (
    DeviceNotFoundError,
    DevicePermissionError,
    SensorNotRespondingError,
    SpiBus,
    SpidevBus,
    SpiError,
)
from pln2033.bus import DEFAULT_SPEED_HZ, parse_device
from pln2033.pln2033 import PLN2033, EmulatedPLN2033


def test_spidev_is_installed():
    assert hasattr(spidev, "SpiDev")


# --- device paths and speeds ---------------------------------------------------------------


@pytest.mark.parametrize(
    ("path", "expected"),
    [("/dev/spidev1.0", (1, 0)), ("/dev/spidev1.1", (1, 1)), ("/dev/spidev12.3", (12, 3))],
)
def test_parse_device(path, expected):
    assert parse_device(path) == expected


@pytest.mark.parametrize(
    "path",
    ["/dev/spidev1", "spidev1.0", "/dev/ttyS0", "/dev/spidev1.0x", "/dev/spidev.1", "", "1.0"],
)
def test_malformed_device_path_is_a_value_error(path):
    with pytest.raises(ValueError) as info:
        SpidevBus(path)
    assert str(info.value) == (f"'{path}' is not a spidev device path (expected /dev/spidevB.C)")


def test_nonexistent_device_explains_the_overlay_and_hdmi():
    with pytest.raises(DeviceNotFoundError) as info:
        SpidevBus("/dev/spidev9.9")
    message = str(info.value)
    assert message.startswith("/dev/spidev9.9 does not exist.")
    assert "device-tree overlay" in message
    assert "HDMI" in message
    assert "SPI1" in message
    assert isinstance(info.value, SpiError)


@pytest.mark.parametrize("speed", [0, 99_999, 8_000_001, 50_000_000, -1])
def test_speed_out_of_range_is_a_value_error(speed):
    # Checked before the device is touched: a missing device does not mask it.
    with pytest.raises(ValueError) as info:
        SpidevBus("/dev/spidev9.9", speed_hz=speed)
    assert str(info.value) == (f"SPI speed {speed} Hz is out of range (100000..8000000 Hz)")


@pytest.mark.parametrize("speed", [100_000, 8_000_000])
def test_speed_limits_are_allowed(speed):
    # In range, so the next problem is the missing device.
    with pytest.raises(DeviceNotFoundError):
        SpidevBus("/dev/spidev9.9", speed_hz=speed)


# --- the kernel's answers, through a stand-in spidev.SpiDev -----------------------------------


class FakeSpiDev:
    """Stands in for spidev.SpiDev; each instance records what was set."""

    open_error: OSError | None = None
    config_error: OSError | None = None
    xfer_error: OSError | None = None
    instances: ClassVar[list[FakeSpiDev]] = []

    def __init__(self) -> None:
        self.opened = None
        self.closed = False
        self.settings: dict[str, object] = {}
        type(self).instances.append(self)

    def open(self, bus, cs):
        if self.open_error is not None:
            raise self.open_error
        self.opened = (bus, cs)

    def __setattr__(self, name, value):
        if name in ("mode", "bits_per_word", "lsbfirst", "max_speed_hz"):
            if self.config_error is not None:
                raise self.config_error
            self.settings[name] = value
        object.__setattr__(self, name, value)

    def xfer2(self, data):
        if self.xfer_error is not None:
            raise self.xfer_error
        return [0xA5] * len(data)

    def close(self):
        self.closed = True


@pytest.fixture
def fake_spidev(monkeypatch):
    class Fake(FakeSpiDev):
        instances: ClassVar[list[FakeSpiDev]] = []  # a fresh list per test

    monkeypatch.setattr(spidev, "SpiDev", Fake)
    return Fake


def test_open_configures_mode_1_8_bit_msb_first(fake_spidev):
    bus = SpidevBus("/dev/spidev1.1")
    dev = fake_spidev.instances[0]
    assert dev.opened == (1, 1)
    assert dev.settings == {
        "mode": 1,
        "bits_per_word": 8,
        "lsbfirst": False,
        "max_speed_hz": DEFAULT_SPEED_HZ,
    }
    assert DEFAULT_SPEED_HZ == 3_000_000
    assert bus.xfer2([1, 2, 3]) == [0xA5, 0xA5, 0xA5]
    bus.close()
    assert dev.closed


def test_permission_denied_explains_the_spi_group(fake_spidev):
    fake_spidev.open_error = PermissionError(errno.EACCES, "Permission denied")
    with pytest.raises(DevicePermissionError) as info:
        SpidevBus("/dev/spidev1.0")
    message = str(info.value)
    assert message.startswith("no permission to open /dev/spidev1.0.")
    assert "'spi' group" in message
    assert "udev rule" in message


def test_other_open_error_is_an_spi_error(fake_spidev):
    fake_spidev.open_error = OSError(errno.EBUSY, "Device or resource busy")
    with pytest.raises(SpiError) as info:
        SpidevBus("/dev/spidev1.0")
    assert type(info.value) is SpiError
    assert str(info.value) == "cannot open /dev/spidev1.0: Device or resource busy"


def test_configure_error_closes_the_device(fake_spidev):
    fake_spidev.config_error = OSError(errno.EINVAL, "Invalid argument")
    with pytest.raises(SpiError) as info:
        SpidevBus("/dev/spidev1.0")
    assert str(info.value) == "cannot configure /dev/spidev1.0 (mode 1, 8 bit): Invalid argument"
    assert fake_spidev.instances[0].closed


def test_device_vanishing_mid_run_is_device_not_found(fake_spidev):
    bus = SpidevBus("/dev/spidev1.0")
    fake_spidev.xfer_error = OSError(errno.ENODEV, "No such device")
    with pytest.raises(DeviceNotFoundError) as info:
        bus.xfer2([0, 0, 0])
    message = str(info.value)
    assert message.startswith("/dev/spidev1.0 disappeared.")
    assert "device-tree overlay" in message


def test_failed_transfer_is_an_spi_error(fake_spidev):
    bus = SpidevBus("/dev/spidev1.0")
    fake_spidev.xfer_error = OSError(errno.EREMOTEIO, "Remote I/O error")
    with pytest.raises(SpiError) as info:
        bus.xfer2([0, 0, 0])
    assert type(info.value) is SpiError
    assert str(info.value) == "SPI transfer on /dev/spidev1.0 failed: Remote I/O error"


def test_missing_spidev_package(monkeypatch):
    monkeypatch.setitem(sys.modules, "spidev", None)  # import spidev -> ImportError
    with pytest.raises(SpiError) as info:
        SpidevBus("/dev/spidev1.0")
    assert "pip install spidev" in str(info.value)


# --- the bus protocol --------------------------------------------------------------------------


def test_emulator_and_spidev_bus_satisfy_the_protocol(fake_spidev):
    assert isinstance(EmulatedPLN2033(), SpiBus)
    assert isinstance(SpidevBus("/dev/spidev1.0"), SpiBus)
    assert not isinstance(object(), SpiBus)


def test_driver_on_a_spidev_bus_with_no_sensor(fake_spidev):
    """Every byte reads 0xA5: the driver sees reserved status bits set."""
    drv = PLN2033(SpidevBus("/dev/spidev1.0"), name="/dev/spidev1.0")
    with pytest.raises(SensorNotRespondingError) as info:
        drv.read_motion()
    assert "status register reads 0xa5a5" in str(info.value)
