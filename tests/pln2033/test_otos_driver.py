"""The OTOS driver against its register-level emulator, byte by byte."""

from __future__ import annotations

import math

import pytest
from fakes import FakeClock

from pln2033.angles import wrap_pi
from pln2033.chips import chip_info, make_driver, make_emulator
from pln2033.errors import (
    FirmwareError,
    InvalidCpiError,
    ProductIdError,
    SensorError,
    SensorNotRespondingError,
)
from pln2033.motion import ConstantVelocity, Stationary
from pln2033.otos import OTOS, OTOS_INFO, ConstantYawRate, EmulatedOTOS, InvalidSettingError, regs
from pln2033.otos.driver import quantise_offset
from pln2033.sensor import INCH_M, SensorDriver


def make(motion=None, heading=None, record=False, **options):
    ft = FakeClock()
    emu = EmulatedOTOS(motion=motion, clock=ft, heading_source=heading, record=record)
    drv = OTOS(emu, name="/dev/i2c-2", sleep=ft.sleep, clock=ft, **options)
    return ft, emu, drv


def writes(emu):
    return [(w[0], w[1]) for w in emu.stats.history if w[2] == b""]


def test_registry_builds_the_otos_and_it_is_a_sensor_driver():
    emu = make_emulator("otos", clock=FakeClock())
    drv = make_driver("otos", emu, name="/dev/i2c-2")
    assert isinstance(drv, SensorDriver)
    info = chip_info("otos")
    assert info is OTOS_INFO
    assert info.bus == "i2c" and info.cpi.fixed and info.firmware == ""
    assert info.max_speed_mps == 2.5 and info.quality_threshold == 1
    assert info.low_quality(0) and not info.low_quality(1)


def test_bring_up_bytes_and_what_the_chip_holds_after_it():
    ft, emu, drv = make(
        record=True, linear_scalar=0.95, angular_scalar=1.013, offset=(0.05, -0.1, 0.2)
    )
    drv.initialise(1000)
    assert drv.versions == "hw 1.1, fw 1.0"
    # the first transfer reads the product id: pointer 0x00, one byte
    assert emu.stats.history[0] == (0x17, b"\x00", b"\x5f")
    w = writes(emu)
    assert w[0] == (0x17, b"\x06\xff")  # IMU calibration, 255 samples
    assert w[1] == (0x17, b"\x0e\x0f")  # signal process: the power-up bits, all on
    assert w[2] == (0x17, bytes([0x04, (-50) & 0xFF, 13]))  # scalars: int8 of (s-1)/0.001
    # offset: x 0.05 m = 164 LSB, y -0.1 m = -328, h 0.2 rad = 2086 (int16 LE)
    assert w[3] == (0x17, bytes([0x10, 164, 0, 0xB8, 0xFE, 0x26, 0x08]))
    assert w[4] == (0x17, b"\x07\x01")  # reset tracking
    assert emu.linear_scalar == 0.95 and emu.angular_scalar == 1.013
    assert emu.offset[0] == pytest.approx(0.05, abs=2e-4)
    assert emu.offset[2] == pytest.approx(0.2, abs=1e-4)
    assert emu.imu_calibrations == 2  # power-up quick one, then the driver's
    # 100 ms + 64 samples at power-up, then 255 x 2.4 ms: the robot must be still that long
    assert 0.85 < ft.t < 0.95
    assert drv.get_scalars() == (0.95, 1.013)


def test_wrong_product_id_says_what_was_read_expected_and_how_to_override():
    ft = FakeClock()
    emu = EmulatedOTOS(clock=ft, product_id=0x42)
    drv = OTOS(emu, name="/dev/i2c-1", sleep=ft.sleep, clock=ft)
    with pytest.raises(ProductIdError) as e:
        drv.initialise(1000)
    msg = str(e.value)
    assert "0x42" in msg and "0x5f" in msg and "expected_product_id" in msg and "0x17" in msg
    assert isinstance(e.value, SensorNotRespondingError)
    OTOS(emu, sleep=ft.sleep, clock=ft, expected_product_id=0x42, imu_samples=0).initialise(1000)


def test_missing_chip_at_the_address_is_a_no_ack_error():
    ft = FakeClock()
    emu = EmulatedOTOS(clock=ft, address=0x18)
    with pytest.raises(SensorNotRespondingError, match=r"i2cdetect|acknowledges"):
        OTOS(emu, sleep=ft.sleep, clock=ft).initialise(1000)


