"""SparkFun's own OTOS client against our emulator: the vendor's reading of the chip vs ours.

The unmodified ``sparkfun-qwiic-otos`` (qwiic_otos.QwiicOTOS) with ``sparkfun-qwiic-i2c``
(qwiic_i2c.LinuxI2C) and ``smbus2``; only the kernel is faked: ``open("/dev/i2c-1")`` and
the i2c-dev ioctls (I2C_FUNCS, I2C_SLAVE, I2C_SMBUS as the kernel's SMBus-over-I2C
emulation turns them into messages, I2C_RDWR) reach :class:`EmulatedOTOS` as bus bytes, and
every transaction moves the emulator's clock by its time on a 100 kHz bus; ``time.sleep``
moves the same clock. The truth is the motion the test drives (and the emulator's filters
for what only they define: the standard deviations).
"""

from __future__ import annotations

import ctypes
import math
import os
import time
import types

import pytest
import qwiic_i2c  # the test extra (pyproject.toml) installs them: a missing one is an error
import qwiic_otos
import smbus2.smbus2 as smbus2_mod
from fakes import FakeClock

from pln2033.otos import ConstantYawRate, EmulatedOTOS, regs

BUS_HZ = 100_000
M = 0  # kLinearUnitMeters
RAD = 0  # kAngularUnitRadians


class I2cDevKernel:
    """The kernel side of /dev/i2c-1: the i2c-dev ioctls, turned into the bus bytes a chip sees.

    SMBus calls are split into messages as the kernel does for a plain I2C adapter
    (i2c_smbus_xfer_emulated): read_byte_data = write [reg] + repeated start + read 1, etc.
    """

    def __init__(self, emu: EmulatedOTOS, clock: FakeClock, hz: int = BUS_HZ) -> None:
        self.emu, self.clock, self.hz = emu, clock, hz
        self.addr = 0
        self.transactions: list[tuple[float, bytes, bytes]] = []  # (start time, written, read)

    def open(self, path: str, flags: int) -> int:
        if path != "/dev/i2c-1":
            raise FileNotFoundError(2, "No such file or directory", path)
        return os.open(os.devnull, os.O_RDWR)

    def _xfer(self, write: bytes, read_len: int | None) -> bytes:
        """One transaction: the emulator serves it at its start, the bus time then passes."""
        t = self.clock.t
        if read_len is None:
            self.emu.write(self.addr, write)
            out = b""
            nbytes = 1 + len(write)
        else:
            out = self.emu.write_read(self.addr, write, read_len)
            nbytes = (1 + len(write) if write else 0) + 1 + read_len
        self.clock.t += (nbytes * 9 + 2) / self.hz  # 9 bits a byte, start and stop
        self.transactions.append((t, bytes(write), out))
        return out

    def ioctl(self, fd: int, request: int, arg: object) -> int:
        s = smbus2_mod
        if request == s.I2C_FUNCS:
            # a plain I2C adapter: the kernel emulates every SMBus call with I2C messages
            arg.value = 0x0EFF0001  # type: ignore[attr-defined]  # I2C_FUNC_I2C | SMBUS_EMUL
        elif request in (s.I2C_SLAVE, s.I2C_SLAVE_FORCE):
            self.addr = int(arg)  # type: ignore[call-overload]
        elif request == s.I2C_SMBUS:
            self._smbus(arg)
        elif request == s.I2C_RDWR:
            msgs = [arg.msgs[i] for i in range(arg.nmsgs)]  # type: ignore[attr-defined]
            write = b"".join(ctypes.string_at(m.buf, m.len) for m in msgs if not m.flags & 1)
            reads = [m for m in msgs if m.flags & 1]
            out = self._xfer(write, sum(m.len for m in reads) if reads else None)
            for m in reads:
                ctypes.memmove(m.buf, out[: m.len], m.len)
                out = out[m.len :]
        else:
            raise OSError(25, "Inappropriate ioctl for device")
        return 0

    def _smbus(self, msg) -> None:
        s, data = smbus2_mod, msg.data.contents
        read = msg.read_write == s.I2C_SMBUS_READ
        cmd = bytes([msg.command])
        if msg.size == s.I2C_SMBUS_QUICK:
            self._xfer(b"", None)
        elif msg.size == s.I2C_SMBUS_BYTE:
            if read:
                data.byte = self._xfer(b"", 1)[0]
            else:
                self._xfer(cmd, None)
        elif msg.size == s.I2C_SMBUS_BYTE_DATA:
            if read:
                data.byte = self._xfer(cmd, 1)[0]
            else:
                self._xfer(cmd + bytes([data.byte]), None)
        elif msg.size == s.I2C_SMBUS_I2C_BLOCK_DATA:
            n = data.block[0]
            if read:
                out = self._xfer(cmd, n)
                data.block[1 : n + 1] = list(out)
            else:
                self._xfer(cmd + bytes(data.block[1 : n + 1]), None)
        else:
            raise OSError(95, "Operation not supported (this fake)")


