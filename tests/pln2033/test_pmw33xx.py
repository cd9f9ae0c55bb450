"""The real PMW3360/PMW3389 drivers against their register-level emulators, byte by byte."""

from __future__ import annotations

import math

import pytest
from fakes import FakeClock
from hypothesis import given, settings
from hypothesis import strategies as st

from pln2033.chips import chip_info, make_driver, make_emulator
from pln2033.errors import FirmwareError, InvalidCpiError, ProductIdError, SensorNotRespondingError
from pln2033.motion import ConstantVelocity, Stationary
from pln2033.pmw33xx import (
    PMW3360,
    PMW3360_INFO,
    PMW3389,
    PMW3389_INFO,
    EmulatedPMW3360,
    EmulatedPMW3389,
    poll_budget,
    read_srom_file,
)
from pln2033.pmw33xx import regs as R  # noqa: N812
from pln2033.sensor import INCH_M, SensorDriver

CHIPS = ("pmw3360", "pmw3389")
BLOB = bytes((i * 7 + 3) & 0xFF for i in range(R.SROM_LENGTH))  # a stand-in, not PixArt's


def make(chip="pmw3360", motion=None, record=False, emu_kw=None, **drv_kw):
    clock = FakeClock()

    emu = make_emulator(
        chip, motion=motion or Stationary(), clock=clock, record=record, **(emu_kw or {})
    )
    drv = make_driver(chip, emu, name="/dev/spidev1.0", sleep=clock.sleep, **drv_kw)
    return clock, emu, drv


@pytest.mark.parametrize("chip", CHIPS)
def test_bring_up_speaks_the_power_up_sequence(chip):
    _clock, emu, drv = make(chip, record=True)
    assert isinstance(drv, SensorDriver)
    assert drv.info is chip_info(chip)
    drv.initialise(800, firmware=list(BLOB))
    assert emu.stats.protocol_errors == 0
    frames = [tx for tx, _rx in emu.stats.history]
    assert drv.get_cpi() == (800, 800)
    assert drv.srom_version == 0x04 and emu.srom_running and emu.srom_intact
    assert frames[0] == ((0x3A | 0x80, 0x5A),)  # Power_Up_Reset 0x5A
    # then Motion and the deltas, each address followed by its data byte
    assert [seg[0] for seg in frames[1][::2]] == [0x02, 0x03, 0x04, 0x05, 0x06]
    assert [seg[0] for seg in frames[2][::2]] == [0x00, 0x3F]  # product id, inverse
    assert ((0x10 | 0x80, 0x00), (0x13 | 0x80, 0x1D)) in frames  # Rest off, SROM init
    assert ((0x13 | 0x80, 0x18),) in frames
    upload = next(f for f in frames if f[0] == (0x62 | 0x80,))
    assert len(upload) == 1 + R.SROM_LENGTH and bytes(s[0] for s in upload[1:]) == BLOB
    assert frames[-1] == ((0x50,), (0,) * 12)  # the last frame is a motion burst


def test_the_burst_frame_holds_the_tsrad_delay_and_arms_once():
    seen = []
    _clock, emu, drv = make()
    drv.initialise(1600)
    real = emu.xfer_segments

    def spy(segments):
        seen.append([(list(b), d) for b, d in segments])
        return real(segments)

    emu.xfer_segments = spy
    drv.read_motion()
    drv.read_motion()
    assert seen == [[([0x50], 35), ([0] * 12, 0)]] * 2
    assert drv.transfers_per_poll == 1 and drv.burst_delay_us == 35
    drv.get_cpi()  # a non-burst read: the next poll arms the burst again
    seen.clear()
    drv.read_motion()
    assert seen[0] == [([0x50 | 0x80, 0x00], 180)]
    assert seen[1] == [([0x50], 35), ([0] * 12, 0)]


