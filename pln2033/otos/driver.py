"""The SparkFun OTOS driver (PAA5160 optical chip + LSM6DSO IMU + STM32 fusion, I2C 0x17).

No ROS here. The driver talks to any :class:`~pln2033.i2c.I2cBus`. Facts and their
sources: :mod:`pln2033.otos.regs`, docs/sensors.md (OTOS section).

Two outputs:

- :meth:`OTOS.read_motion` -- the project's counts pipeline. The OTOS exposes no
  accumulating optical counter: its PAA5160 burst copy (0x50..0x5B) is the delta of the
  firmware's latest 2.4 ms update, overwritten by the next, with no sequence number, so a
  host cannot sum it without losing or double counting updates. The driver instead takes
  the change of the on-chip position between two reads, undoes the mounting offset the
  driver wrote, turns it from the OTOS's world frame into the sensor frame by the on-chip
  heading, divides out the linear scalar, and states it in counts at a nominal effective
  CPI (:data:`EFFECTIVE_CPI`). No count is lost or doubled whatever the poll rate, as
  long as the sensor moves less than 10 m (the int16 position range) between two reads.
  These counts are fused (optical + accelerometer, SparkFun's velocity lookup table), not
  raw optical counts: docs/sensors.md (OTOS section) says so. They follow the chip's
  own integration within a bound, not exactly: the firmware truncates position (0.305
  mm) and heading (pi/32768 rad) toward zero. The driver takes each register at the
  middle of its LSB (``_centred``), so a total is off by <= 1 position LSB (12 counts)
  plus <= 4.8e-5 x the distance travelled (half the heading's LSB turning every step);
  taken as read, the heading's mean error was a drift across the motion (0.5 LSB x the
  distance: 71 counts after 36 m). tests/beagle/test_power_cycle_otos.py pins the bound.
- :meth:`OTOS.read_pose` / :attr:`OTOS.last_pose` -- the on-chip pose and velocity, for a
  second nav_msgs/Odometry.

Frames: the OTOS's own axes are the project's sensor frame (+x right, +y forward, heading
counter-clockwise), per SparkFun's Example4 offset convention.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from typing import NamedTuple

from ..angles import wrap_pi
from ..errors import (
    FirmwareError,
    InvalidCpiError,
    ProductIdError,
    SensorError,
    SensorNotRespondingError,
)
from ..i2c import I2cBus, I2cError
from ..sensor import INCH_M, NO_MOTION, ChipInfo, CpiRange, Motion
from . import regs

EFFECTIVE_CPI = 1000
"""Counts per inch of :meth:`OTOS.read_motion`'s counts (1 count = 25.4 um). The on-chip
position has 0.305 mm per LSB, about 12 counts; the driver keeps the fraction."""

RESET_SETTLE_S = 0.01
"""Wait after a tracking reset: four of the firmware's 2.4 ms updates."""

QUALITY_OK = 1
QUALITY_WARN = 0

OTOS_INFO = ChipInfo(
    chip="otos",
    title="SparkFun OTOS (PixArt PAA5160 + LSM6DSO)",
    bus="i2c",
    cpi=CpiRange(EFFECTIVE_CPI, EFFECTIVE_CPI, 1),
    cpi_default=EFFECTIVE_CPI,
    counter_bits=16,
    quality_name="tracking ok",  # 1 = status bit warnOpticalTracking clear, 0 = set
    quality_threshold=1,
    # the warning is set only while the firmware rejects the optical measurement at speed
    # (measured < 0.25 m/s, estimate > 0.5 m/s) and then integrates its filters' velocity,
    # carried by the accelerometer ([fw] main.cpp sensorUpdate): the counts of such a read
    # are motion, already counted; a lift-gap estimate on top would count it twice (the
    # other 0, a PAA error, is sticky until power-off: a gap that never closed got no estimate)
    poor_polls_carry_motion=True,
    max_speed_mps=regs.MAX_SPEED_MPS,
    firmware="",
    source=(
        "SparkFun_Qwiic_OTOS_Arduino_Library sfDevOTOS.h/.cpp, qwiic_otos_py, "
        "SparkFun_Optical_Tracking_Odometry_Sensor Firmware/ (docs/sensors.md, OTOS section)"
    ),
)


