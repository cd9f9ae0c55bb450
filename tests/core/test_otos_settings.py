"""The OTOS's scalars and offset from the calibration (mm_pc.core.otos_settings)."""

from __future__ import annotations

import math

import pytest
from fakes import FakeClock

from mm_pc.core.calibration import Calibration, SensorCalibration
from mm_pc.core.geometry import SensorMount
from mm_pc.core.otos_settings import angular_scalar, linear_scalar, otos_settings
from pln2033.chips import make_driver, make_emulator

DEV = "/dev/i2c-2"


def test_linear_scalar_is_the_geometric_mean_and_refuses_what_the_chip_cannot_take():
    assert linear_scalar(1.03, 1.03) == 1.03
    assert linear_scalar(0.98, 1.02) == pytest.approx(math.sqrt(0.98 * 1.02), abs=1e-3)
    with pytest.raises(ValueError, match=r"out of range.*height above the floor"):
        linear_scalar(1.2, 1.2)


def test_angular_scalar_from_a_spin_test():
    assert angular_scalar(10 * math.tau, 10 * math.tau / 1.01) == 1.01
    with pytest.raises(ValueError, match="other way"):
        angular_scalar(math.tau, -math.tau)
    with pytest.raises(ValueError, match="non-zero"):
        angular_scalar(math.tau, 0.0)
    with pytest.raises(ValueError, match="out of range"):
        angular_scalar(math.tau, math.tau / 1.5)


def test_settings_take_the_fitted_scale_position_and_yaw_into_the_otos_frame():
    cal = Calibration({DEV: SensorCalibration(angle_offset=0.02, scale_x=1.04, scale_y=1.04,
                                              x=0.05, y=-0.03)})  # fmt: skip
    s = otos_settings(cal, DEV, SensorMount(0.0, 0.0, 0.1), angular=0.99)
    assert s.linear_scalar == 1.04 and s.angular_scalar == 0.99
    assert s.offset == pytest.approx((0.03, 0.05, 0.12))  # x right, y forward, CCW
    # no calibration of that sensor: identity scale, the configured mount
    s = otos_settings(Calibration(), DEV, SensorMount(0.1, 0.02, 0.0))
    assert (s.linear_scalar, s.offset) == (1.0, pytest.approx((-0.02, 0.1, 0.0)))


def test_the_driver_writes_the_settings_at_every_start():
    cal = Calibration({DEV: SensorCalibration(scale_x=0.97, scale_y=0.97, x=0.0, y=0.0)})
    s = otos_settings(cal, DEV, SensorMount(0.0, 0.0, 0.0), angular=1.02)
    ft = FakeClock()
    emu = make_emulator("otos", clock=ft)
    drv = make_driver("otos", emu, name=DEV, sleep=ft.sleep, clock=ft, **s.driver_options())
    drv.initialise(1000)
    assert drv.get_scalars() == (0.97, 1.02)
    emu.power_cycle()  # the chip forgets them ...
    assert drv.get_scalars() == (1.0, 1.0)
    drv.initialise(1000)  # ... and the next start writes them again
    assert drv.get_scalars() == (0.97, 1.02)


def test_the_command_prints_chip_options_and_refuses_bad_input_with_exit_2(tmp_path, capsys):
    from mm_pc.core.otos_settings import main

    path = tmp_path / "calibration.yaml"
    Calibration({DEV: SensorCalibration(scale_x=1.02, scale_y=1.02, x=0.0, y=0.01)}).save(path)
    assert main([str(path), "--device", DEV, "--spin", "62.832,62.2"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out == [
        "chip_options:",
        '  - "otos.linear_scalar=1.020"',
        '  - "otos.angular_scalar=1.010"',
        '  - "otos.offset=-0.0100,0.0000,0.0000"',
    ]
    for argv, words in (
        ([str(tmp_path / "none.yaml"), "--device", DEV], "none.yaml"),
        ([str(path), "--device", DEV, "--mount", "1,2"], "--mount must be 3"),
        ([str(path), "--device", DEV, "--spin", "6.28,-6.28"], "other way"),
    ):
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert err.startswith("mm-otos-settings: ") and words in err and "Traceback" not in err
    big = tmp_path / "big.yaml"
    Calibration({DEV: SensorCalibration(scale_x=1.3, scale_y=1.3)}).save(big)
    assert main([str(big), "--device", DEV]) == 2
    assert "height above the floor" in capsys.readouterr().err