@pytest.mark.parametrize("chip", CHIPS)
def test_burst_decodes_deltas_squal_and_motion_bits(chip):
    cpi = 1000
    clock, _emu, drv = make(chip, motion=ConstantVelocity(0.254, -0.127))
    drv.initialise(cpi)
    clock.t += 0.010  # 0.1 inch x, -0.05 inch y at 1000 cpi
    m = drv.read_motion()
    assert (m.dx, m.dy) == (100, -50)
    assert m.moved and not m.lifted and not m.overflow
    assert m.status & R.MOT and m.status & R.MOTION_RESET
    assert R.MIN_SQ_RUN_DEFAULT <= m.quality <= R.SQUAL_MAX
    assert not drv.info.low_quality(m.quality)
    m2 = drv.read_motion()  # no time passed: the burst cleared the counters
    assert (m2.dx, m2.dy, m2.moved) == (0, 0, False)


@pytest.mark.parametrize("chip", CHIPS)
def test_counts_follow_the_true_motion_within_one_count_over_a_long_run_with_noise(chip):
    v = (0.31, -0.17)
    cpi = chip_info(chip).cpi.max // 2
    clock, emu, drv = make(chip, motion=ConstantVelocity(*v), emu_kw={"noise_counts": 3.0})
    drv.initialise(cpi)
    emu.stats.counted_x = emu.stats.counted_y = 0
    sx = sy = 0
    for _ in range(5000):  # 5 s at 1 kHz
        clock.t += 0.001
        m = drv.read_motion()
        sx += m.dx
        sy += m.dy
    assert (sx, sy) == (emu.stats.counted_x, emu.stats.counted_y)
    true_x = v[0] * 5.0 * cpi / INCH_M
    true_y = v[1] * 5.0 * cpi / INCH_M
    noise = 3.0 * math.sqrt(5.0) * 5  # 5 sigma of the accumulated noise
    assert abs(sx - true_x) < noise + 1 and abs(sy - true_y) < noise + 1
    assert emu.stats.protocol_errors == 0


@pytest.mark.parametrize("chip", CHIPS)
def test_16_bit_counters_wrap_when_polled_too_slowly(chip):
    cpi = chip_info(chip).cpi.max
    clock, emu, drv = make(chip, motion=ConstantVelocity(1.0, 0.0))
    drv.initialise(cpi)
    dt = 40000 * INCH_M / cpi  # 40000 counts: more than 32767
    clock.t += dt
    m = drv.read_motion()
    assert emu.stats.overflow_events == 1
    # the chip has no overflow flag: the poll sees a wrapped value
    assert abs(m.dx - (40000 - 65536)) <= 1
    assert not m.overflow


@pytest.mark.parametrize("chip", CHIPS)
def test_lift_sets_lift_stat_drops_squal_and_clears_the_counts(chip):
    clock, emu, drv = make(
        chip,
        motion=ConstantVelocity(0.2, 0.0),
        emu_kw={"lift_windows": [(1.0, 1.5)], "low_quality_windows": [(2.0, 2.2)]},
    )
    drv.initialise(1600)
    clock.t = 1.2
    m = drv.read_motion()
    assert m.lifted and m.status & R.LIFT_STAT and m.quality <= 3
    assert drv.info.low_quality(m.quality)
    assert (m.dx, m.dy) == (0, 0)
    assert emu.stats.lift_events == 1
    clock.t = 1.8
    m = drv.read_motion()  # the window ended inside the interval: reported once, then down
    clock.t = 1.9
    m = drv.read_motion()
    assert not m.lifted and m.quality >= R.MIN_SQ_RUN_DEFAULT and m.dx > 0
    clock.t = 2.1
    m = drv.read_motion()
    assert not m.lifted and 4 <= m.quality < R.MIN_SQ_RUN_DEFAULT and m.dx == 0
    assert drv.info.low_quality(m.quality) and emu.stats.low_quality_events == 1


@pytest.mark.parametrize("chip", CHIPS)
def test_cpi_set_get_over_the_whole_range(chip):
    _clock, emu, drv = make(chip)
    drv.initialise(chip_info(chip).cpi_default)
    for cpi in chip_info(chip).cpi.values:
        drv.set_cpi(cpi)
        assert drv.get_cpi() == (cpi, cpi)
        assert (emu.cpi_x, emu.cpi_y) == (cpi, cpi)
    assert emu.stats.protocol_errors == 0