class InvalidSettingError(SensorError, ValueError):
    """A setting (scalar, offset, calibration samples) outside what the chip accepts."""


class Pose(NamedTuple):
    """A planar pose or its rate: x, y (m or m/s), heading h (rad or rad/s), OTOS frame."""

    x: float
    y: float
    h: float


class PoseReading(NamedTuple):
    """One burst of the on-chip odometry: pose, velocity, status byte, host time (s)."""

    pose: Pose
    velocity: Pose
    status: int
    t: float


def _pose_bytes(p: Pose) -> bytes:
    """A pose as the six register bytes the firmware takes (rounded to the LSB)."""
    out: list[int] = []
    for v in (
        round(p.x / regs.POS_M_PER_LSB),
        round(p.y / regs.POS_M_PER_LSB),
        round(p.h / regs.HEADING_RAD_PER_LSB),
    ):
        out += regs.int16_bytes(v)
    return bytes(out)


def quantise_offset(p: Pose) -> Pose:
    """The offset the chip holds after writing ``p`` (its int16 LSBs)."""
    b = _pose_bytes(p)
    return Pose(
        regs.signed16(b[0], b[1]) * regs.POS_M_PER_LSB,
        regs.signed16(b[2], b[3]) * regs.POS_M_PER_LSB,
        regs.signed16(b[4], b[5]) * regs.HEADING_RAD_PER_LSB,
    )


def invert_pose(p: Pose) -> Pose:
    """The inverse transform of ``p`` (as the firmware's invertPose in pose2d.cpp)."""
    c, s = math.cos(p.h), math.sin(p.h)
    return Pose(-p.x * c - p.y * s, p.x * s - p.y * c, -p.h)


def _centred(value: float, lsb: float) -> float:
    """A register value truncated toward zero by the firmware, moved to the middle of the
    LSB it stands for (0 stays 0: the truth is within one LSB either side). Halves the
    worst error and removes the mean one, which the heading's would turn into a drift
    across the motion (0.5 LSB x the distance)."""
    return value + 0.5 * lsb if value > 0 else value - 0.5 * lsb if value < 0 else value


