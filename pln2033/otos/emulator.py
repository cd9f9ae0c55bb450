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
sensor-frame motion into the PAA5160's counts at 20 000 CPI times ``paa_resolution`` (lifts,
poor surface, noise, faults as for every chip). Each update follows sensorUpdate: the
optical velocity (counts x 25.4 um / 20 000 / 2.4 ms), divided by ``paa_resolution`` when
the lookup-table bit is set (the table is modelled as the exact inverse of the chip's
resolution error), times the linear scalar; turned into the world frame by the heading
when the rotation bit is set (else integrated as it is, as the firmware does); the
accelerometer reads the true sensor-frame acceleration (change of the true velocity
between updates; no gravity, tilt or centripetal terms). With the accelerometer bit set the
firmware's rejection rule runs: measured |vx|+|vy| < 0.25 m/s while the estimate is above
0.5 m/s (the filters' velocity, as in the firmware) sets the optical warning and the
position follows the filters' velocity, carried by the accelerometer alone. The
heading comes from ``heading_source`` scaled by the angular scalar, plus the gyro's residual
bias: ``gyro_bias_rps`` until the first calibration, then what the calibration left
(``gyro_noise_rps`` / sqrt(samples), minus the mean true yaw rate during it when the robot
turned while calibrating): a heading drift at rest, as users report.

Position and velocity are the lag-free integration of those measurements; acceleration and
the nine standard deviations come from the firmware's own Kalman filters
(:mod:`pln2033.otos.kalman`) run alongside on the same measurements, with its variances (times
the variance bit). Simplifications (docs/sensors.md, OTOS section): position and velocity
without the filters' lag, a constant resolution error in place of the speed-dependent
table, no tilt (warnTiltAngle stays 0), the PAA burst holds only the deltas (bytes 2..5),
the raw LSM6DSO registers stay 0.
"""

from __future__ import annotations

import math
from typing import Any, Protocol

from ..angles import wrap_pi
from ..emulated import CountingCore
from ..i2c import I2cError, I2cNoAckError
from ..motion import MotionSource
from ..sensor import INCH_M
from . import kalman, regs

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
        write_latency_s: how long the main loop takes to apply a host write; a write is
            applied before the next transaction in any case (the loop passes many times
            while the host sends the next address), unless a calibration blocks the loop.
        paa_resolution: the PAA5160's true resolution over its nominal 20 000 CPI (1.0:
            exact). SparkFun's lookup table corrects it (signal-process bit 0); clear the
            bit and the position reads the true distance times this.
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
        write_latency_s: float = 0.0001,
        paa_resolution: float = 1.0,
        **core: Any,
    ) -> None:
        super().__init__(
            motion=motion,
            **core,
            cpi=regs.PAA_CPI * paa_resolution,
            counter_bits=16,
        )
        self.paa_resolution = paa_resolution
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
        self.vx = self.vy = 0.0  # the sensor's velocity estimate, world frame (m/s)
        self._v_true: tuple[float, float] | None = None  # true sensor-frame velocity, last update
        self.kf_x = kalman.AxisFilter(kalman.Q_LINEAR)
        self.kf_y = kalman.AxisFilter(kalman.Q_LINEAR)
        self.kf_h = kalman.AxisFilter(kalman.Q_HEADING)
        self._host_prev: tuple[float, float, float] | None = None
        self.gyro_residual = self.gyro_bias_rps  # uncalibrated until the quick calibration
        self.imu_calibrations = 0
        self._t_frame = now
        self._start_calibration(now + 0.1, regs.POWER_UP_IMU_SAMPLES)

    @property
    def t_update(self) -> float:
        """When the latest 2.4 ms update ran (s, emulator clock): the registers' moment."""
        return self._t_frame

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

    def _set_filters(self) -> None:
        """The filters' positions follow a pose the host wrote (copyRegsFromHostShadow)."""
        self.kf_x.x[0], self.kf_y.x[0], self.kf_h.x[0] = self.sx, self.sy, self.sh

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
        """One sensorUpdate: PAA counts and IMU -> pose, velocity, filters, registers."""
        self._t_frame = t
        self.advance(t)
        nx, ny = self.take_counts()
        self.take_flags()
        yaw = self.heading_source.yaw(self._t_yaw, t) if t > self._t_yaw else 0.0
        self._t_yaw = t
        self.true_yaw += yaw
        sp = self.mem[regs.SIGNAL_PROCESS]
        var = 1.0 if sp & regs.SP_VAR else 0.0
        # the optical velocity, sensor frame (m/s)
        k = INCH_M / regs.PAA_CPI / _T
        mx, my = nx * k, ny * k
        if sp & regs.SP_LUT and max(abs(mx), abs(my)) < regs.LUT_LIMIT_IPS * INCH_M:
            mx, my = mx / self.paa_resolution, my / self.paa_resolution
        mx, my = mx * self.linear_scalar, my * self.linear_scalar
        ax, ay = self._accelerometer(t)
        # heading: the gyro rate (true yaw plus the residual bias) times the angular scalar
        wh = self.angular_scalar * (yaw / _T + self.gyro_residual)
        dh = wh * _T
        self.kf_h.predict(_T)
        self.kf_h.update(wh, kalman.R_GYRO, 1)
        if sp & regs.SP_ROT:  # by the mid-update heading: no lag in the emulator
            hm = self.sh + dh / 2
            c, s = math.cos(hm), math.sin(hm)
            mx, my = c * mx - s * my, s * mx + c * my
            ax, ay = c * ax - s * ay, s * ax + c * ay
        self.sh = wrap_pi(self.sh + dh)
        status = self.mem[regs.STATUS]
        self.kf_x.predict(_T)
        self.kf_y.predict(_T)
        if sp & regs.SP_ACC:
            self.kf_x.update(ax, kalman.R_ACC * var, 2)
            self.kf_y.update(ay, kalman.R_ACC * var, 2)
            rejected = (
                abs(mx) + abs(my) < regs.REJECT_MEASURED_MPS
                and abs(self.kf_x.x[1]) + abs(self.kf_y.x[1]) > regs.REJECT_ESTIMATED_MPS
            )
            if rejected:  # IMU only: the filters' velocity, carried by the accelerometer
                status |= regs.STATUS_WARN_OPTICAL
                mx, my = self.kf_x.x[1], self.kf_y.x[1]
            else:
                status &= ~regs.STATUS_WARN_OPTICAL
                self.kf_x.update(mx, kalman.R_VEL * var, 1)
                self.kf_y.update(my, kalman.R_VEL * var, 1)
        else:  # the warning bit keeps its last value: the firmware does not touch it
            self.kf_x.update(mx, kalman.R_VEL * var, 1)
            self.kf_y.update(my, kalman.R_VEL * var, 1)
        self.vx, self.vy = mx, my
        self.sx += mx * _T
        self.sy += my * _T
        self.mem[regs.STATUS] = status
        hx, hy, hh = self._host_pose()
        prev = self._host_prev or (hx, hy, hh)
        self._host_prev = (hx, hy, hh)
        vx, vy, vh = (hx - prev[0]) / _T, (hy - prev[1]) / _T, dh / _T
        out: list[int] = []
        for v, lsb in zip(
            (hx, hy, hh, vx, vy, vh, *self._host_acceleration(), *self._std_devs()),
            regs.POSE_BLOCK_LSB * 2,
            strict=True,
        ):
            out += regs.int16_bytes(_to_int16(v / lsb))
        self.mem[regs.POSITION : regs.POSITION + len(out)] = bytes(out)
        burst = bytearray(regs.PAA_BURST_LEN)
        burst[regs.PAA_BURST_DX : regs.PAA_BURST_DX + 2] = bytes(regs.int16_bytes(nx))
        burst[regs.PAA_BURST_DY : regs.PAA_BURST_DY + 2] = bytes(regs.int16_bytes(ny))
        self.mem[regs.PAA_BURST : regs.PAA_BURST + regs.PAA_BURST_LEN] = burst

    def _accelerometer(self, t: float) -> tuple[float, float]:
        """The true sensor-frame acceleration over the update ending at ``t`` (m/s^2)."""
        dx, dy = self.motion.displacement(t - _T, t)
        v = (dx / _T, dy / _T)
        prev = self._v_true or v
        self._v_true = v
        return (v[0] - prev[0]) / _T, (v[1] - prev[1]) / _T

    def _host_acceleration(self) -> tuple[float, float, float]:
        """The filters' acceleration moved to the host (main.cpp accHost, its terms as written)."""
        ix, iy, _ = self._offset_inv
        c, s = math.cos(self.sh), math.sin(self.sh)
        w, alpha = self.kf_h.x[1], self.kf_h.x[2]
        cen = math.hypot(ix, iy) * w * w
        return (
            self.kf_x.x[2] + (-ix * s - iy * c) * alpha - (cen * c - cen * s),
            self.kf_y.x[2] + (ix * c - iy * s) * alpha - (cen * s + cen * c),
            alpha,
        )

    def _std_devs(self) -> tuple[float, ...]:
        """sqrt of the filters' covariance diagonals: position, velocity, acceleration (x, y, h)."""
        out: list[float] = []
        for i in range(3):
            for f in (self.kf_x, self.kf_y, self.kf_h):
                out.append(math.sqrt(max(0.0, f.p[i][i])))
        return tuple(out)

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
                self.vx = self.vy = 0.0
                for f in (self.kf_x, self.kf_y, self.kf_h):
                    f.reset()
                self._set_filters()
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
        self._set_filters()
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
        if self._apply_at is not None and self._apply_at > now:
            # the loop applies a write on its next pass, long before the host has sent the
            # next address (unless a blocking calibration holds the loop: run() waits then)
            self._apply_at = now
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