def test_cpi_register_encodings_per_source():
    _, emu, drv = make("pmw3360")
    drv.initialise(5000)
    assert emu.r["Config1"] == 0x31  # the datasheet's 0x31 = 5000 cpi
    drv.set_cpi(12000)
    assert emu.r["Config1"] == 0x77
    _, emu, drv = make("pmw3389")
    drv.initialise(16000)
    assert (emu.r["Resolution_H"], emu.r["Resolution_L"]) == (0x01, 0x3F)  # QMK: 16000/50 - 1
    _, emu, drv = make("pmw3389", emu_kw={"resolution_offset": 0}, resolution_offset=0)
    drv.initialise(16000)
    assert (emu.r["Resolution_H"], emu.r["Resolution_L"]) == (0x01, 0x40)  # teamspatzenhirn
    # a driver with the other encoding than its chip: the registers read back what was
    # written, so only the counts show it (1550 instead of 1600 cpi: 3 %, the calibration's job)
    _, emu, drv = make("pmw3389", emu_kw={"resolution_offset": 0})
    drv.initialise(1600)
    assert drv.get_cpi() == (1600, 1600) and emu.cpi_y == 1550


@pytest.mark.parametrize(
    ("chip", "bad", "allowed"),
    [
        ("pmw3360", 150, "100..12000 in steps of 100"),
        ("pmw3360", 12100, "100..12000 in steps of 100"),
        ("pmw3360", 0, "100..12000"),
        ("pmw3389", 75, "50..16000 in steps of 50"),
        ("pmw3389", 16050, "50..16000"),
    ],
)
def test_bad_cpi_is_refused_before_any_transfer(chip, bad, allowed):
    _, emu, drv = make(chip)
    drv.initialise(1600)
    n = emu.stats.transfers
    with pytest.raises(InvalidCpiError, match=allowed):
        drv.set_cpi(bad)
    with pytest.raises(InvalidCpiError):
        drv.initialise(bad)
    assert emu.stats.transfers == n
    assert "integer" in drv.cpi_problem("800")


@settings(max_examples=40, deadline=None)
@given(cpi=st.integers(1, 20000))
def test_cpi_problem_matches_the_chip(cpi):
    _, _emu, drv = make("pmw3389")
    ok = 50 <= cpi <= 16000 and cpi % 50 == 0
    assert (drv.cpi_problem(cpi) is None) == ok


@pytest.mark.parametrize("chip", CHIPS)
def test_wrong_product_id_message_says_what_was_read_and_what_to_do(chip):
    _, emu, drv = make(chip, emu_kw={"product_id": 0x42 if chip == "pmw3389" else 0x47})
    with pytest.raises(ProductIdError) as e:
        drv.initialise(1600)
    msg = str(e.value)
    want = drv.product_id
    got = emu.product_id
    assert f"Product_ID reads {got:#04x}" in msg and f"answers {want:#04x}" in msg
    assert f"product_id={got:#04x}" in msg and "chips" in msg
    # the override makes it work
    _, emu, drv = make(chip, emu_kw={"product_id": got}, product_id=got)
    drv.initialise(1600)
    assert emu.stats.protocol_errors == 0


def test_no_chip_message_names_wiring_and_spi_mode_3():
    class Dead:
        def xfer_segments(self, segments):
            return [[0xFF] * len(b) for b, _ in segments]

        def close(self):
            pass

    drv = PMW3360(Dead(), "/dev/spidev1.0", sleep=lambda s: None)
    with pytest.raises(ProductIdError, match="mode 3") as e:
        drv.initialise(1600)
    assert "wiring" in str(e.value) and "0xff" in str(e.value)
    with pytest.raises(SensorNotRespondingError, match="all ones"):
        drv.read_motion()
    with pytest.raises(TypeError, match="xfer_segments"):
        PMW3389(object(), "/dev/spidev1.1")


