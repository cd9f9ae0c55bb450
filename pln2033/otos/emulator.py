"""A register-level SparkFun OTOS emulator behind the I2C bus's bytes.

It follows the firmware 1.0 (sparkfun/SparkFun_Optical_Tracking_Odometry_Sensor,
Firmware/SFE/Src/main.cpp, registers.cpp, Core/Src/stm32c0xx_it.c) where it matters to a
host: a 96-byte register buffer read with auto increment (0 past the end); host writes land
in a shadow copy that the main loop applies a moment later (after an IMU calibration that
is running); a pose write (offset, position) counts only when all six bytes arrived; the
offset is never readable; every 2.4 ms update (416 Hz) rewrites position, velocity,
acceleration, std devs and the raw PAA5160 burst; a power cycle forgets scalars, offset and
calibration and runs the 64-sample quick IMU calibration after 100 ms.

The motion model: the shared :class:`~pln2033.emulated.CountingCore` turns the true
sensor-frame motion into the PAA5160's counts at 20 000 CPI (lifts, poor surface, noise,
faults as for every chip); each update scales them by the linear scalar, turns them into the
world frame by the emulated heading and integrates the position (an ideal filter: no
Kalman lag, no accelerometer). The heading comes from ``heading_source`` (a sensor-frame
motion source has no rotation) scaled by the angular scalar, plus the gyro's residual bias:
``gyro_bias_rps`` until the first calibration, then what the calibration left
(``gyro_noise_rps`` / sqrt(samples), plus minus the mean true yaw rate during it when the
robot turned while calibrating): a heading drift at rest, as users report.

Simplifications (docs/sensors.md (OTOS section)): no Kalman filter or velocity lookup table, the
status tracking warning is set exactly while lifted or over a poor surface, acceleration and
std-dev registers stay 0, the PAA burst holds only the deltas (bytes 2..5).
"""

from __future__ import annotations

import math
from typing import Any, Protocol

from ..angles import wrap_pi
from ..emulated import CountingCore
from ..i2c import I2cError, I2cNoAckError
from ..motion import MotionSource
from ..sensor import INCH_M
from . import regs

_T = 1.0 / regs.UPDATE_HZ
_POWER_UP_S = 0.1 + regs.POWER_UP_IMU_SAMPLES * _T  # delay(100) then calibrateImu(64) [fw]


class HeadingSource(Protocol):
    def yaw(self, t0: float, t1: float) -> float:
        """True heading change (rad, counter-clockwise) of the sensor between t0 <= t1."""
        ...


class NoRotation:
    def yaw(self, t0: float, t1: float) -> float:
        return 0.0


class ConstantYawRate:
    """Turning at ``rate`` rad/s (from ``t_start`` on)."""

    def __init__(self, rate: float, t_start: float = float("-inf")) -> None:
        self.rate, self.t_start = rate, t_start

    def yaw(self, t0: float, t1: float) -> float:
        return self.rate * max(0.0, t1 - max(t0, self.t_start))


def _to_int16(value: float) -> int:
    """The firmware's float -> int16: truncation toward zero, low 16 bits kept."""
    return int(value) & 0xFFFF