def test_scalars_and_offset_are_reapplied_after_a_power_cycle():
    _ft, emu, drv = make(linear_scalar=1.02, angular_scalar=0.99, offset=(0.0, 0.1, 0.0))
    drv.initialise(1000)
    assert (emu.linear_scalar, emu.angular_scalar) == (1.02, 0.99)
    emu.power_cycle()
    assert (emu.linear_scalar, emu.angular_scalar) == (1.0, 1.0)  # the chip forgot them
    assert emu.offset == (0.0, 0.0, 0.0)
    assert drv.get_scalars() == (1.0, 1.0)
    drv.initialise(1000)  # what the node does at every start
    assert (emu.linear_scalar, emu.angular_scalar) == (1.02, 0.99)
    assert emu.offset[1] == pytest.approx(0.1, abs=2e-4)


@pytest.mark.parametrize(
    ("linear", "angular", "words"),
    [
        (1.2, 1.0, "linear scalar 1.2 is out of range"),
        (1.0, 0.8, "angular scalar 0.8"),
        (float("nan"), 1.0, "out of range"),
        ("1", 1.0, "must be a number"),
    ],
)
def test_out_of_range_scalars_are_refused_with_the_range_and_nothing_is_written(
    linear, angular, words
):
    _ft, emu, drv = make(record=True)
    drv.initialise(1000)
    n = len(writes(emu))
    with pytest.raises(InvalidSettingError) as e:
        drv.set_scalars(linear, angular)
    assert words in str(e.value) and "0.872..1.127" in str(e.value)
    assert isinstance(e.value, ValueError)
    assert len(writes(emu)) == n
    with pytest.raises(InvalidSettingError):
        OTOS(emu, linear_scalar=0.5)


def test_scalar_encoding_ends_and_rounding():
    assert regs.encode_scalar(0.872) == 0x80 and regs.decode_scalar(0x80) == 0.872
    assert regs.encode_scalar(1.127) == 0x7F and regs.decode_scalar(0x7F) == 1.127
    assert regs.encode_scalar(0.995) == (-5) & 0xFF  # rounds (the Arduino library truncates)
    assert regs.scalar_problem(0.8719, "linear") and not regs.scalar_problem(1.0, "linear")


def test_offset_out_of_range_is_refused():
    _ft, emu, drv = make()
    with pytest.raises(InvalidSettingError, match=r"\+-10\.000 m"):
        drv.set_offset(12.0, 0.0, 0.0)
    with pytest.raises(InvalidSettingError, match="three numbers"):
        OTOS(emu, offset=(1.0, 2.0))


def test_a_heading_of_plus_and_minus_pi_reaches_the_chip_as_minus_pi():
    # The one wrap (pln2033.angles) keeps +pi and maps -pi to +pi; the int16 heading register
    # holds [-pi, pi), and +pi (32768 LSB) is written as 0x8000 = -pi, as the firmware wraps.
    assert wrap_pi(math.pi) == math.pi and wrap_pi(-math.pi) == math.pi
    for h in (math.pi, -math.pi):
        _ft, emu, drv = make(record=True, offset=(0.0, 0.0, h))
        drv.initialise(1000)
        assert drv.offset.h == math.pi
        assert writes(emu)[3] == (0x17, bytes([0x10, 0, 0, 0, 0, 0x00, 0x80]))
        assert emu.offset[2] == -math.pi  # what the chip holds
        assert quantise_offset(drv.offset).h == -math.pi


def test_pose_burst_decodes_the_int16_units():
    _ft, emu, drv = make(record=True)
    drv.initialise(1000)
    # the chip's bytes, as the firmware writes them (status, then 0x20..0x2B)
    emu.mem[regs.STATUS] = 0x02
    raw = [16384, -3277, -16384, 6554, -3277, 1000]
    emu.mem[0x20:0x2C] = b"".join(int.to_bytes(v & 0xFFFF, 2, "little") for v in raw)
    emu._t_frame = 1e9  # no update overwrites them for this read
    r = drv.read_pose()
    assert emu.stats.history[-1][:2] == (0x17, b"\x1f")  # one transfer from 0x1F
    assert len(emu.stats.history[-1][2]) == 13
    assert r.status == 0x02
    assert r.pose.x == pytest.approx(5.0)  # 16384 x 10 m / 32768
    assert r.pose.y == pytest.approx(-1.0, abs=1e-4)
    assert r.pose.h == pytest.approx(-math.pi / 2)
    assert r.velocity.x == pytest.approx(1.0, abs=1e-4)  # 6554 x 5 m/s / 32768
    assert r.velocity.y == pytest.approx(-0.5, abs=1e-4)
    assert r.velocity.h == pytest.approx(1000 * math.radians(2000) / 32768)


