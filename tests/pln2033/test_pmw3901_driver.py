"""The real PMW3901 / PAA5100 drivers against their register-level emulators, byte by byte.

Bring-up bytes and the init sequence the sources give, the product-id check and its
message, the burst layout and the [pimoroni] rejection rule, counts against the
emulator's ground truth through the field-of-view scale, fixed CPI, no firmware, and the
scale error of a wrong height that the calibration fit must correct.
"""

from __future__ import annotations

import math

import pytest
from fakes import FakeClock
from hypothesis import given, settings
from hypothesis import strategies as st

from mm_pc.core.calibration import calibrate_straight_run
from pln2033 import FirmwareError, InvalidCpiError, ProductIdError, SensorDriver, SpiError
from pln2033.chips import chip_info, make_driver, make_emulator
from pln2033.motion import ConstantVelocity, SampledPath
from pln2033.pmw3901 import (
    PAA5100,
    PAA5100_INFO,
    PMW3901,
    PMW3901_INFO,
    REGISTER_NAMES,
    EmulatedPAA5100,
    EmulatedPMW3901,
    InvalidHeightError,
    regs,
)
from pln2033.pmw3901.emulator import FACTORY_TRIM, expected_init_writes
from pln2033.sensor import INCH_M

CHIPS = [(PMW3901, EmulatedPMW3901), (PAA5100, EmulatedPAA5100)]


def rig(drv_cls=PMW3901, emu_cls=EmulatedPMW3901, motion=None, emu_kw=None, **drv_kw):
    """A driver on an emulator sharing one fake clock; the driver's sleeps advance it."""
    clock = FakeClock()
    emu = emu_cls(motion=motion, clock=clock, **(emu_kw or {}))

    drv = drv_cls(emu, name="/dev/spidev1.0", sleep=clock.sleep, **drv_kw)
    return clock, emu, drv


def burst(dx=0, dy=0, squal=0x60, shutter_upper=0x02, motion=0x80):
    dx &= 0xFFFF
    dy &= 0xFFFF
    return [0, motion, 0, dx & 0xFF, dx >> 8, dy & 0xFF, dy >> 8, squal, 0x30, 0x70, 0x10,
            shutter_upper, 0x40]  # fmt: skip


# --- bring-up ----------------------------------------------------------------------------------


@pytest.mark.parametrize(("drv_cls", "emu_cls"), CHIPS)
def test_bring_up_sends_reset_id_reads_and_the_sources_init_sequence(drv_cls, emu_cls):
    clock, emu, drv = rig(drv_cls, emu_cls, emu_kw={"record": True})
    drv.initialise(1600)  # the cpi is ignored: fixed by the height
    sent = [list(tx) for tx, _ in emu.stats.history]
    # power-up reset, then product id, revision, inverse id, the motion registers once
    assert sent[:9] == [[0xBA, 0x5A], [0x00, 0], [0x01, 0], [0x5F, 0], [0x02, 0], [0x03, 0],
                        [0x04, 0], [0x05, 0], [0x06, 0]]  # fmt: skip
    assert emu.stats.history[1][1] == (0, 0x49) and emu.stats.history[3][1] == (0, 0xB6)
    writes = [(r, v) for _, r, v in emu.writes]
    init = expected_init_writes(drv_cls.CHIP, "pimoroni")
    assert writes == [*init, (0x7F, 0x00), (0x5B, 0xE0)]  # then bank 0, rotation 0
    assert emu.init_variant == ("pimoroni", "px4") and emu.tracking
    assert sent[-1] == [0x16] + [0] * 12  # one burst: clean counters
    # the trim: 0x67 bit 7 set -> 0x48 = 0x04; c1 26 -> 40 (vendor rule), c2 64 -> 28
    assert (0x48, 0x04) in writes[:8]
    assert writes[writes.index((0x51, 0x70)) + 2 : writes.index((0x51, 0x70)) + 4] == [
        (0x70, 40),
        (0x71, 28),
    ]
    assert clock.t == pytest.approx(0.020 + (0.250 if drv_cls is PMW3901 else 0.020))