class Ramp:
    """Sensor-frame motion along +y: from rest at ``t0`` at ``a`` m/s^2 up to ``v`` m/s."""

    def __init__(self, t0: float, a: float, v: float) -> None:
        self.t0, self.a, self.v = t0, a, v
        self.t_acc = v / a

    def y(self, t: float) -> float:
        dt = t - self.t0
        if dt <= 0:
            return 0.0
        if dt <= self.t_acc:
            return 0.5 * self.a * dt * dt
        return 0.5 * self.a * self.t_acc**2 + self.v * (dt - self.t_acc)

    def speed(self, t: float) -> float:
        return min(self.v, max(0.0, self.a * (t - self.t0)))

    def displacement(self, t0: float, t1: float) -> tuple[float, float]:
        return 0.0, self.y(t1) - self.y(t0)


@pytest.fixture
def bench(monkeypatch):
    """(clock, emulator, kernel, make) -- make(**emulator options) builds them afresh."""
    made = {}

    def make(**options):
        ft = FakeClock()
        options.setdefault("gyro_noise_rps", 0.0)
        emu = EmulatedOTOS(clock=ft, **options)
        kernel = I2cDevKernel(emu, ft)
        fake_os = types.SimpleNamespace(open=kernel.open, close=os.close, O_RDWR=os.O_RDWR)
        monkeypatch.setattr(smbus2_mod, "os", fake_os)
        monkeypatch.setattr(smbus2_mod, "ioctl", kernel.ioctl)
        monkeypatch.setattr(time, "sleep", ft.sleep)  # the library's waits move the clock
        otos = qwiic_otos.QwiicOTOS(i2c_driver=qwiic_i2c.getI2CDriver(iBus=1))
        made.update(ft=ft, emu=emu, kernel=kernel, otos=otos)
        return ft, emu, kernel, otos

    return make


T0 = 2.0  # the motion starts here (s), after the bring-up below


def started(make, **options):
    """begin, a full IMU calibration at rest, metres and radians, tracking reset; at T0."""
    ft, emu, kernel, otos = make(**options)
    ft.t = 0.3  # past the power-up quick calibration
    assert otos.begin()
    assert otos.calibrateImu()  # 255 samples, polled as SparkFun's example does
    otos.setLinearUnit(M)
    otos.setAngularUnit(RAD)
    assert ft.t < T0 - 0.1
    ft.t = T0 - 0.1
    otos.resetTracking()
    ft.t = T0
    return ft, emu, kernel, otos


def test_ids_version_self_test_and_the_imu_calibration(bench):
    ft, emu, _kernel, otos = bench()
    ft.t = 0.3
    assert otos.is_connected() and otos.begin()
    assert otos.getVersionInfo() == [0x11, 0x10]  # hw 1.1, fw 1.0 as the firmware reports
    assert otos.selfTest() is True
    n0 = emu.imu_calibrations
    assert otos.calibrateImu(255) is True
    assert emu.imu_calibrations == n0 + 1
    assert otos.getImuCalibrationProgress() == 0
    otos.calibrateImu(100, waitUntilDone=False)
    left = otos.getImuCalibrationProgress()
    assert 95 <= left <= 99  # 3 ms of 2.4 ms samples gone
    ft.t += 0.12
    assert otos.getImuCalibrationProgress() == pytest.approx(left - 50, abs=1)
    ft.t += 0.2
    assert otos.getImuCalibrationProgress() == 0