def test_counts_follow_the_true_motion_with_offset_scalar_and_rotation():
    ft, emu, drv = make(linear_scalar=0.95, angular_scalar=1.01, offset=(0.05, -0.1, 0.2))
    drv.initialise(1000)
    emu.motion = ConstantVelocity(0.1, 0.3)
    emu.heading_source = ConstantYawRate(0.5)
    c0 = (emu.stats.counted_x, emu.stats.counted_y)
    sx = sy = 0
    for _ in range(2000):
        ft.t += 0.001
        m = drv.read_motion()
        sx += m.dx
        sy += m.dy
        assert m.quality == 1 and not m.lifted
    # the PAA5160's counts at 20 000 CPI are the truth; the driver's at 1000 CPI
    true_x = (emu.stats.counted_x - c0[0]) / 20
    true_y = (emu.stats.counted_y - c0[1]) / 20
    assert true_x == pytest.approx(0.2 / INCH_M * 1000, abs=1)
    # within one 2.4 ms update of motion (0.3 m/s x 2.4 ms = 28 counts)
    assert sx == pytest.approx(true_x, abs=30)
    assert sy == pytest.approx(true_y, abs=30)
    # the on-chip pose comes with it, no second transfer
    assert drv.last_pose is not None
    assert drv.last_pose.pose.h == pytest.approx(1.01 * 1.0, abs=0.02)  # 2 s at 0.5 rad/s


@pytest.mark.parametrize("left", [0x0B, 0x0F])
def test_signal_process_bits_left_by_another_client_are_set_back_at_start(left):
    """A client such as SparkFun's may leave enRot clear (0x0B); the chip keeps it until
    power-off and integrates the sensor-frame velocity. Before the driver wrote 0x0F at
    start, its counts on a 2 s turn at 1 rad/s read (16720, 10718) for a truth of (0, 23622)."""
    ft, emu, drv = make()
    ft.t = 0.3
    emu.write(0x17, bytes([regs.SIGNAL_PROCESS, left]))
    ft.t += 0.001
    assert emu.write_read(0x17, bytes([regs.SIGNAL_PROCESS]), 1) == bytes([left])
    drv.initialise(1000)
    assert emu.mem[regs.SIGNAL_PROCESS] == regs.SIGNAL_PROCESS_DEFAULT
    emu.motion = ConstantVelocity(0.0, 0.3)
    emu.heading_source = ConstantYawRate(1.0)
    c0 = (emu.stats.counted_x, emu.stats.counted_y)
    sx = sy = 0
    for _ in range(2000):
        ft.t += 0.001
        m = drv.read_motion()
        sx, sy = sx + m.dx, sy + m.dy
    true_x = (emu.stats.counted_x - c0[0]) / 20  # the PAA5160's 20 000 CPI
    true_y = (emu.stats.counted_y - c0[1]) / 20
    assert (true_x, true_y) == pytest.approx((0.0, 0.6 / INCH_M * 1000), abs=1)
    # within two of the chip's 2.4 ms updates (28 counts each at 0.3 m/s)
    assert sx == pytest.approx(true_x, abs=56) and sy == pytest.approx(true_y, abs=56)


def test_a_signal_process_write_that_does_not_stick_is_a_clear_error():
    ft, emu, drv = make(imu_samples=0)
    ft.t = 0.3
    emu.write_read = lambda addr, write, n, _real=emu.write_read: (  # type: ignore[method-assign]
        b"\x0b" if write == bytes([regs.SIGNAL_PROCESS]) else _real(addr, write, n)
    )
    with pytest.raises(SensorError, match=r"signal-process register reads back 0x0b, wrote 0x0f"):
        drv.initialise(1000)