def test_the_init_sequences_hold_the_values_the_sources_give():
    # literal values from pimoroni/pmw3901-python, not through regs' own tables
    pmw = expected_init_writes("pmw3901", "pimoroni")
    paa = expected_init_writes("paa5100", "pimoroni")
    assert pmw[-3:] == [(0x7F, 0x14), (0x6F, 0x1C), (0x7F, 0x00)]  # LED_N pulsing
    assert (0x74, 0x21) in pmw and (0x5A, 0x50) in pmw
    assert paa[-3:] == [(0x40, 0x80), (0x73, 0x1F), (0x73, 0x00)]
    assert (0x5A, 0x90) in paa and (0x68, 0xF0) in paa and (0x62, 0xF0) not in paa
    bc = expected_init_writes("pmw3901", "bitcraze")
    assert bc[0] == (0x7F, 0x00) and (0x74, 0x1F) in bc and bc[-2:] == [(0x5A, 0x10), (0x54, 0)]
    # preamble 5, trim 1, middle 5, c1/c2 4 + 2, block 78 less 2 waits
    assert len(pmw) == 17 + 76 and len(bc) == 76
    assert regs.adjust_c1(26, "px4") == 40 and regs.adjust_c1(26, "pimoroni") == 51
    assert regs.adjust_c1(40) == 51 and regs.adjust_c1(60) == 0x3F and regs.adjust_c2(64) == 28


def test_bitcraze_variant_and_pimoroni_c1_rule_are_accepted_a_foreign_sequence_is_not():
    _, emu, drv = rig(init="bitcraze")
    drv.initialise(104)
    assert emu.init_variant == ("bitcraze", "px4")
    assert (0x0E, 0x67) not in {(b, r) for b, r, _ in emu.writes}  # no preamble
    _, emu, drv = rig(c1_rule="pimoroni")
    drv.initialise(104)
    assert emu.init_variant == ("pimoroni", "pimoroni") and (0x70, 51) in [
        (r, v) for _, r, v in emu.writes
    ]
    clock, emu, drv = rig(motion=ConstantVelocity(0.0, 0.1), init=[(0x7F, 0x00), (0x40, 0x80)])
    drv.initialise(104)
    assert not emu.tracking
    clock.t += 0.5
    m = drv.read_motion()
    assert (m.dx, m.dy) == (0, 0) and drv.info.low_quality(m.quality)
    with pytest.raises(ValueError, match="init sequence 'bitcraze' unknown for the PixArt PAA"):
        PAA5100(emu, init="bitcraze")
    with pytest.raises(ValueError, match="rotation_deg must be one of 0, 90, 180, 270"):
        PMW3901(emu, rotation_deg=45)


@pytest.mark.parametrize(("drv_cls", "emu_cls"), CHIPS)
def test_wrong_product_id_says_what_was_read_expected_and_what_to_do(drv_cls, emu_cls):
    _, emu, drv = rig(drv_cls, emu_cls, emu_kw={"product_id": 0x42})
    with pytest.raises(ProductIdError) as e:
        drv.initialise(0)
    msg = str(e.value)
    assert "/dev/spidev1.0: no PixArt" in msg
    assert "product id reads 0x42, inverse id 0xbd" in msg
    assert "expected 0x49 and inverse 0xb6" in msg
    assert "wiring (MISO, MOSI, SCLK, CS)" in msg and "SPI mode 3" in msg
    assert "driver option product_id" in msg
    assert emu.writes == []  # no init sequence written to an unknown chip
    _, emu, drv = rig(drv_cls, emu_cls, emu_kw={"product_id": 0x42}, product_id=0x42)
    drv.initialise(0)
    assert emu.tracking


def test_nothing_on_the_bus_and_a_short_reply_are_clear_errors():
    class ZeroBus:
        def xfer2(self, data):
            return [0] * len(data)

    with pytest.raises(ProductIdError, match=r"every byte reads 0x00: nothing answers"):
        PMW3901(ZeroBus(), sleep=lambda s: None).initialise(0)

    class ShortBus:
        def xfer2(self, data):
            return [0] * (len(data) - 1)

    with pytest.raises(SpiError, match="sent 13 bytes, received 12"):
        PMW3901(ShortBus()).read_motion()