def test_a_write_is_read_back_by_the_very_next_transaction(bench):
    ft, emu, kernel, otos = bench()
    ft.t = 0.3
    for value, raw in ((1.05, 50), (0.95, 0xCE), (1.127, 127), (0.873, 0x81)):
        otos.setLinearScalar(value)
        assert otos.getLinearScalar() == pytest.approx(value)
        (t_w, w, _), (t_r, r, _) = kernel.transactions[-2:]
        assert w == bytes([regs.SCALAR_LINEAR, raw]) and r == bytes([regs.SCALAR_LINEAR])
        assert t_r - t_w == pytest.approx(2.9e-4)  # the read starts 0.29 ms after the write
        otos.setAngularScalar(2.0 - value)
        assert otos.getAngularScalar() == pytest.approx(2.0 - value)
        assert (emu.linear_scalar, emu.angular_scalar) == pytest.approx((value, 2.0 - value))
    assert otos.setLinearScalar(1.2) is False  # refused by the library: nothing written
    assert emu.linear_scalar == pytest.approx(0.873)


def test_units_offset_and_position_written(bench):
    ft, emu, _kernel, otos = started(bench)
    otos.setOffset(qwiic_otos.Pose2D(0.05, -0.1, 0.2))
    otos.setPosition(qwiic_otos.Pose2D(1.0, 2.0, 0.5))
    ft.t += regs.IMU_SAMPLE_S  # the position registers change at the next 2.4 ms update
    assert emu.offset == pytest.approx((0.05, -0.1, 0.2), abs=2e-4)
    off = otos.getOffset()
    assert (off.x, off.y, off.h) == (0.0, 0.0, 0.0)  # firmware 1.0 never makes it readable
    p = otos.getPosition()
    assert (p.x, p.y, p.h) == pytest.approx((1.0, 2.0, 0.5), abs=3.1e-4)
    otos.setLinearUnit(1)  # inches, degrees: the library converts, the chip is unchanged
    otos.setAngularUnit(1)
    p = otos.getPosition()
    assert (p.x, p.y) == pytest.approx((39.37, 78.74), abs=0.02)
    assert p.h == pytest.approx(math.degrees(0.5), abs=0.02)
    otos.setLinearUnit(M)
    otos.setAngularUnit(RAD)
    otos.resetTracking()
    ft.t += 0.01
    p = otos.getPosition()  # the host at the origin again, the offset kept
    assert (p.x, p.y, p.h) == pytest.approx((0.0, 0.0, 0.0), abs=3.1e-4)
    assert emu.offset == pytest.approx((0.05, -0.1, 0.2), abs=2e-4)


def test_a_known_motion_position_velocity_acceleration_and_heading(bench):
    ft, emu, _kernel, otos = started(bench)
    t0 = ft.t
    ramp = Ramp(t0, a=0.6, v=0.3)
    emu.motion = ramp
    ft.t = t0 + 0.4  # accelerating: 0.6 m/s^2
    p = otos.getPosition()
    tu = emu.t_update  # the update the position came from (the next reads may see a newer one)
    v, a = otos.getVelocity(), otos.getAcceleration()
    assert p.y == pytest.approx(ramp.y(tu), abs=3.1e-4)
    assert v.y == pytest.approx(ramp.speed(tu), abs=2e-3)
    assert a.y == pytest.approx(0.6, abs=0.03)  # the firmware's filter on a true 0.6 m/s^2
    assert (p.x, v.x, a.x) == pytest.approx((0.0, 0.0, 0.0), abs=1e-3)
    ft.t = t0 + 2.0  # cruising at 0.3 m/s
    p = otos.getPosition()
    tu = emu.t_update  # the update the position came from (the next reads may see a newer one)
    v, a = otos.getVelocity(), otos.getAcceleration()
    assert p.y == pytest.approx(ramp.y(tu), abs=3.1e-4)
    assert v.y == pytest.approx(0.3, abs=2e-3)
    assert a.y == pytest.approx(0.0, abs=0.01)
    assert otos.getStatus() == 0


