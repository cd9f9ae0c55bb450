"""The driver interface (pln2033.sensor) and the chip registry (pln2033.chips)."""

from __future__ import annotations

import pytest

from pln2033 import SensorDriver
from pln2033.chips import CHIPS, check_chips, chip_info, make_driver, make_emulator
from pln2033.emulated import CountingCore, wrap
from pln2033.motion import ConstantVelocity
from pln2033.pln2033 import PLN2033, EmulatedPLN2033, RegisterMap
from pln2033.sensor import INCH_M, ChipInfo, CpiRange, Motion


def test_cpi_range_names_what_is_allowed():
    r = CpiRange(100, 12000, 100)
    assert r.problem(1600) is None
    assert r.problem(12000) is None
    assert "out of range" in r.problem(12100, "PMW3360")
    assert "PMW3360 allows 100..12000 in steps of 100" in r.problem(150, "PMW3360")
    assert "integer" in r.problem("800")
    assert "integer" in r.problem(True)
    assert not r.fixed
    assert list(CpiRange(50, 200, 50).values) == [50, 100, 150, 200]
    fixed = CpiRange(13, 13, 1)
    assert fixed.fixed and fixed.describe() == "fixed at 13"
    with pytest.raises(ValueError):
        CpiRange(200, 100, 100)


def test_low_quality_only_below_the_threshold_and_never_for_no_figure():
    info = ChipInfo("x", "X", "spi", CpiRange(100, 100, 1), 100, quality_threshold=16)
    assert info.low_quality(15) and info.low_quality(0)
    assert not info.low_quality(16)
    assert not info.low_quality(-1)  # the chip has no quality figure
    assert Motion(1, 2, 0, False, True, False).quality == -1


def test_the_pln2033_is_a_sensor_driver_and_its_info_follows_the_register_map():
    emu = EmulatedPLN2033()
    drv = make_driver("pln2033", emu, name="/dev/spidev1.0")
    assert isinstance(drv, PLN2033) and isinstance(drv, SensorDriver)
    drv.initialise(1600)
    assert drv.get_cpi() == (1600, 1600)
    assert drv.info.cpi == CpiRange(100, 6400, 100)
    assert chip_info("pln2033").firmware == "patch"
    narrow = RegisterMap.from_dict({"cpi": {"max": 3200}})
    assert PLN2033(emu, narrow).info.cpi.max == 3200


def test_check_chips_one_for_all_one_each_or_a_clear_error():
    assert check_chips([], 2) == ["pln2033", "pln2033"]
    assert check_chips(["PMW3360"], 2) == ["pmw3360", "pmw3360"]
    assert check_chips(["pln2033", "otos"], 2) == ["pln2033", "otos"]
    with pytest.raises(ValueError, match="unknown chip 'adns9800'; allowed: pln2033, pmw3360"):
        check_chips(["adns9800"], 1)
    with pytest.raises(ValueError, match="names 3 chips for 2 devices"):
        check_chips(["pln2033"] * 3, 2)
    assert set(CHIPS) == {"pln2033", "pmw3360", "pmw3389", "pmw3901", "paa5100", "otos"}


def test_make_emulator_takes_the_common_keywords():
    t = [0.0]
    emu = make_emulator(
        "pln2033", motion=ConstantVelocity(0.0, 0.1), clock=lambda: t[0], seed=3, record=True
    )
    drv = PLN2033(emu)
    drv.initialise(1000)
    t[0] = 1.0
    m = drv.read_motion()
    assert m.dy == pytest.approx(0.1 / INCH_M * 1000, abs=1)


def test_counting_core_poor_surface_counts_nothing_and_is_ground_truth():
    t = [0.0]
    core = CountingCore(
        ConstantVelocity(0.0, 0.0254),
        clock=lambda: t[0],
        low_quality_windows=[(1.0, 2.0)],
        cpi=1000,
    )
    for k in range(1, 31):
        t[0] = k * 0.1
        core.advance()
    assert core.stats.low_quality_events == 1
    assert core.stats.counted_y == pytest.approx(2000, abs=1)  # 3 s, 1 s of it poor
    assert core.stats.lift_motion_y == pytest.approx(1000, abs=1)
    assert wrap(32768) == (-32768, True) and wrap(-32768) == (-32768, False)
    assert wrap(2048, 12) == (-2048, True)