@pytest.mark.parametrize("chip", CHIPS)
def test_srom_good_corrupted_short_and_wrong_version(chip):
    _, emu, drv = make(chip, emu_kw={"srom": BLOB})
    drv.initialise(1600, firmware=list(BLOB))
    assert emu.srom_intact and emu.srom_crc() == R.SROM_CRC_PASS
    bad = bytearray(BLOB)
    bad[1000] ^= 0x10
    _, emu, drv = make(chip, emu_kw={"srom": BLOB})
    with pytest.raises(FirmwareError, match="CRC self test answers 0x") as e:
        drv.initialise(1600, firmware=list(bad))
    assert "not 0xbeef" in str(e.value)
    _, emu, drv = make(chip)
    n = emu.stats.transfers
    with pytest.raises(FirmwareError, match=r"4093 bytes.*4094.*srom_length"):
        drv.initialise(1600, firmware=list(BLOB[:-1]))
    assert emu.stats.transfers == n  # refused before the reset
    with pytest.raises(FirmwareError, match=r"0\.\.255"):
        drv.check_firmware([0x100])
    with pytest.raises(FirmwareError, match="empty"):
        drv.check_firmware([])
    _, emu, drv = make(chip, srom_id=0x05)
    with pytest.raises(FirmwareError, match="SROM_ID reads 0x04, expected 0x05"):
        drv.initialise(1600, firmware=list(BLOB))


def test_srom_upload_too_fast_is_garbled_and_caught_by_the_crc():
    _, emu, drv = make()
    drv.initialise(1600)
    real = emu.xfer_segments

    def hurried(segments):  # a bus that drops the inter-byte delay of the SROM burst
        if segments and segments[0][0] == [0x62 | 0x80]:
            segments = [(b, 0) for b, _ in segments]
        return real(segments)

    emu.xfer_segments = hurried
    with pytest.raises(FirmwareError, match="CRC"):
        drv.load_firmware(list(BLOB))
    assert emu.stats.protocol_errors >= 1 and not emu.srom_intact


def test_srom_waits_are_checked_on_the_clock():
    _clock, emu, drv = make()
    drv.initialise(1600)
    drv._sleep = lambda s: None  # a driver that does not wait 10 ms after 0x1D
    with pytest.raises(FirmwareError, match="SROM_ID reads 0x00"):
        drv.load_firmware(list(BLOB))
    assert emu.stats.protocol_errors >= 1


def test_srom_file_reader_text_and_binary(tmp_path):
    text = tmp_path / "srom.txt"
    text.write_text("// PixArt SROM 0x04\n" + ", ".join(f"0x{b:02x}" for b in BLOB) + "\n")
    assert read_srom_file(text) == list(BLOB)
    binary = tmp_path / "srom.bin"
    binary.write_bytes(BLOB)
    assert read_srom_file(binary) == list(BLOB)
    bad = tmp_path / "bad.txt"
    bad.write_text("const unsigned char firmware_data[] = { 0x01 };")
    with pytest.raises(FirmwareError, match=r"SROM file .*'const' is not a hex byte"):
        read_srom_file(bad)
    with pytest.raises(FirmwareError, match="cannot read SROM file"):
        read_srom_file(tmp_path / "missing.bin")


@pytest.mark.parametrize(("option", "value"), [("tsrad_motbr_us", 20), ("tsrad_us", 100)])
def test_a_too_short_read_delay_gives_garbage_and_a_protocol_error(option, value):
    clock, emu, drv = make(motion=ConstantVelocity(0.1, 0.0), **{option: value})
    if option == "tsrad_us":
        with pytest.raises(ProductIdError):  # the ids read as garbage
            drv.initialise(1600)
    else:
        drv.initialise(1600)  # the last step is a burst: garbage, counted
        clock.t += 0.01
        drv.read_motion()
        assert emu.stats.counted_x > 0
    assert emu.stats.protocol_errors >= 1