@pytest.mark.parametrize("config", [0x0F, 0x0B])
def test_rotation_bit_turning_path(bench, config):
    """0x0F: the velocity turned by the heading (an arc); 0x0B (enRot clear, as SparkFun's
    setSignalProcessConfig lets a user write): the sensor-frame velocity integrated as it is."""
    ft, emu, _kernel, otos = started(bench)
    otos.setSignalProcessConfig(config)
    assert otos.getSignalProcessConfig() == config
    t0 = ft.t
    w, v = 1.0, 0.3
    emu.motion = Ramp(t0, a=1e9, v=v)  # 0.3 m/s along the sensor's +y from t0
    emu.heading_source = ConstantYawRate(w, t_start=t0)
    ft.t = t0 + 1.0
    p = otos.getPosition()
    tu = emu.t_update - t0
    assert p.h == pytest.approx(w * tu, abs=2e-4)
    if config & regs.SP_ROT:
        truth = (v / w * (math.cos(w * tu) - 1.0), v / w * math.sin(w * tu))
    else:
        truth = (0.0, v * tu)
    assert (p.x, p.y) == pytest.approx(truth, abs=4e-4)


def test_lookup_table_bit_undoes_the_paa_resolution_error(bench):
    ft, emu, _kernel, otos = started(bench, paa_resolution=0.95)
    t0 = ft.t
    ramp = Ramp(t0, a=1e9, v=0.2)
    emu.motion = ramp
    ft.t = t0 + 1.0
    assert otos.getPosition().y == pytest.approx(ramp.y(emu.t_update), abs=3.1e-4)
    otos.setSignalProcessConfig(regs.SIGNAL_PROCESS_DEFAULT & ~regs.SP_LUT)
    otos.resetTracking()
    t1 = ft.t
    ft.t = t1 + 1.0
    assert otos.getPosition().y == pytest.approx(0.95 * 0.2 * (emu.t_update - t1), abs=1e-3)


@pytest.mark.parametrize(("speed", "warn"), [(0.3, False), (1.0, True)])
def test_status_warning_only_above_the_firmware_threshold(bench, speed, warn):
    ft, emu, _kernel, otos = started(bench, lift_windows=[(T0 + 1.0, T0 + 1.5)])
    t0 = ft.t
    emu.motion = Ramp(t0, a=1e9, v=speed)
    ft.t = t0 + 0.9
    assert otos.getStatus() == 0
    y_before = otos.getPosition().y
    ft.t = t0 + 1.3
    status = otos.getStatus()
    y_lifted = otos.getPosition().y
    assert status == (regs.STATUS_WARN_OPTICAL if warn else 0)
    if warn:  # IMU only: the accelerometer reads 0, the estimate holds 1 m/s
        assert y_lifted - y_before == pytest.approx(speed * 0.4, abs=0.01)
        assert otos.getVelocity().y == pytest.approx(speed, abs=2e-3)
    else:  # the optical velocity 0 is believed: the pose stops
        assert y_lifted - y_before == pytest.approx(speed * 0.1, abs=0.003)
        assert otos.getVelocity().y == pytest.approx(0.0, abs=2e-3)
    ft.t = t0 + 1.7
    assert otos.getStatus() == 0


def test_standard_deviations_are_the_firmware_filters(bench):
    ft, emu, _kernel, otos = started(bench)
    t0 = ft.t
    emu.motion = Ramp(t0, a=1e9, v=0.2)
    ft.t = t0 + 1.0
    pos, vel = otos.getPositionStdDev(), otos.getVelocityStdDev()
    acc = otos.getAccelerationStdDev()
    n = round((emu.t_update - t0) / regs.IMU_SAMPLE_S)
    assert n > 400
    # the position has no measurement: its variance grows by q00 (1e-8) and the velocity's
    # share every update; the velocity's settles where the two updates balance
    assert pos.x == pos.y and pos.x > math.sqrt(1e-8 * n)
    assert vel.x == vel.y and 1e-3 < vel.x < 0.02
    assert acc.x == acc.y and 0 < acc.x < 0.1
    want = [math.sqrt(f.p[i][i]) for i in range(3) for f in (emu.kf_x, emu.kf_y, emu.kf_h)]
    got = [pos.x, pos.y, pos.h, vel.x, vel.y, vel.h, acc.x, acc.y, acc.h]
    for g, w_, lsb in zip(got, want, regs.POSE_BLOCK_LSB, strict=True):
        assert g == pytest.approx(w_, abs=1.01 * lsb)
    ft.t += 5.0
    assert otos.getPositionStdDev().x > pos.x  # it only grows without a position fix
    # the 18-byte bursts agree with the single reads
    _p2, v2, _a2 = otos.getPosVelAccStdDev()
    assert v2.x == pytest.approx(otos.getVelocityStdDev().x, abs=regs.VEL_MPS_PER_LSB)


