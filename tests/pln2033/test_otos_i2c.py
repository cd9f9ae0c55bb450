"""The I2C bus (pln2033.i2c): smbus2 message building and the errors that say what to do."""

from __future__ import annotations

import errno
import types

import pytest

from pln2033.errors import DeviceNotFoundError, DevicePermissionError, SensorNotRespondingError
from pln2033.i2c import (
    I2cBus,
    I2cDeviceNotFoundError,
    I2cError,
    I2cNoAckError,
    I2cPermissionError,
    Smbus2Bus,
    parse_device,
)
from pln2033.otos import OTOS, EmulatedOTOS


class FakeMsg:
    def __init__(self, addr: int, read: bool, data: bytes) -> None:
        self.addr, self.read, self.buf = addr, read, bytearray(data)

    def __bytes__(self) -> bytes:
        return bytes(self.buf)


def fake_smbus2(open_error: OSError | None = None, rdwr_error: OSError | None = None):
    """A stand-in for the smbus2 module: records i2c_rdwr calls, answers 0xA0, 0xA1, ..."""
    calls: list[list[FakeMsg]] = []

    class SMBus:
        def __init__(self, path: str) -> None:
            if open_error is not None:
                raise open_error
            self.path = path

        def i2c_rdwr(self, *msgs: FakeMsg) -> None:
            if rdwr_error is not None:
                raise rdwr_error
            calls.append(list(msgs))
            for m in msgs:
                if m.read:
                    m.buf[:] = bytes(0xA0 + i for i in range(len(m.buf)))

        def close(self) -> None:
            pass

    msg = types.SimpleNamespace(
        write=lambda addr, buf: FakeMsg(addr, False, bytes(buf)),
        read=lambda addr, n: FakeMsg(addr, True, bytes(n)),
    )
    return types.SimpleNamespace(SMBus=SMBus, i2c_msg=msg), calls


def test_write_read_is_one_combined_transfer_and_its_messages_are_built_once():
    mod, calls = fake_smbus2()
    bus = Smbus2Bus("/dev/i2c-2", smbus2=mod)
    assert isinstance(bus, I2cBus)
    assert bus.write_read(0x17, b"\x1f", 3) == b"\xa0\xa1\xa2"
    ((w, r),) = calls
    assert (w.addr, w.read, bytes(w)) == (0x17, False, b"\x1f")
    assert (r.addr, r.read, len(r.buf)) == (0x17, True, 3)
    bus.write_read(0x17, b"\x1f", 3)
    assert calls[1][0] is w and calls[1][1] is r  # the hot path reuses them
    bus.write(0x17, b"\x04\x01\x02")
    assert [(m.read, bytes(m)) for m in calls[2]] == [(False, b"\x04\x01\x02")]


def test_a_missing_device_file_says_to_enable_the_bus(tmp_path):
    missing = str(tmp_path / "i2c-7")
    mod, _ = fake_smbus2(open_error=FileNotFoundError(errno.ENOENT, "No such file", missing))
    with pytest.raises(I2cDeviceNotFoundError) as e:
        Smbus2Bus(missing, smbus2=mod)
    assert missing in str(e.value) and "overlay" in str(e.value) and "i2c-dev" in str(e.value)
    assert isinstance(e.value, DeviceNotFoundError)  # the node's existing handler catches it


def test_the_real_open_of_a_missing_path_fails_with_the_hint(tmp_path):
    smbus2 = pytest.importorskip("smbus2")
    with pytest.raises(I2cDeviceNotFoundError, match="Enable the I2C bus"):
        Smbus2Bus(str(tmp_path / "i2c-9"), smbus2=smbus2)
    plain = tmp_path / "i2c-8"
    plain.write_bytes(b"")
    with pytest.raises(I2cError, match="not an I2C adapter"):
        Smbus2Bus(str(plain), smbus2=smbus2)


def test_real_smbus2_messages_carry_the_bytes():
    smbus2 = pytest.importorskip("smbus2")
    bus = Smbus2Bus.__new__(Smbus2Bus)
    bus._smbus2, bus._messages, bus.path = smbus2, {}, "/dev/i2c-1"
    w, r = bus.messages(0x17, b"\x1f", 13)
    assert (w.addr, w.flags, bytes(w)) == (0x17, 0, b"\x1f")
    assert (r.addr, r.flags & smbus2.smbus2.I2C_M_RD, len(r)) == (0x17, 1, 13)


def test_no_permission_says_i2c_group(tmp_path):
    path = str(tmp_path / "i2c-1")
    mod, _ = fake_smbus2(open_error=PermissionError(errno.EACCES, "Permission denied", path))
    with pytest.raises(I2cPermissionError) as e:
        Smbus2Bus(path, smbus2=mod)
    assert "'i2c' group" in str(e.value) and "udev" in str(e.value)
    assert isinstance(e.value, DevicePermissionError)


def test_no_ack_names_the_address_and_i2cdetect():
    mod, _ = fake_smbus2(rdwr_error=OSError(errno.EREMOTEIO, "Remote I/O error"))
    bus = Smbus2Bus("/dev/i2c-2", smbus2=mod)
    with pytest.raises(I2cNoAckError) as e:
        bus.write_read(0x17, b"\x00", 1)
    assert "0x17" in str(e.value) and "i2cdetect -y 2" in str(e.value)
    assert isinstance(e.value, SensorNotRespondingError)
    mod, _ = fake_smbus2(rdwr_error=OSError(errno.ETIMEDOUT, "Timed out"))
    with pytest.raises(I2cError, match="pull-ups"):
        Smbus2Bus("/dev/i2c-2", smbus2=mod).write(0x17, b"\x07\x01")


def test_missing_smbus2_package_says_how_to_install(monkeypatch):
    import builtins

    real = builtins.__import__

    def no_smbus2(name, *a, **k):
        if name == "smbus2":
            raise ImportError("No module named 'smbus2'")
        return real(name, *a, **k)

    monkeypatch.setattr(builtins, "__import__", no_smbus2)
    with pytest.raises(I2cError, match="python3-smbus2"):
        Smbus2Bus("/dev/i2c-1")


def test_parse_device():
    assert parse_device("/dev/i2c-2") == 2
    with pytest.raises(ValueError, match="/dev/i2c-N"):
        parse_device("/dev/spidev1.0")


def test_emulator_faults_come_as_the_bus_errors():
    t = [0.5]
    emu = EmulatedOTOS(clock=lambda: t[0], fault_windows=[(1.0, 2.0, "no_response")])
    drv = OTOS(emu, imu_samples=0)
    assert drv.read_register(0) == 0x5F
    t[0] = 1.5
    with pytest.raises(I2cNoAckError):
        drv.read_register(0)
    t[0] = 2.5
    assert drv.read_register(0) == 0x5F and emu.stats.resets == 1  # power cycled