def test_counts_survive_the_position_registers_wrapping_at_10_m():
    ft, emu, drv = make(imu_samples=0)
    ft.t = 0.3  # after the power-up calibration (100 ms + 64 x 2.4 ms)
    drv.initialise(1000)
    emu.motion = ConstantVelocity(0.0, 2.0)
    y0 = emu.stats.counted_y
    total = 0
    for _ in range(800):  # 8 s at 2 m/s: 16 m, past +10 m
        ft.t += 0.01
        total += drv.read_motion().dy
    true_y = (emu.stats.counted_y - y0) / 20
    assert true_y > 15.9 / INCH_M * 1000
    assert total == pytest.approx(true_y, abs=200)  # one update's motion at 2 m/s = 190
    assert drv.last_pose.pose.y == pytest.approx(true_y / 1000 * INCH_M, abs=0.01)


def lift_run(speed):
    ft = FakeClock()
    emu = EmulatedOTOS(motion=ConstantVelocity(0.0, speed), clock=ft, lift_windows=[(2.0, 2.5)])
    drv = OTOS(emu, sleep=ft.sleep, clock=ft, imu_samples=0)
    drv.initialise(1000)
    seen = []
    while ft.t < 3.0:
        ft.t += 0.01
        m = drv.read_motion()
        seen.append((ft.t, m.quality, m.status, m.dy))
    return emu, seen


def test_a_lift_at_speed_sets_the_tracking_warning_and_the_imu_carries_on():
    # the firmware's rule: measured |vx|+|vy| < 0.25 m/s while its estimate is > 0.5 m/s
    emu, seen = lift_run(1.0)
    low = [t for t, q, s, dy in seen if q == 0]
    assert low and 2.0 <= low[0] <= 2.02 and 2.49 <= low[-1] <= 2.52
    assert all(s & regs.STATUS_WARN_OPTICAL for t, q, s, dy in seen if q == 0)
    # IMU only: the velocity held (the accelerometer reads 0), so the pose keeps following
    lifted = sum(dy for t, q, s, dy in seen if 2.03 <= t <= 2.48)
    assert lifted == pytest.approx(0.46 / INCH_M * 1000, rel=0.01)
    assert emu.stats.lift_events == 1


def test_a_lift_below_the_firmware_threshold_sets_no_warning_and_the_pose_stops():
    emu, seen = lift_run(0.3)  # the estimate falls with the measurement: never above 0.5 m/s
    assert all(q == 1 and not s & regs.STATUS_WARN_OPTICAL for t, q, s, dy in seen)
    lifted = sum(dy for t, q, s, dy in seen if 2.03 <= t <= 2.48)
    assert lifted == 0
    assert emu.stats.lift_events == 1


@pytest.mark.parametrize(("speed", "warn"), [(0.3, False), (0.8, True)])
def test_a_poor_surface_follows_the_same_firmware_rule(speed, warn):
    ft = FakeClock()
    emu = EmulatedOTOS(
        motion=ConstantVelocity(0.0, speed), clock=ft, low_quality_windows=[(2.0, 2.03)]
    )
    drv = OTOS(emu, sleep=ft.sleep, clock=ft, imu_samples=0)
    drv.initialise(1000)
    seen = []
    while ft.t < 2.2:
        ft.t += 0.001
        m = drv.read_motion()
        seen.append((ft.t, m.quality, m.dy))
    low = [t for t, q, dy in seen if q == 0]
    window = sum(dy for t, q, dy in seen if 2.003 <= t <= 2.03)
    if warn:  # the IMU carries the 0.8 m/s through the 30 ms: counts keep coming
        assert low and 2.0 <= low[0] <= 2.004 and low[-1] <= 2.034
        assert window == pytest.approx(speed * 0.027 / INCH_M * 1000, rel=0.05)
    else:  # no warning, and the pose stops
        assert low == [] and window == 0
    assert emu.stats.low_quality_events == 1


def test_heading_drifts_at_rest_without_calibration_and_not_after_it():
    ft, emu, drv = make(motion=Stationary(), imu_samples=0)
    emu.gyro_noise_rps = 0.0
    # turning while the power-up calibration runs: the gyro offset learns that rate
    emu.heading_source = ConstantYawRate(0.2)
    ft.t = 0.3
    drv.initialise(1000)
    emu.heading_source = ConstantYawRate(0.0)
    h0 = drv.read_pose().pose.h
    ft.t += 10.0
    drift = drv.read_pose().pose.h - h0
    assert drift == pytest.approx(-2.0, abs=0.05)  # -0.2 rad/s residual for 10 s
    drv.calibrate_imu(255)  # still now
    drv.reset_tracking()
    h0 = drv.read_pose().pose.h
    ft.t += 10.0
    assert abs(drv.read_pose().pose.h - h0) < 1e-3