def test_variance_bit_clear_the_linear_filters_take_each_measurement_as_exact(bench):
    ft, emu, _kernel, otos = started(bench)
    otos.setSignalProcessConfig(regs.SIGNAL_PROCESS_DEFAULT & ~regs.SP_VAR)
    t0 = ft.t
    emu.motion = Ramp(t0, a=0.6, v=0.2)  # 0.6 m/s^2 for 0.33 s
    ft.t = t0 + 0.2
    # the filters' acceleration is the accelerometer's reading, exactly
    assert otos.getAcceleration().y == pytest.approx(0.6, abs=regs.ACC_MPSS_PER_LSB)
    ft.t = t0 + 0.5
    vel = otos.getVelocityStdDev()
    assert (vel.x, vel.y) == (0.0, 0.0)  # zero measurement variance: nothing left
    assert vel.h > 0  # the heading filter's gyro variance is fixed (1e-3)
    assert otos.getVelocity().y == pytest.approx(0.2, abs=2e-3)


def test_accelerometer_bit_clear_no_rejection_the_pose_stops_when_lifted(bench):
    ft, emu, _kernel, otos = started(bench, lift_windows=[(T0 + 1.0, T0 + 1.5)])
    otos.setSignalProcessConfig(regs.SIGNAL_PROCESS_DEFAULT & ~regs.SP_ACC)
    t0 = ft.t
    emu.motion = Ramp(t0, a=1e9, v=1.0)
    ft.t = t0 + 0.9
    y0 = otos.getPosition().y
    ft.t = t0 + 1.3
    assert otos.getStatus() == 0  # no rule without the accelerometer
    assert otos.getPosition().y - y0 == pytest.approx(0.1, abs=0.004)


def test_accelerometer_bit_clear_the_acceleration_is_the_filters_guess_from_velocity(bench):
    """enAcc clear: no accelerometer update, so the filters' acceleration (what the client
    reads) follows the optical velocity's changes only, about 0.2 s late (with the bit set:
    0.6 at 0.4 s and 0.0 cruising, test_a_known_motion_position_velocity_...)."""
    ft, emu, _kernel, otos = started(bench)
    otos.setSignalProcessConfig(regs.SIGNAL_PROCESS_DEFAULT & ~regs.SP_ACC)
    t0 = ft.t
    emu.motion = Ramp(t0, a=0.6, v=0.3)  # 0.6 m/s^2 until 0.5 s, then 0.3 m/s
    got = {}
    for dt in (0.2, 0.4, 0.7, 2.0):
        ft.t = t0 + dt
        got[dt] = otos.getAcceleration().y
    assert got[0.2] == pytest.approx(0.17, abs=0.02)  # a true 0.6 m/s^2 seen late
    assert got[0.4] == pytest.approx(0.56, abs=0.02)
    assert got[0.7] == pytest.approx(0.33, abs=0.02)  # 0.2 s after the ramp ended: truth 0
    assert got[2.0] == pytest.approx(0.0, abs=0.005)
    assert otos.getVelocity().y == pytest.approx(0.3, abs=2e-3)  # the velocity is unharmed
    assert otos.getAccelerationStdDev().y == pytest.approx(0.091, abs=0.005)  # 0.014 with it
    assert emu.stats.protocol_errors == 0  # the OTOS's bus has no timing or length rule