def test_registers_are_banked_an_id_read_in_another_bank_fails():
    _, _emu, drv = rig()
    drv.initialise(0)
    drv.write_register(0x7F, 0x0E)
    assert drv.read_register(0x67) == FACTORY_TRIM[0x67]
    with pytest.raises(ProductIdError, match="every byte reads 0x00"):
        drv.check_product_id()
    drv.write_register(0x7F, 0x00)
    drv.check_product_id()


def test_an_odd_length_frame_is_one_protocol_error_its_whole_pairs_still_run():
    """EmulatorStats.protocol_errors on this chip: a register frame that is not whole
    (address, value) pairs; the burst (0x16 + any length) is no such frame."""
    _, emu, drv = rig()
    drv.initialise(0)
    assert emu.stats.protocol_errors == 0
    assert emu.xfer2([0x00, 0, 0x5F]) == [0, 0x49, 0]  # the pair is read, the odd byte not
    assert emu.stats.protocol_errors == 1
    emu.xfer2([regs.MOTION_BURST] + [0] * 5)  # a short burst read is legal
    assert emu.stats.protocol_errors == 1


# --- the burst ----------------------------------------------------------------------------------


def test_burst_decode_little_endian_signed_deltas_and_squal():
    drv = PMW3901(None)
    m = drv.decode_motion(burst(0x1234, -2, squal=0x60))
    assert (m.dx, m.dy, m.quality, m.status, m.moved) == (0x1234, -2, 0x60, 0x80, True)
    assert not m.lifted and not m.overflow
    m = drv.decode_motion(burst(-32768, 32767, motion=0))
    assert (m.dx, m.dy, m.moved) == (-32768, 32767, False)
    with pytest.raises(SpiError, match="received 12"):
        drv.decode_motion(burst()[:-1])


@given(st.integers(0, 255), st.integers(0, 255))
def test_low_quality_is_exactly_the_pimoroni_rejection_rule(squal, shutter_upper):
    drv = PMW3901(None)
    m = drv.decode_motion(burst(5, 5, squal=squal, shutter_upper=shutter_upper))
    rejected = squal < 0x19 and shutter_upper == 0x1F
    assert drv.info.low_quality(m.quality) == rejected
    assert m.quality == (squal if rejected or squal >= 0x19 else 0x19)


@pytest.mark.parametrize(("drv_cls", "emu_cls"), CHIPS)
def test_lift_and_poor_surface_read_as_low_quality_with_the_shutter_at_0x1f(drv_cls, emu_cls):
    clock, emu, drv = rig(
        drv_cls,
        emu_cls,
        motion=ConstantVelocity(0.0, 0.05),
        emu_kw={"lift_windows": [(1.0, 1.2)], "low_quality_windows": [(2.0, 2.3)]},
    )
    drv.initialise(0)
    low_at = []
    for k in range(1, 3001):
        clock.t = k * 0.001
        m = drv.read_motion()
        if drv.info.low_quality(m.quality):
            low_at.append(round(clock.t, 3))
            assert drv.last_burst[1 + regs.B_SHUTTER_UPPER] == 0x1F
            assert (m.dx, m.dy) == (0, 0)
    # every poll whose interval (t - 1 ms, t] overlaps a window, and no other
    in_windows = [t for t in low_at if 1.0 < t <= 1.2 or 2.0 < t <= 2.3]
    assert low_at == in_windows and len(low_at) == 200 + 300
    assert emu.stats.lift_events == 1 and emu.stats.low_quality_events == 1


class StartsAt:
    """Still until ``t_on``, then ``vy`` m/s forward (the counts' fraction starts at 0)."""

    def __init__(self, t_on: float, vy: float) -> None:
        self.t_on, self.vy = t_on, vy

    def displacement(self, t0: float, t1: float) -> tuple[float, float]:
        return 0.0, self.vy * max(0.0, t1 - max(t0, self.t_on))