class OTOS:
    """One SparkFun OTOS on one I2C bus address.

    Args:
        bus: the I2C bus (:class:`~pln2033.i2c.Smbus2Bus` or the emulator).
        name: the device path, used in messages.
        address: 7-bit I2C address (0x17; the OTOS has no address setting).
        expected_product_id: override when a firmware reports another id (default 0x5F).
        linear_scalar, angular_scalar: 0.872..1.127, applied at every :meth:`initialise`.
        offset: (x m, y m, heading rad) of the sensor relative to the robot's centre,
            applied at every :meth:`initialise` (the chip forgets it at power-off).
        imu_samples: IMU calibration samples at :meth:`initialise` (2.4 ms each, 0 = skip;
            255 = 0.61 s: the robot must stand still and flat meanwhile).
        sleep, clock: injected for tests.
    """

    info = OTOS_INFO

    def __init__(
        self,
        bus: I2cBus,
        name: str = "otos",
        address: int = regs.ADDRESS,
        expected_product_id: int = regs.PRODUCT_ID,
        linear_scalar: float = 1.0,
        angular_scalar: float = 1.0,
        offset: Sequence[float] = (0.0, 0.0, 0.0),
        imu_samples: int = regs.IMU_SAMPLES_MAX,
        sleep: Callable[[float], None] = time.sleep,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        if not 0x08 <= address <= 0x77:
            raise InvalidSettingError(f"I2C address {address:#x} is not a 7-bit device address")
        if (
            isinstance(imu_samples, bool)
            or not isinstance(imu_samples, int)
            or not (0 <= imu_samples <= regs.IMU_SAMPLES_MAX)
        ):
            raise InvalidSettingError(
                f"imu_samples {imu_samples!r} is out of range: 0 (skip) .. 255 samples of 2.4 ms"
            )
        self.bus = bus
        self.name = name
        self.address = address
        self.expected_product_id = expected_product_id
        self._check_scalars(linear_scalar, angular_scalar)
        self.linear_scalar = float(linear_scalar)
        self.angular_scalar = float(angular_scalar)
        self.offset = self._check_offset(offset)
        self.imu_samples = imu_samples
        self.sleep = sleep
        self.clock = clock
        self.hw_version = self.fw_version = 0
        # the motion read: status then position and velocity, one transaction
        self._motion_ptr = bytes([regs.STATUS])
        self._motion_len = 1 + 12
        self._chip_offset_inv = invert_pose(quantise_offset(self.offset))
        self._chip_scalar = 1.0
        self._prev: tuple[float, float, float] | None = None  # sensor x, y (m), heading (rad)
        self._frac_x = self._frac_y = 0.0
        self._wraps_x = self._wraps_y = 0
        self._prev_raw_xy: tuple[int, int] | None = None
        self.last_pose: PoseReading | None = None

    # --- raw access ------------------------------------------------------------------------

    def read_bytes(self, reg: int, n: int) -> bytes:
        """``n`` bytes from ``reg`` on (the OTOS auto-increments), one transaction."""
        rx = self.bus.write_read(self.address, bytes([reg]), n)
        if len(rx) != n:
            raise I2cError(f"{self.name}: asked for {n} bytes from {reg:#04x}, got {len(rx)}")
        return rx

    def write_bytes(self, reg: int, data: bytes | Sequence[int]) -> None:
        self.bus.write(self.address, bytes([reg, *data]))

    def read_register(self, reg: int) -> int:
        return self.read_bytes(reg, 1)[0]

    # --- identity ----------------------------------------------------------------------------

    def check_product_id(self) -> None:
        got = self.read_register(regs.PRODUCT_ID_REG)
        if got != self.expected_product_id:
            raise ProductIdError(
                f"{self.name}: the chip at I2C address {self.address:#04x} reads product id "
                f"{got:#04x} at register 0x00, expected {self.expected_product_id:#04x} (SparkFun "
                "OTOS). Check that the device at this address is an OTOS ('i2cdetect' shows "
                "what answers), the Qwiic cable and 3.3 V; if your OTOS firmware reports "
                "another id, set the driver option expected_product_id"
            )
        hw, fw = self.read_bytes(regs.HW_VERSION, 2)
        self.hw_version, self.fw_version = hw, fw

    @property
    def versions(self) -> str:
        """ "hw 1.1, fw 1.0" (major.minor nibbles of registers 0x01, 0x02)."""
        hw, fw = self.hw_version, self.fw_version
        return f"hw {hw >> 4}.{hw & 15}, fw {fw >> 4}.{fw & 15}"

    def check_status(self) -> int:
        """The status byte; SensorNotRespondingError when the chip reports a fatal error."""
        status = self.read_register(regs.STATUS)
        self._raise_on_error(status)
        return status

    def _raise_on_error(self, status: int) -> None:
        if status & regs.STATUS_ERROR_PAA:
            raise SensorNotRespondingError(
                f"{self.name}: the OTOS reports an optical-chip (PAA5160) error (status "
                f"{status:#04x}); the error stays until power-off: power-cycle the sensor, and "
                "if it stays, check the 3.3 V supply (the firmware checks the PAA5160 is powered)"
            )
        if status & regs.STATUS_ERROR_LSM:
            raise SensorNotRespondingError(
                f"{self.name}: the OTOS reports an IMU (LSM6DSO) error (status {status:#04x}), "
                "e.g. an IMU calibration that timed out; power-cycle the sensor"
            )

    # --- settings ----------------------------------------------------------------------------

    @staticmethod
    def _check_scalars(linear: object, angular: object) -> None:
        for which, value in (("linear", linear), ("angular", angular)):
            problem = regs.scalar_problem(value, which)
            if problem:
                raise InvalidSettingError(problem)

    @staticmethod
    def _check_offset(offset: Sequence[float]) -> Pose:
        try:
            x, y, h = (float(v) for v in offset)
        except (TypeError, ValueError):
            raise InvalidSettingError(
                f"offset must be three numbers (x m, y m, heading rad), got {offset!r}"
            ) from None
        limit = 32767 * regs.POS_M_PER_LSB
        if not all(math.isfinite(v) for v in (x, y, h)) or abs(x) > limit or abs(y) > limit:
            raise InvalidSettingError(
                f"offset ({x}, {y}, {h}) is out of range: x and y within +-{limit:.3f} m "
                "(int16 registers of 10 m / 32768), heading finite"
            )
        return Pose(x, y, wrap_pi(h))

    def set_scalars(self, linear: float, angular: float) -> None:
        """Write the linear and angular scalars (0.872..1.127) and verify them by reading back.

        Both are checked before anything is written. The firmware applies host writes in
        its main loop (registers are written to a shadow copy first), so the read-back
        waits up to ~20 ms, longer while an IMU calibration runs.
        """
        self._check_scalars(linear, angular)
        want = bytes([regs.encode_scalar(linear), regs.encode_scalar(angular)])
        self.write_bytes(regs.SCALAR_LINEAR, want)
        got = self._await(regs.SCALAR_LINEAR, want, self._settle_s())
        if got != want:
            dec = regs.decode_scalar
            raise SensorError(
                f"{self.name}: scalars read back {dec(got[0])}/{dec(got[1])} (bytes "
                f"{got.hex()}), wrote {dec(want[0])}/{dec(want[1])}; check the I2C wiring "
                "and retry"
            )
        self.linear_scalar, self.angular_scalar = float(linear), float(angular)
        self._chip_scalar = regs.decode_scalar(want[0])

    def set_signal_process(self, value: int = regs.SIGNAL_PROCESS_DEFAULT) -> None:
        """Write the signal-process bits (0x0E) and verify them by reading back.

        The counts need the power-up value 0x0F: with enRot clear the chip integrates the
        sensor-frame velocity, and the driver's turn from the world frame by the heading
        then mixes the axes. The chip keeps what a host wrote until power-off, so another
        client (SparkFun's ``setSignalProcessConfig``) may have left another value.
        """
        self.write_bytes(regs.SIGNAL_PROCESS, [value])
        got = self._await(regs.SIGNAL_PROCESS, bytes([value]), self._settle_s())
        if got != bytes([value]):
            raise SensorError(
                f"{self.name}: the signal-process register reads back {got[0]:#04x}, wrote "
                f"{value:#04x}; check the I2C wiring and retry"
            )

    def get_scalars(self) -> tuple[float, float]:
        """(linear, angular) as the chip holds them."""
        b = self.read_bytes(regs.SCALAR_LINEAR, 2)
        return regs.decode_scalar(b[0]), regs.decode_scalar(b[1])

    def set_offset(self, x: float, y: float, h: float) -> None:
        """The sensor's mounting offset from the robot's centre (m, m, rad), one 6-byte write.

        The firmware takes an offset only when all six bytes arrive and never copies it
        into its readable registers (firmware 1.0, main.cpp): it cannot be read back, so
        the driver keeps what it wrote (rounded to the LSB) and uses it to undo the
        offset in the counts. Reset tracking after it so the pose starts at the origin.
        """
        p = self._check_offset((x, y, h))
        self.write_bytes(regs.OFFSET, _pose_bytes(p))
        self.offset = p
        self._chip_offset_inv = invert_pose(quantise_offset(p))
        self._prev = None

    def _settle_s(self) -> float:
        return 0.02

    def _await(self, reg: int, want: bytes, timeout: float) -> bytes:
        """Read ``len(want)`` bytes at ``reg`` until they equal ``want`` or ``timeout`` passes."""
        end = self.clock() + timeout
        while True:
            got = self.read_bytes(reg, len(want))
            if got == want or self.clock() >= end:
                return got
            self.sleep(0.001)

    def calibrate_imu(self, samples: int | None = None) -> None:
        """Calibrate the IMU's gyro and accelerometer offsets; the robot must stand still, flat.

        ``samples`` of 2.4 ms each (default: the constructor's ``imu_samples``); waits until
        the chip's sample countdown (register 0x06) reaches 0, at most samples x 3 ms + 0.1 s.
        """
        n = self.imu_samples if samples is None else samples
        if isinstance(n, bool) or not isinstance(n, int) or not 1 <= n <= regs.IMU_SAMPLES_MAX:
            raise InvalidSettingError(f"IMU calibration samples {n!r}: 1..255 (2.4 ms each)")
        self.write_bytes(regs.IMU_CALIB, [n])
        self.sleep(0.003)  # one sample period, so the register holds the countdown
        end = self.clock() + n * 0.003 + 0.1
        while True:
            left = self.read_register(regs.IMU_CALIB)
            if left == 0:
                return
            if self.clock() >= end:
                raise SensorNotRespondingError(
                    f"{self.name}: the IMU calibration did not finish ({left} of {n} samples "
                    f"left after {n * 3 + 100} ms); power-cycle the sensor"
                )
            self.sleep(0.003)

    def reset_tracking(self) -> None:
        """Reset the on-chip pose to the origin (and its Kalman filters)."""
        self.write_bytes(regs.RESET, [regs.RESET_TRACKING])
        # the firmware applies it (and a pending offset) in its main loop and clears the
        # register at once: wait a few 2.4 ms updates so the next read sees the new pose
        self.sleep(RESET_SETTLE_S)
        got = self._await(regs.RESET, b"\x00", self._settle_s())
        if got != b"\x00":
            raise SensorNotRespondingError(
                f"{self.name}: the OTOS did not finish the tracking reset (register 0x07 reads "
                f"{got[0]:#04x}); power-cycle the sensor"
            )
        self._prev = None
        self._wraps_x = self._wraps_y = 0
        self._prev_raw_xy = None

    def self_test(self) -> bool:
        """The OTOS's self test (an IMU test, ~20 ms): True when it passed."""
        self.write_bytes(regs.SELF_TEST, [regs.SELF_TEST_START])
        value = 0
        for _ in range(20):
            self.sleep(0.005)
            value = self.read_register(regs.SELF_TEST)
            if value & (regs.SELF_TEST_PASS | regs.SELF_TEST_FAIL):
                break
        return bool(value & regs.SELF_TEST_PASS)

    # --- bring-up ----------------------------------------------------------------------------

    def initialise(self, cpi: int = EFFECTIVE_CPI, firmware: Sequence[int] | None = None) -> None:
        """Product id, error check, IMU calibration, signal-process bits, scalars, offset,
        reset tracking, one read.

        Run at every start: the OTOS forgets its scalars, offset and IMU calibration at
        power-off (SparkFun, Example3/Example4), and keeps until then whatever another client
        wrote. ``cpi`` is ignored: the counts' resolution
        is fixed (:data:`EFFECTIVE_CPI`). The OTOS takes no firmware from this driver.
        """
        if firmware is not None:
            self.check_firmware(firmware)
        self.check_product_id()
        self.check_status()
        if self.imu_samples:
            self.calibrate_imu()
        self.set_signal_process()
        self.set_scalars(self.linear_scalar, self.angular_scalar)
        self.set_offset(*self.offset)
        self.reset_tracking()
        self.check_status()
        self.read_motion()  # the baseline of the counts

    # --- motion ------------------------------------------------------------------------------

    def _host_to_self(self, x: float, y: float, h: float) -> tuple[float, float, float]:
        """The sensor's own pose from the robot pose the chip reports (offset undone)."""
        inv = self._chip_offset_inv
        hs = h - inv.h
        c, s = math.cos(hs), math.sin(hs)
        return x - (inv.x * c - inv.y * s), y - (inv.x * s + inv.y * c), hs

    def _decode_pose(self, b: bytes, t: float, status: int) -> PoseReading:
        px, py, ph = regs.signed16(b[0], b[1]), regs.signed16(b[2], b[3]), regs.signed16(b[4], b[5])
        if self._prev_raw_xy is not None:
            ox, oy = self._prev_raw_xy
            self._wraps_x += (px - ox < -32768) - (px - ox >= 32768)
            self._wraps_y += (py - oy < -32768) - (py - oy >= 32768)
        self._prev_raw_xy = (px, py)
        span = 65536 * regs.POS_M_PER_LSB
        pose = Pose(
            px * regs.POS_M_PER_LSB + self._wraps_x * span,
            py * regs.POS_M_PER_LSB + self._wraps_y * span,
            ph * regs.HEADING_RAD_PER_LSB,
        )
        vel = Pose(
            regs.signed16(b[6], b[7]) * regs.VEL_MPS_PER_LSB,
            regs.signed16(b[8], b[9]) * regs.VEL_MPS_PER_LSB,
            regs.signed16(b[10], b[11]) * regs.VEL_RPS_PER_LSB,
        )
        reading = PoseReading(pose, vel, status, t)
        self.last_pose = reading
        return reading

    def read_pose(self) -> PoseReading:
        """The on-chip pose and velocity: one burst of status + 0x20..0x2B (13 bytes).

        ``pose`` is the robot's (the offset applied) in the OTOS's world frame since the
        last tracking reset: x, y in metres (continued past the registers' +-10 m by the
        driver), heading in rad (-pi..pi, CCW). ``velocity`` in m/s and rad/s, world frame.
        The counts of :meth:`read_motion` are not touched (they follow the position).
        """
        rx = self.read_bytes(regs.STATUS, self._motion_len)
        return self._decode_pose(rx[1:], self.clock(), rx[0])

    def read_motion(self) -> Motion:
        """Counts since the previous read from the change of the on-chip position (one burst).

        Also refreshes :attr:`last_pose` (the same bytes), so a node that publishes the
        on-chip odometry needs no second transfer.
        """
        rx = self.read_bytes(regs.STATUS, self._motion_len)
        status = rx[0]
        reading = self._decode_pose(rx[1:], self.clock(), status)
        pose = reading.pose
        sx, sy, sh = self._host_to_self(
            _centred(pose.x, regs.POS_M_PER_LSB),
            _centred(pose.y, regs.POS_M_PER_LSB),
            _centred(pose.h, regs.HEADING_RAD_PER_LSB),
        )
        quality = (
            QUALITY_WARN
            if status & (regs.STATUS_WARN_OPTICAL | regs.STATUS_ERROR_PAA)
            else (QUALITY_OK)
        )
        prev = self._prev
        self._prev = (sx, sy, sh)
        if prev is None:
            return Motion(0, 0, status, False, False, False, quality)
        dxw, dyw = sx - prev[0], sy - prev[1]
        hm = prev[2] + wrap_pi(sh - prev[2]) / 2  # mid heading of the interval
        c, s = math.cos(hm), math.sin(hm)
        scale = EFFECTIVE_CPI / INCH_M / self._chip_scalar
        fx = self._frac_x + (c * dxw + s * dyw) * scale
        fy = self._frac_y + (-s * dxw + c * dyw) * scale
        nx, ny = math.floor(fx + 0.5), math.floor(fy + 0.5)
        self._frac_x, self._frac_y = fx - nx, fy - ny
        overflow = False
        if not -32768 <= nx <= 32767 or not -32768 <= ny <= 32767:
            overflow = True
            nx, ny = max(-32768, min(32767, nx)), max(-32768, min(32767, ny))
        return Motion(nx, ny, status, False, bool(nx or ny), overflow, quality)

    # --- the interface's remaining methods ------------------------------------------------------

    def cpi_problem(self, cpi: object) -> str | None:
        return self.info.cpi.problem(cpi, "the OTOS (counts from its fused position)")

    def get_cpi(self) -> tuple[int, int]:
        return EFFECTIVE_CPI, EFFECTIVE_CPI

    def set_cpi(self, cpi: int, on_drain: Callable[[Motion], None] | None = None) -> None:
        """Accepts only :data:`EFFECTIVE_CPI`; ``on_drain`` is never called (nothing changes
        scale)."""
        problem = self.cpi_problem(cpi)
        if problem:
            raise InvalidCpiError(problem)

    def read_all_registers(self) -> tuple[Motion, dict[str, int]]:
        """0x00..0x5B in one transaction, by :data:`~pln2033.otos.regs.DUMP` (16-bit patterns).

        Reading the OTOS clears nothing: the Motion is zero (the counts follow the position).
        """
        rx = self.read_bytes(0, regs.DUMP_LEN)
        values = {}
        for name, addr, n in regs.DUMP:
            values[name] = rx[addr] if n == 1 else rx[addr] | (rx[addr + 1] << 8)
        return NO_MOTION, values

    def check_firmware(self, words: Sequence[int]) -> None:
        raise FirmwareError(
            "the OTOS takes no firmware from this driver: its STM32 firmware is flashed over "
            "its UART pins (SparkFun_Optical_Tracking_Odometry_Sensor, Firmware/README.md); "
            "leave the firmware option empty for an OTOS"
        )

    def load_firmware(self, words: Sequence[int]) -> None:
        self.check_firmware(words)