class EmulatedOTOS(CountingCore):
    """One emulated OTOS; use it wherever an :class:`~pln2033.i2c.I2cBus` goes.

    Args as :class:`~pln2033.emulated.CountingCore` (motion, clock, lift_windows,
    noise_counts, fault_windows, reset_after_fault, seed, record, low_quality_windows),
    plus:
        heading_source: the sensor's true rotation (default none).
        product_id: what register 0x00 reads (0x5F).
        address: the I2C address it answers (0x17).
        gyro_bias_rps: the gyro's zero-rate offset before any calibration (rad/s).
        gyro_noise_rps: per-sample gyro noise that a calibration of n samples leaves as
            residual bias / sqrt(n) (rad/s).
        write_latency_s: how long the main loop takes to apply a host write.
    """

    def __init__(
        self,
        motion: MotionSource | None = None,
        *,
        heading_source: HeadingSource | None = None,
        product_id: int = regs.PRODUCT_ID,
        address: int = regs.ADDRESS,
        gyro_bias_rps: float = math.radians(1.0),
        gyro_noise_rps: float = 0.005,
        write_latency_s: float = 0.0005,
        **core: Any,
    ) -> None:
        super().__init__(
            motion=motion,
            **core,
            cpi=regs.PAA_CPI,
            counter_bits=16,
        )
        self.heading_source: HeadingSource = heading_source or NoRotation()
        self.product_id = product_id
        self.address = address
        self.gyro_bias_rps = gyro_bias_rps
        self.gyro_noise_rps = gyro_noise_rps
        self.write_latency_s = write_latency_s
        self.true_yaw = 0.0  # the true heading change since construction (ground truth)
        self._t_yaw = self._t  # how far true_yaw has been followed
        self._power_on(self._t)
        self.stats.resets = 0

    # --- chip state ------------------------------------------------------------------------

    def _power_on(self, now: float) -> None:
        """registers.cpp resetRegisters + main.cpp setup (scalars 1, no offset, quick cal)."""
        self.mem = bytearray(regs.REGISTER_COUNT)
        self.mem[regs.PRODUCT_ID_REG] = self.product_id
        self.mem[regs.HW_VERSION] = 0x11
        self.mem[regs.FW_VERSION] = 0x10
        self.mem[regs.SIGNAL_PROCESS] = regs.SIGNAL_PROCESS_DEFAULT
        self._shadow = bytearray(regs.REGISTER_COUNT)
        self._written = [False] * regs.REGISTER_COUNT
        self._apply_at: float | None = None
        self._index = 0
        self.linear_scalar = self.angular_scalar = 1.0
        self.offset = (0.0, 0.0, 0.0)
        self._offset_inv = (0.0, 0.0, 0.0)
        self.sx = self.sy = self.sh = 0.0  # the sensor's own pose (firmware: the filters)
        self._host_prev: tuple[float, float, float] | None = None
        self.gyro_residual = self.gyro_bias_rps  # uncalibrated until the quick calibration
        self.imu_calibrations = 0
        self._t_frame = now
        self._start_calibration(now + 0.1, regs.POWER_UP_IMU_SAMPLES)

    def power_cycle(self) -> None:
        """Power off and on (also the end of a fault window): everything set is forgotten."""
        super().power_cycle()
        self._power_on(self._t)

    def _start_calibration(self, start: float, samples: int) -> None:
        self._cal_start = start
        self._cal_samples = max(1, samples)
        self._busy_until: float | None = start + self._cal_samples * _T
        self._cal_yaw_start: float | None = None  # set when the truth reaches ``start``
        self.mem[regs.IMU_CALIB] = samples

    def _end_calibration(self, t: float) -> None:
        """The blocking calibration ends at ``t`` (s, emulator clock)."""
        self._advance_truth(t)
        # the yaw during the calibration window counts as gyro offset (firmware: the mean)
        yaw_cal = self.true_yaw - (self._cal_yaw_start or self.true_yaw)
        duration = t - self._cal_start
        mean_rate = yaw_cal / duration if duration > 0 else 0.0
        noise = self._rng.gauss(0.0, self.gyro_noise_rps / math.sqrt(self._cal_samples))
        self.gyro_residual = -mean_rate + noise
        self.imu_calibrations += 1
        self.mem[regs.IMU_CALIB] = 0
        self._busy_until = None
        self._t_frame = t

    # --- time --------------------------------------------------------------------------------

    def _advance_truth(self, t: float) -> None:
        """Heading truth up to ``t`` while the loop is blocked (no update is made)."""
        if t <= self._t_yaw:
            return
        if self._cal_yaw_start is None and self._t_yaw <= self._cal_start <= t:
            self.true_yaw += self.heading_source.yaw(self._t_yaw, self._cal_start)
            self._t_yaw = self._cal_start
            self._cal_yaw_start = self.true_yaw  # the calibration's samples start here
        self.true_yaw += self.heading_source.yaw(self._t_yaw, t)
        self._t_yaw = t

    def run(self, now: float | None = None) -> None:
        """The firmware's main loop up to ``now``: host writes applied, 416 Hz updates."""
        if now is None:
            now = self.clock()
        while True:
            if self._busy_until is not None:
                if now < self._busy_until:
                    self._advance_truth(now)
                    left = math.ceil((self._busy_until - max(now, self._cal_start)) / _T)
                    self.mem[regs.IMU_CALIB] = max(1, min(self._cal_samples, left))
                    self.advance(now)  # the PAA5160 keeps counting meanwhile
                    return
                self._end_calibration(self._busy_until)
            t_next = self._t_frame + _T
            # a write that waited for a blocking calibration is applied when it ends
            t_apply = math.inf if self._apply_at is None else max(self._apply_at, self._t_frame)
            if min(t_next, t_apply) > now:
                self.advance(now)
                return
            if t_apply <= t_next:
                self._apply_host_writes(t_apply)
            else:
                self._update(t_next)

    def _update(self, t: float) -> None:
        """One sensorUpdate: PAA counts -> world-frame position, heading, registers."""
        self._t_frame = t
        self.advance(t)
        nx, ny = self.take_counts()
        self.take_flags()
        yaw = self.heading_source.yaw(self._t_yaw, t) if t > self._t_yaw else 0.0
        self._t_yaw = t
        self.true_yaw += yaw
        dh = self.angular_scalar * (yaw + self.gyro_residual * _T)
        hm = self.sh + dh / 2
        k = INCH_M / regs.PAA_CPI * self.linear_scalar
        ex, ey = nx * k, ny * k
        c, s = math.cos(hm), math.sin(hm)
        self.sx += c * ex - s * ey
        self.sy += s * ex + c * ey
        self.sh = wrap_pi(self.sh + dh)
        hx, hy, hh = self._host_pose()
        prev = self._host_prev or (hx, hy, hh)
        self._host_prev = (hx, hy, hh)
        vx, vy, vh = (hx - prev[0]) / _T, (hy - prev[1]) / _T, dh / _T
        out: list[int] = []
        for v in (
            hx / regs.POS_M_PER_LSB,
            hy / regs.POS_M_PER_LSB,
            hh / regs.HEADING_RAD_PER_LSB,
            vx / regs.VEL_MPS_PER_LSB,
            vy / regs.VEL_MPS_PER_LSB,
            vh / regs.VEL_RPS_PER_LSB,
        ):
            out += regs.int16_bytes(_to_int16(v))
        self.mem[regs.POSITION : regs.POSITION + 12] = bytes(out)
        burst = bytearray(regs.PAA_BURST_LEN)
        burst[regs.PAA_BURST_DX : regs.PAA_BURST_DX + 2] = bytes(regs.int16_bytes(nx))
        burst[regs.PAA_BURST_DY : regs.PAA_BURST_DY + 2] = bytes(regs.int16_bytes(ny))
        self.mem[regs.PAA_BURST : regs.PAA_BURST + regs.PAA_BURST_LEN] = burst
        status = self.mem[regs.STATUS] & ~regs.STATUS_WARN_OPTICAL
        if self.lifted or self.poor_surface:
            status |= regs.STATUS_WARN_OPTICAL
        self.mem[regs.STATUS] = status

    def _host_pose(self) -> tuple[float, float, float]:
        """The robot's pose from the sensor's (main.cpp: posHost from the filters + offset)."""
        ix, iy, ih = self._offset_inv
        c, s = math.cos(self.sh), math.sin(self.sh)
        return self.sx + ix * c - iy * s, self.sy + ix * s + iy * c, self.sh + ih

    def _pose_from(self, start: int) -> tuple[float, float, float] | None:
        """A pose the host wrote at ``start`` (six bytes), or None unless all six arrived."""
        flags = self._written[start : start + 6]
        for i in range(start, start + 6):
            self._written[i] = False
        if not all(flags):
            return None
        b = self._shadow
        return (
            regs.signed16(b[start], b[start + 1]) * regs.POS_M_PER_LSB,
            regs.signed16(b[start + 2], b[start + 3]) * regs.POS_M_PER_LSB,
            regs.signed16(b[start + 4], b[start + 5]) * regs.HEADING_RAD_PER_LSB,
        )

    def _apply_host_writes(self, t: float) -> None:
        """copyRegsFromHostShadow, in the firmware's order."""
        self._apply_at = None
        w, sh, mem = self._written, self._shadow, self.mem
        if w[regs.RESET]:
            w[regs.RESET] = False
            if sh[regs.RESET] & regs.RESET_TRACKING:
                ox, oy, oh = self.offset  # the host at the origin: the sensor at the offset
                self.sx, self.sy, self.sh = ox, oy, oh
                self._host_prev = None
            mem[regs.RESET] = 0
        if w[regs.SIGNAL_PROCESS]:
            w[regs.SIGNAL_PROCESS] = False
            mem[regs.SIGNAL_PROCESS] = sh[regs.SIGNAL_PROCESS]
        if w[regs.SELF_TEST]:
            w[regs.SELF_TEST] = False
            if sh[regs.SELF_TEST] & regs.SELF_TEST_START:
                mem[regs.SELF_TEST] = regs.SELF_TEST_PASS
        if w[regs.IMU_CALIB]:
            w[regs.IMU_CALIB] = False
            self._advance_truth(t)
            self._start_calibration(t, sh[regs.IMU_CALIB])
            if any(w):  # the rest waits for the blocking calibration to end
                self._apply_at = self._busy_until
            return
        for reg in (regs.SCALAR_LINEAR, regs.SCALAR_ANGULAR):
            if w[reg]:
                w[reg] = False
                mem[reg] = sh[reg]
                value = regs.decode_scalar(sh[reg])
                if reg == regs.SCALAR_LINEAR:
                    self.linear_scalar = value
                else:
                    self.angular_scalar = value
        host = self._pose_from(regs.POSITION)
        off = self._pose_from(regs.OFFSET)
        if host is None and off is None:
            return
        if host is None:  # the robot's pose as last computed, under the old offset
            host = self._host_pose()
        if off is not None:
            self.offset = off
            c, s = math.cos(off[2]), math.sin(off[2])
            self._offset_inv = (-off[0] * c - off[1] * s, off[0] * s - off[1] * c, -off[2])
        # transformPose(host, offset): the sensor's pose for the host pose
        ox, oy, oh = self.offset
        c, s = math.cos(host[2]), math.sin(host[2])
        self.sx, self.sy = ox * c - oy * s + host[0], ox * s + oy * c + host[1]
        self.sh = wrap_pi(oh + host[2])
        self._host_prev = None

    # --- I2C ----------------------------------------------------------------------------------

    def _transfer_start(self, addr: int, now: float) -> str | None:
        mode = self.fault_now(now)
        if mode == "raise":
            raise I2cError("I2C transfer failed: Remote I/O error (emulated fault)")
        if mode == "no_response" or addr != self.address:
            raise I2cNoAckError(
                f"no chip acknowledges address {addr:#04x} (emulated OTOS at "
                f"{self.address:#04x}{', faulted' if mode else ''})"
            )
        self.run(now)
        return mode

    def _host_write(self, data: bytes, now: float) -> None:
        if not data:
            return
        self._index = data[0]
        for byte in data[1:]:
            if self._index < regs.REGISTER_COUNT:
                self._shadow[self._index] = byte
                self._written[self._index] = True
                self._index += 1
        if len(data) > 1 and self._apply_at is None:
            self._apply_at = now + self.write_latency_s

    def write_read(self, addr: int, write: bytes, read_len: int) -> bytes:
        now = self.clock()
        mode = self._transfer_start(addr, now)
        self._host_write(bytes(write), now)
        out = []
        for _ in range(read_len):
            out.append(self.mem[self._index] if self._index < regs.REGISTER_COUNT else 0)
            if self._index < regs.REGISTER_COUNT:
                self._index += 1
        if mode == "corrupt":
            self.corrupt(out)
        if self.record:
            self.stats.history.append((addr, bytes(write), bytes(out)))
        return bytes(out)

    def write(self, addr: int, data: bytes) -> None:
        now = self.clock()
        self._transfer_start(addr, now)
        self._host_write(bytes(data), now)
        if self.record:
            self.stats.history.append((addr, bytes(data), b""))

    def close(self) -> None:
        pass