def straddle_rig(window_kw: str, polls_ms=range(10, 201, 10)):
    """1.25 counts per ms forward from t = 1.0002 s (0.306 m/s at 0.10 m), a window from
    1.0232 to 1.1168 s, reads at 1 s + ``polls_ms``: [(t_ms, dy, low quality)] and the stats."""
    clock = FakeClock()
    vy = 1250 * INCH_M / EmulatedPMW3901.OPTICS.cpi(0.10)
    emu = EmulatedPMW3901(
        motion=StartsAt(1.0002, vy), clock=clock, **{window_kw: [(1.0232, 1.1168)]}
    )
    drv = PMW3901(emu, sleep=clock.sleep)
    drv.initialise(0)
    assert clock.t < 1.0
    reads = []
    for ms in polls_ms:
        clock.t = 1.0 + ms / 1000
        m = drv.read_motion()
        reads.append((ms, m.dy, drv.info.low_quality(m.quality)))
    return reads, emu.stats


@pytest.mark.parametrize("window_kw", ["lift_windows", "low_quality_windows"])
def test_a_read_that_straddles_a_window_edge_keeps_the_counts_outside_the_window(window_kw):
    # true counts: 1.25 per ms from 1.0002 s: 24.75 by 1.020, 28.75 by the window's start
    # (1.0232), 117 inside it (93.6 ms), 4.0 from its end (1.1168) to 1.120, 249.75 by 1.200
    reads, s = straddle_rig(window_kw)
    by_ms = {ms: (dy, low) for ms, dy, low in reads}
    assert by_ms[10] == (12, False) and by_ms[20] == (12, False)  # 12.25 -> 12, 24.75 -> 24
    # the read at 1.030: the 4 counts (24 -> 28) made before the window began, low quality
    # (the chip saw the window; [pimoroni]'s rule rejects the read, our driver keeps the counts)
    assert by_ms[30] == (4, True)
    assert all(by_ms[ms] == (0, True) for ms in range(40, 111, 10))
    # the read at 1.120: the 4 counts made after it ended (the fraction 0.75 kept through the
    # window + 4.0), still low quality (its interval saw the window)
    assert by_ms[120] == (4, True)
    assert by_ms[130] == (13, False) and by_ms[200] == (12, False)  # 0.75 + 12.5, 0.25 + 12.5
    assert sum(dy for _, dy, _ in reads) == s.counted_y == 132  # floor(249.75) - 117 in the window
    assert s.lift_motion_y == pytest.approx(117.0, abs=1e-9)  # exactly the window: 93.6 ms
    assert s.lift_cleared_y == 0  # no lift detector clears the counters
    # before (issue 26) the two straddling reads dropped their whole 10 ms: 125 lost, 124 read


def test_counts_made_before_a_lift_wait_in_the_counter_until_the_next_read():
    # no read from 1.020 s to after the lift: the next read holds the 4 counts before the lift
    # and the 42 after it (0.75 + 41.5 by 1.150), as the chip's accumulator holds them
    reads, s = straddle_rig("lift_windows", polls_ms=(20, 150))
    assert reads == [(20, 24, False), (150, 4 + 42, True)]
    assert s.counted_y == 70 and s.lift_motion_y == pytest.approx(117.0, abs=1e-9)
    assert s.lift_events == 1


# --- counts through the scale --------------------------------------------------------------------


@settings(max_examples=20)
@given(
    st.sampled_from(CHIPS),
    st.floats(0.0, 1.0),
    st.floats(-0.4, 0.4),
    st.floats(-0.4, 0.4),
)
def test_counts_follow_the_true_motion_through_the_fov_scale(chip, where, vx, vy):
    drv_cls, emu_cls = chip
    lo, hi = drv_cls.HEIGHT_RANGE_M
    h = lo + where * (hi - lo)
    clock, _emu, drv = rig(
        drv_cls, emu_cls, ConstantVelocity(vx, vy), emu_kw={"height_m": h}, height_m=h
    )
    drv.initialise(0)
    t0, sx, sy = clock.t, 0, 0
    for k in range(1, 501):
        clock.t = t0 + k * 0.002
        m = drv.read_motion()
        sx, sy = sx + m.dx, sy + m.dy
    true_x, true_y = vx * (clock.t - t0), vy * (clock.t - t0)
    mpc = drv.metres_per_count
    assert abs(sx - true_x / mpc) <= 1 and abs(sy - true_y / mpc) <= 1
    assert mpc == pytest.approx(h * drv.optics.rad_per_count)