def test_xfer2_without_delays_is_garbage_and_a_write_too_close_to_the_next_is_counted():
    clock, emu, drv = make()
    drv.initialise(1600)
    n = emu.stats.protocol_errors
    emu.xfer2([0x00, 0x00])  # a read without tSRAD
    assert emu.stats.protocol_errors == n + 1 and emu.timing_errors == {"tSRAD": 1}
    clock.t += 0.001
    emu.xfer_segments([([0x0F | 0x80, 0x77], 40), ([0x0F], 160), ([0], 20)])  # tSWR missed
    assert emu.stats.protocol_errors == n + 2 and emu.timing_errors["tSWR"] == 1
    assert emu.cpi_y == 12000  # the write itself is applied (counted, not dropped)
    clock.t += 0.001
    emu.xfer_segments([([0x0F | 0x80, 0x31], 180)])  # tSWW kept: 5000 cpi
    assert emu.cpi_y == 5000 and emu.stats.protocol_errors == n + 2


def test_register_dump_hands_back_the_counts_it_cleared():
    clock, emu, drv = make(motion=ConstantVelocity(0.1, 0.05))
    drv.initialise(1600)
    total = 0
    for _ in range(50):
        clock.t += 0.001
        total += drv.read_motion().dx
    clock.t += 0.02
    m, values = drv.read_all_registers()
    total += m.dx
    clock.t += 0.001
    total += drv.read_motion().dx
    assert values["Product_ID"] == 0x42 and values["Inverse_Product_ID"] == 0xBD
    assert values["SROM_ID"] == 0 and values["Min_SQ_Run"] == 0x10
    assert list(values) == sorted(values, key=R.PMW3360.addresses.__getitem__)
    assert "SROM_Enable" not in values and "Power_Up_Reset" not in values
    assert m.dx > 0 and m.quality == values["SQUAL"]
    assert emu.stats.protocol_errors == 0


def test_mixed_pmw3360_and_pmw3389_side_by_side():
    clock = FakeClock()

    v = ConstantVelocity(0.25, 0.1)
    e60 = EmulatedPMW3360(motion=v, clock=clock)
    e89 = EmulatedPMW3389(motion=v, clock=clock)
    d60 = make_driver("pmw3360", e60, name="/dev/spidev1.0", sleep=clock.sleep)
    d89 = make_driver("pmw3389", e89, name="/dev/spidev1.1", sleep=clock.sleep)
    d60.initialise(1200)
    d89.initialise(2400)
    with pytest.raises(ProductIdError):  # a PMW3389 driver on the PMW3360's bus
        PMW3389(e60, "/dev/spidev1.0", sleep=clock.sleep).initialise(2400)
    d60.initialise(1200)
    d89.read_motion()  # what d89 counted while d60 started again
    s60 = s89 = 0
    for _ in range(1000):
        clock.t += 0.001
        s60 += d60.read_motion().dx
        s89 += d89.read_motion().dx
    assert abs(s60 - 0.25 * 1200 / INCH_M) <= 1  # 1 s at 0.25 m/s, within one count
    assert abs(s89 - 0.25 * 2400 / INCH_M) <= 1
    assert e60.stats.protocol_errors == e89.stats.protocol_errors == 0


def test_chip_info_and_poll_budget():
    assert PMW3360_INFO.spi_mode == PMW3389_INFO.spi_mode == 3
    assert PMW3360_INFO.max_speed_mps == pytest.approx(6.35)
    assert PMW3389_INFO.max_speed_mps == pytest.approx(10.16)
    assert PMW3360_INFO.quality_threshold == 16 and PMW3360_INFO.firmware == "srom"
    b = poll_budget(PMW3360_INFO, 1000)
    assert b.delay_share == pytest.approx(0.035)
    assert b.counts_per_poll == pytest.approx(3000)
    assert b.min_rate_hz == pytest.approx(3_000_000 / 32767)
    assert b.hold_us == pytest.approx(35 + 13 * 8 / 2e6 * 1e6)
    b89 = poll_budget(PMW3389_INFO, 1000)
    assert b89.counts_per_poll == pytest.approx(6400) and b89.headroom > 5