def test_accelerometer_bit_cleared_during_a_warning_freezes_the_warning_bit(bench):
    """The firmware touches warnOpticalTracking only inside its enAcc branch: cleared while
    the bit is set, it stays set (our driver's quality stays 0) until enAcc is set again."""
    ft, emu, _kernel, otos = started(bench, lift_windows=[(T0 + 1.0, T0 + 1.5)])
    t0 = ft.t
    emu.motion = Ramp(t0, a=1e9, v=1.0)
    ft.t = t0 + 1.2  # lifted at 1 m/s: the warning
    assert otos.getStatus() == regs.STATUS_WARN_OPTICAL
    otos.setSignalProcessConfig(regs.SIGNAL_PROCESS_DEFAULT & ~regs.SP_ACC)
    y0 = otos.getPosition().y
    ft.t = t0 + 1.4
    assert otos.getStatus() == regs.STATUS_WARN_OPTICAL
    assert otos.getPosition().y - y0 == pytest.approx(0.0, abs=3.1e-4)  # optical 0 believed
    ft.t = t0 + 1.7  # on the floor again, tracking
    assert otos.getStatus() == regs.STATUS_WARN_OPTICAL
    assert otos.getVelocity().y == pytest.approx(1.0, abs=2e-3)
    otos.setSignalProcessConfig(regs.SIGNAL_PROCESS_DEFAULT)
    ft.t += 0.01
    assert otos.getStatus() == 0


# --- the documented simplifications, pinned ---------------------------------------------


def test_pinned_position_has_no_filter_lag(bench):
    """The firmware's velocity filter lags a step; the emulator integrates without lag."""
    ft, emu, _kernel, otos = started(bench)
    t0 = ft.t
    ramp = Ramp(t0, a=1e9, v=0.5)  # a step to 0.5 m/s
    emu.motion = ramp
    ft.t = t0 + 0.05
    assert otos.getPosition().y == pytest.approx(ramp.y(emu.t_update), abs=3.1e-4)
    assert otos.getVelocity().y == pytest.approx(0.5, abs=2e-3)
    # what is left out: the firmware's own filter (run alongside) stays ~1.8 mm behind
    ft.t = t0 + 1.0
    assert ramp.y(emu.t_update) - emu.kf_y.x[0] == pytest.approx(1.8e-3, abs=3e-4)
    assert otos.getPosition().y == pytest.approx(ramp.y(emu.t_update), abs=3.1e-4)


def test_pinned_lookup_table_is_speed_independent(bench):
    ratios = []
    for speed in (0.1, 1.0):
        ft, emu, _kernel, otos = started(bench, paa_resolution=0.9)
        otos.setSignalProcessConfig(regs.SIGNAL_PROCESS_DEFAULT & ~regs.SP_LUT)
        t0 = ft.t
        emu.motion = Ramp(t0, a=1e9, v=speed)
        ft.t = t0 + 1.0
        ratios.append(otos.getPosition().y / (speed * (emu.t_update - t0)))
    assert ratios == pytest.approx([0.9, 0.9], abs=0.005)


def test_pinned_no_tilt_no_centripetal_no_raw_imu_and_burst_deltas_only(bench):
    ft, emu, _kernel, otos = started(bench)
    emu.motion = Ramp(ft.t, a=1e9, v=0.3)
    emu.heading_source = ConstantYawRate(1.0, t_start=ft.t)
    ft.t += 1.0
    assert otos.getStatus() & regs.STATUS_WARN_TILT == 0
    # turning at 1 rad/s at 0.3 m/s: a real accelerometer feels 0.3 m/s^2 towards the centre
    a = otos.getAcceleration()
    assert math.hypot(a.x, a.y) < 0.01
    assert bytes(emu.mem[regs.LSM_RAW : regs.LSM_RAW + 12]) == bytes(12)
    burst = emu.mem[regs.PAA_BURST : regs.PAA_BURST + regs.PAA_BURST_LEN]
    assert bytes(burst[:2]) == bytes(2) and bytes(burst[6:]) == bytes(6)
    dy = regs.signed16(burst[4], burst[5])
    assert dy == pytest.approx(0.3 * regs.IMU_SAMPLE_S / 0.0254 * regs.PAA_CPI, abs=2)


def test_vendor_burst_of_36_bytes_is_refused_by_smbus2_on_linux(bench):
    """getPosVelAccAndStdDev reads 36 bytes in one SMBus block: smbus2 allows 32 (the
    library's limit on Linux, not the chip's; our driver reads with i2c_rdwr)."""
    _ft, _emu, _kernel, otos = started(bench)
    with pytest.raises(ValueError, match="over 32 bytes"):
        otos.getPosVelAccAndStdDev()