def test_pinned_counts_accrue_continuously_not_per_frame():
    """An assumption (docs/sensors.md "The emulators"): the real chip reports motion per
    frame (~121 fps, 8.3 ms), so of 1 ms reads most would hold 0 and every eighth the whole
    frame. The emulator counts continuously: every 1 ms read holds its 1 ms of motion."""
    clock, emu, drv = rig()
    drv.initialise(0)
    t0 = clock.t
    emu.motion = ConstantVelocity(0.0, 1.25e3 * drv.metres_per_count)  # 1.25 counts per ms
    reads = []
    for k in range(1, 41):
        clock.t = t0 + k * 0.001
        reads.append(drv.read_motion().dy)
    assert set(reads) == {1, 2} and abs(sum(reads) - 50) <= 1  # 40 ms x 1.25, the fraction kept


def test_a_long_noisy_run_loses_no_count_and_stays_within_noise_of_the_truth():
    # a 60 s random-looking path (m), 1 kHz polls, count noise, a register dump every 5 s
    n, dt = 601, 0.1
    xs = [0.3 * math.sin(0.05 * i) + 0.002 * i for i in range(n)]
    ys = [0.5 * math.sin(0.031 * i + 1.0) + 0.01 * i for i in range(n)]
    path = SampledPath(xs, ys, dt, t_start=1.0)
    clock, emu, drv = rig(motion=path, emu_kw={"noise_counts": 2.0, "seed": 7})
    drv.initialise(0)
    assert clock.t < 1.0
    sx = sy = 0
    for k in range(1, 61_001):
        clock.t = 1.0 + k * 0.001
        m = drv.read_all_registers()[0] if k % 5000 == 0 else drv.read_motion()
        sx, sy = sx + m.dx, sy + m.dy
    s = emu.stats
    assert (sx, sy) == (s.counted_x, s.counted_y)  # nothing lost by the chip or a dump
    px, py = path.position(clock.t)
    mpc = drv.metres_per_count
    sigma = 2.0 * math.sqrt(60.0)
    assert abs(sx - px / mpc) < 5 * sigma and abs(sy - py / mpc) < 5 * sigma
    assert abs(py / mpc) > 100 * sigma  # the run is long against the noise


def test_rotation_register_turns_the_reported_axes():
    for rot, want in ((0, (0, 1)), (180, (0, -1)), (90, (-1, 0)), (270, (1, 0))):
        clock, emu, drv = rig(motion=ConstantVelocity(0.0, 0.0254), rotation_deg=rot)
        drv.initialise(0)
        assert emu.orientation == regs.ROTATIONS[rot]
        clock.t += 1.0
        m = drv.read_motion()
        n = round(drv.effective_cpi)
        assert (round(m.dx / n), round(m.dy / n)) == want


def test_register_dump_names_values_and_the_motion_it_cleared():
    clock, _emu, drv = rig(motion=ConstantVelocity(0.0, 0.0254))
    drv.initialise(0)
    clock.t += 1.0
    motion, values = drv.read_all_registers()
    assert tuple(values) == REGISTER_NAMES
    assert values["product_id"] == 0x49 and values["inverse_product_id"] == 0xB6
    assert values["orientation"] == 0xE0 and values["shutter_upper"] == 0x02
    assert motion.dy == pytest.approx(drv.effective_cpi, abs=1)
    assert values["delta_y"] == motion.dy and values["squal"] == motion.quality
    assert drv.read_motion().dy == 0


# --- resolution, height, firmware ----------------------------------------------------------------