def test_a_tracking_reset_returns_the_pose_to_the_origin():
    ft, _emu, drv = make(motion=ConstantVelocity(0.1, 0.0), imu_samples=0)
    drv.initialise(1000)
    ft.t += 1.0
    assert drv.read_pose().pose.x == pytest.approx(0.1, abs=1e-3)
    drv.reset_tracking()
    assert abs(drv.read_pose().pose.x) < 2e-3


def test_cpi_is_fixed_and_firmware_refused():
    _ft, _emu, drv = make()
    assert drv.get_cpi() == (1000, 1000)
    drv.set_cpi(1000)
    with pytest.raises(InvalidCpiError, match="fixed at 1000"):
        drv.set_cpi(800)
    with pytest.raises(FirmwareError, match="takes no firmware"):
        drv.load_firmware([1, 2])
    with pytest.raises(FirmwareError):
        drv.initialise(1000, firmware=[1])


def test_register_dump_names_and_values_in_one_read():
    ft, emu, drv = make(record=True, linear_scalar=1.01)
    drv.initialise(1000)
    emu.motion = ConstantVelocity(0.0, 0.1)
    ft.t += 0.5
    n = len(emu.stats.history)
    motion, values = drv.read_all_registers()
    assert len(emu.stats.history) == n + 1
    assert emu.stats.history[-1][1] == b"\x00" and len(emu.stats.history[-1][2]) == 0x5C
    assert (motion.dx, motion.dy) == (0, 0)
    assert values["product_id"] == 0x5F and values["scalar_linear"] == 10
    assert values["signal_process"] == 0x0F
    assert list(values)[:3] == ["product_id", "hw_version", "fw_version"]
    # the raw PAA5160 delta of the latest update: 0.1 m/s x 2.4 ms at 20 000 CPI = 189 counts
    dy = values["paa_burst_04"] | (values["paa_burst_05"] << 8)
    assert 185 <= dy <= 192
    assert values["offset_x"] == 0  # firmware 1.0 never makes the offset readable
    assert all(0 <= v <= 0xFFFF for v in values.values())


def test_a_host_write_is_seen_by_the_next_transaction_however_soon_but_not_during_a_calibration():
    """The firmware applies host writes on its next loop pass, long before the host's next
    address arrives: no latency a transaction can see (write_latency_s only times a write
    no transaction follows). A blocking IMU calibration holds the loop: the write waits."""
    ft, emu, _drv = make()
    ft.t = 0.3
    emu.write(0x17, bytes([regs.SCALAR_LINEAR, 50]))
    assert emu.write_read(0x17, bytes([regs.SCALAR_LINEAR]), 1) == bytes([50])  # same instant
    emu.write(0x17, bytes([regs.IMU_CALIB, 100]))  # 100 x 2.4 ms with the loop blocked
    ft.t += 0.001
    emu.write(0x17, bytes([regs.SCALAR_LINEAR, 20]))
    ft.t += 0.001
    assert emu.write_read(0x17, bytes([regs.SCALAR_LINEAR]), 1) == bytes([50])
    ft.t += 0.25
    assert emu.write_read(0x17, bytes([regs.IMU_CALIB]), 1) == b"\x00"
    assert emu.write_read(0x17, bytes([regs.SCALAR_LINEAR]), 1) == bytes([20])


def test_invalid_imu_samples_is_refused():
    _ft, emu, drv = make()
    with pytest.raises(InvalidSettingError, match=r"0 \(skip\) .. 255"):
        OTOS(emu, imu_samples=300)
    with pytest.raises(InvalidSettingError):
        drv.calibrate_imu(0)


def test_motion_during_a_blocking_calibration_overflows_the_paa_counter():
    # the firmware's loop stops for samples x 2.4 ms; the PAA5160's 16-bit delta overflows
    # when the sensor moves more than 41 mm meanwhile: calibrate standing still
    _ft, emu, drv = make(motion=ConstantVelocity(0.0, 1.0))
    drv.initialise(1000)
    assert emu.stats.overflow_events >= 1