@pytest.mark.parametrize(
    ("drv_cls", "emu_cls", "info", "cpi"),
    [(PMW3901, EmulatedPMW3901, PMW3901_INFO, 104), (PAA5100, EmulatedPAA5100, PAA5100_INFO, 232)],
)
def test_cpi_is_fixed_by_the_height_and_set_cpi_refuses_another(drv_cls, emu_cls, info, cpi):
    _, emu, drv = rig(drv_cls, emu_cls)
    assert info.cpi.fixed and info.cpi.min == cpi == info.cpi_default
    assert drv.get_cpi() == (cpi, cpi) and drv.cpi_problem(cpi) is None
    assert info.quality_name == "SQUAL" and info.quality_threshold == 0x19
    assert info.firmware == "" and info.spi_mode == 3 and info.counter_bits == 16
    n = emu.stats.transfers
    drv.set_cpi(cpi)
    with pytest.raises(InvalidCpiError) as e:
        drv.set_cpi(1600)
    msg = str(e.value)
    assert f"resolution is fixed at {cpi} CPI" in msg and "driver option height_m" in msg
    assert "cannot set 1600" in msg
    assert emu.stats.transfers == n  # nothing was written
    higher = drv_cls(emu, height_m=drv_cls.HEIGHT_RANGE_M[1])
    assert higher.get_cpi()[0] < cpi and higher.info.cpi.min == higher.get_cpi()[0]


def test_heights_outside_the_working_range_are_refused_with_the_reason():
    with pytest.raises(InvalidHeightError, match=r"0\.05 m is outside .*0\.08\.\.1 m.*80 mm"):
        PMW3901(None, height_m=0.05)
    with pytest.raises(InvalidHeightError, match=r"PAA5100JE-Q's working range 0\.015\.\.0\.035"):
        PAA5100(None, height_m=0.05)
    with pytest.raises(InvalidHeightError, match="number of metres"):
        PMW3901(None, height_m=float("nan"))
    assert PMW3901.chip_info(0.2).max_speed_mps == pytest.approx(1.48)
    assert PAA5100_INFO.max_speed_mps == pytest.approx(1.143)


def test_the_chip_takes_no_firmware():
    _, emu, drv = rig()
    with pytest.raises(FirmwareError, match="the PixArt PMW3901 takes no firmware"):
        drv.initialise(0, firmware=[1, 2])
    assert emu.stats.transfers == 0
    with pytest.raises(FirmwareError, match="PAA5100JE-Q takes no firmware"):
        PAA5100(emu).load_firmware([1])


def test_wrong_height_shows_the_scale_error_the_calibration_fit_corrects():
    # the sensor sits at 0.12 m, the driver is told 0.10 m: it sees 0.10 / 0.12 of the truth
    clock, _emu, drv = rig(motion=ConstantVelocity(0.0, 0.2), emu_kw={"height_m": 0.12})
    drv.initialise(0)
    t0, sy, sx = clock.t, 0, 0
    for k in range(1, 5001):
        clock.t = t0 + k * 0.001
        m = drv.read_motion()
        sx, sy = sx + m.dx, sy + m.dy
    true_m = 0.2 * 5.0
    seen_m = sy / drv.get_cpi()[1] * INCH_M
    assert seen_m / true_m == pytest.approx(0.10 / 0.12, rel=0.01)
    cal = calibrate_straight_run(sx / drv.cpi * INCH_M, seen_m, true_distance=true_m)
    assert cal.scale == pytest.approx(1.2, rel=0.01)


def test_registry_builds_both_chips_with_driver_options():
    t = FakeClock()
    for chip, info in (("pmw3901", PMW3901_INFO), ("paa5100", PAA5100_INFO)):
        assert chip_info(chip) == info
        emu = make_emulator(chip, motion=ConstantVelocity(0.0, 0.1), clock=t, seed=1)
        lo = info.cpi.min
        drv = make_driver(chip, emu, name="/dev/spidev1.1", height_m=None, sleep=lambda s: None)
        assert isinstance(drv, SensorDriver) and drv.info == info and drv.get_cpi() == (lo, lo)
        drv.initialise(lo)
        assert emu.tracking
