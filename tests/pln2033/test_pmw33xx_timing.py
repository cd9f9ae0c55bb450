"""The PMW33xx emulators' timing model against sequences written from the datasheet's table.

[DS3360] Table 4 (AC Electrical Specifications), sec. 4 (burst), sec. 5 / Figure 22 (SROM),
sec. 7 (power up), SROM_Enable (CRC test). A byte takes 4 us at 2 MHz; the gaps below are
each constraint's minimum EXACTLY, with chip select raised between commands (as QMK and the
Arduino sketches do): 0 errors. Each gap shortened below its minimum: exactly one error,
named. No vendor code here: the sequences follow the datasheet's tables.
"""

from __future__ import annotations

import pytest
from fakes import FakeClock

from pln2033.chips import make_driver, make_emulator
from pln2033.motion import ConstantVelocity
from pln2033.pmw33xx import regs as R  # noqa: N812
from pln2033.pmw33xx import timing as T  # noqa: N812

BLOB = bytes((i * 7 + 3) & 0xFF for i in range(R.SROM_LENGTH))  # a stand-in, not PixArt's
BYTE_US = 4.0  # one byte at 2 MHz
W = R.WRITE_FLAG
NCS = R.T_NCS_SCLK_US  # waited after chip select falls, and kept before it rises after a read
T_W = R.T_SCLK_NCS_WRITE_US  # chip select kept low after a write

# how far each constraint is shortened (us): 1 us, or 0.02 us for the sub-microsecond ones
CUTS = {
    T.TSWW: 1.0,
    T.TSWR: 1.0,
    T.TSRW: 1.0,
    T.TSRR: 1.0,
    T.TSRAD: 1.0,
    T.TSRAD_MOTBR: 1.0,
    T.TBEXIT: 0.1,
    T.TNCS_SCLK: 0.02,
    T.TSCLK_NCS_WRITE: 1.0,
    T.POWER_UP_WAIT: 1.0,
    T.SROM_INIT_WAIT: 1.0,
    T.CRC_WAIT: 1.0,
    T.SROM_BYTE: 1.0,
    T.SROM_END_WAIT: 1.0,
}


def test_every_constraint_of_the_model_is_exercised():
    names = {v for k, v in vars(T).items() if k.isupper() and isinstance(v, str)}
    assert set(CUTS) == names


def datasheet_sequence(short: str | None = None) -> list[tuple[list, float]]:
    """(frame segments, chip select high after it in us): the power-up sequence, the SROM
    download, CPI, two motion bursts, a read and the CRC self test; every gap at its
    minimum, the one named ``short`` shortened by CUTS[short]."""

    def cut(name: str, us: float) -> float:
        return us - CUTS[name] if short == name else us

    def write(reg: int, value: int, low: float = T_W) -> list:
        return [([], NCS), ([reg | W, value], low)]

    def read(reg: int, tsrad: float = R.T_SRAD_US, setup: float = NCS) -> list:
        return [([], setup), ([reg], tsrad), ([0], NCS)]

    def burst(tsrad: float = R.T_SRAD_MOTBR_US) -> list:
        return [([], NCS), ([0x50], tsrad), ([0] * R.BURST_LENGTH, 0)]

    # chip select high so that the gap to the next command is exactly its minimum
    w_w = R.T_SWW_US - T_W - NCS - 2 * BYTE_US  # to the end of the next write's data byte
    w_r = R.T_SWR_US - T_W - NCS - BYTE_US  # to the end of the next read's address byte
    r_r = R.T_SRR_US - 2 * NCS  # from the read's last bit to the next address
    r_w = R.T_SRW_US - 2 * NCS

    def wait(us: float) -> float:  # a write's own wait (reset, SROM, CRC), to the next start
        return us - T_W - NCS

    short_low = cut(T.TSCLK_NCS_WRITE, T_W)  # chip select risen early, the gap kept
    srom = [([], NCS), ([0x62 | W], R.T_SROM_BYTE_US)]
    srom += [([b], cut(T.SROM_BYTE, 15.0) if k == 100 else 15.0) for k, b in enumerate(BLOB)]
    return [
        (write(0x3A, 0x5A), cut(T.POWER_UP_WAIT, wait(R.T_RESET_S * 1e6))),
        (read(0x02), r_r),
        (read(0x03, tsrad=cut(T.TSRAD, R.T_SRAD_US)), cut(T.TSRR, r_r)),
        (read(0x04), r_r),
        (read(0x05), r_r),
        (read(0x06), cut(T.TSRW, r_w)),
        (write(0x10, 0x00, low=short_low), cut(T.TSWW, w_w) + (T_W - short_low)),
        (write(0x13, 0x1D), cut(T.SROM_INIT_WAIT, wait(R.T_SROM_INIT_S * 1e6))),
        # SROM_Enable 0x18 -> the burst's byte 1 ends tSWW later (address, 15 us, byte)
        (write(0x13, 0x18), w_w - R.T_SROM_BYTE_US),
        (srom, cut(T.SROM_END_WAIT, R.T_SROM_END_US - 15.0 - NCS)),
        (read(0x2A), r_w),  # SROM_ID
        (write(0x10, 0x00), w_w),
        (write(0x0F, 0x31), w_w),  # Config1: 5000 cpi
        (write(0x50, 0x00), cut(T.TSWR, w_r)),  # arm the burst
        (burst(tsrad=cut(T.TSRAD_MOTBR, R.T_SRAD_MOTBR_US)), cut(T.TBEXIT, R.T_BEXIT_US)),
        (burst(), R.T_BEXIT_US),
        (read(0x00, setup=cut(T.TNCS_SCLK, NCS)), r_w),  # Product_ID
        (write(0x13, 0x15), cut(T.CRC_WAIT, wait(R.T_CRC_S * 1e6))),
        (read(0x26), r_r),
        (read(0x25), r_r),
    ]


def run(chip: str, steps: list[tuple[list, float]], seed: int = 0):
    """Drive a fresh emulator (the controller's own chip-select setup and minimum high time
    set to 0: the sequence's own waits are the only ones) and return it and each frame's
    received bytes."""
    clock = FakeClock(1.0)
    emu = make_emulator(
        chip, clock=clock, srom=BLOB, cs_setup_us=0.0, min_cs_high_us=0.0, seed=seed
    )
    rx = []
    for segments, high_us in steps:
        rx.append(emu.xfer_segments(segments))
        clock.t += high_us * 1e-6
    return emu, rx


@pytest.mark.parametrize("chip", ["pmw3360", "pmw3389"])
def test_the_datasheet_sequence_with_every_gap_at_its_minimum_is_clean(chip):
    emu, rx = run(chip, datasheet_sequence())
    assert emu.stats.protocol_errors == 0 and not emu.timing_errors
    assert emu.srom_running and emu.srom_intact
    assert rx[10][2] == [0x04]  # SROM_ID after the upload
    assert rx[16][2] == [emu.product_id]
    assert (rx[18][2][0] << 8) | rx[19][2][0] == R.SROM_CRC_PASS
    assert rx[14][2][0] & R.MOTION_RESET  # the burst's Motion byte


@pytest.mark.parametrize("name", sorted(CUTS))
def test_each_gap_shortened_below_its_minimum_is_exactly_one_error(name):
    emu, _rx = run("pmw3360", datasheet_sequence(short=name))
    assert emu.timing_errors == {name: 1}
    assert emu.stats.protocol_errors == 1


@pytest.mark.parametrize(
    ("name", "frame"),
    [
        (T.TSRAD, 2),  # Motion_Delta_X_L read with a short tSRAD
        (T.TSRR, 3),  # the read after a short tSRR
        (T.POWER_UP_WAIT, 1),  # the first read after the reset
        (T.TNCS_SCLK, 16),  # Product_ID
        (T.CRC_WAIT, 18),  # Data_Out_Upper
        (T.TBEXIT, 15),  # the burst after a short tBEXIT
        (T.TSRAD_MOTBR, 14),
    ],
)
def test_a_read_that_breaks_a_constraint_returns_garbage(name, frame):
    good = run("pmw3360", datasheet_sequence())[1][frame][-1]
    seen = [run("pmw3360", datasheet_sequence(short=name), seed)[1][frame][-1] for seed in range(8)]
    assert good not in seen[:1] or seen[1] != good
    assert len({tuple(rx) for rx in seen}) > 1  # random bytes, not a value


def test_a_write_during_the_reset_wait_is_lost_a_hurried_one_is_applied():
    steps = datasheet_sequence(short=T.POWER_UP_WAIT)
    steps[1] = ([([], NCS), ([0x0F | W, 0x77], T_W)], 200.0)  # Config1 during the reset
    emu, _ = run("pmw3360", steps)
    assert emu.timing_errors[T.POWER_UP_WAIT] == 1 and emu.cpi_y != 12000
    steps = datasheet_sequence(short=T.TSWW)
    steps[7] = ([([], NCS), ([0x0F | W, 0x77], T_W)], 10_000.0)  # 0x1D replaced by Config1
    emu, _ = run("pmw3360", steps[:8])
    assert emu.timing_errors == {T.TSWW: 1} and emu.cpi_y == 12000


def test_qmk_style_write_low_35_then_high_145_is_clean_and_writes_36_us_apart_are_not():
    """The issue's case: chip select low 35 us after each write, then 145 us high (the
    datasheet's tSCLK-NCS + the rest of tSWW), against writes 36 us apart."""
    clock = FakeClock(1.0)
    emu = make_emulator("pmw3360", clock=clock)
    for value in (0x07, 0x0F, 0x31):
        emu.xfer_segments([([], 1.0), ([0x0F | W, value], 35.0)])
        clock.t += 145e-6
    assert emu.stats.protocol_errors == 0 and emu.cpi_y == 5000
    for value in (0x07, 0x0F, 0x31):
        emu.xfer_segments([([], 1.0), ([0x0F | W, value], 35.0)])
        clock.t += 1e-6  # the next write 36 us later
    assert emu.timing_errors == {T.TSWW: 2}  # the second and the third write
    assert emu.stats.protocol_errors == 2


def srom_download(emu, clock, after_upload: list) -> list:
    """Reset, SROM_Enable 0x1D, 10 ms, 0x18, the upload (15 us between bytes) with
    ``after_upload`` segments in the SAME frame (chip select not raised)."""
    emu.xfer_segments([([0x3A | W, 0x5A], 180)])
    clock.t += 0.050
    emu.xfer_segments([([0x13 | W, 0x1D], 180)])
    clock.t += 0.010
    emu.xfer_segments([([0x13 | W, 0x18], 180)])
    segs = [([0x62 | W], 15)] + [([b], 15) for b in BLOB] + after_upload
    return emu.xfer_segments(segs)


def test_srom_id_read_before_chip_select_rises_is_accepted_as_hardware_does():
    """The Arduino sketch reads SROM_ID right after the last SROM byte without raising chip
    select (users report it works); QMK waits 200 us first. The chip takes srom_length
    bytes, so both uploads run; only reading sooner than Figure 22's 200 us is counted."""
    clock = FakeClock(1.0)
    emu = make_emulator("pmw3360", clock=clock, srom=BLOB)
    rx = srom_download(emu, clock, [([], 185), ([0x2A], 160), ([0], 20)])  # 200 us, then read
    assert emu.srom_running and emu.srom_intact and rx[-1] == [0x04]
    assert emu.stats.protocol_errors == 0
    clock = FakeClock(1.0)
    emu = make_emulator("pmw3360", clock=clock, srom=BLOB)
    srom_download(emu, clock, [([0x2A], 160), ([0], 20)])  # 15 us after the last byte
    assert emu.srom_running and emu.srom_intact  # the SROM runs, as reported
    assert emu.timing_errors == {T.SROM_END_WAIT: 1}  # that one read came too soon
    clock.t += 0.001
    assert emu.xfer_segments([([0x2A], 160), ([0], 20)])[1] == [0x04]


@pytest.mark.parametrize("chip", ["pmw3360", "pmw3389"])
def test_our_driver_stays_compliant_through_init_cpi_changes_dumps_and_bursts(chip):
    clock = FakeClock()
    emu = make_emulator(chip, clock=clock, srom=BLOB)
    drv = make_driver(chip, emu, name="/dev/spidev1.0", sleep=clock.sleep)
    drv.initialise(1600, firmware=list(BLOB))
    for cpi in (400, 800, 3200, 1600):
        drv.set_cpi(cpi)
        drv.read_motion()  # back to back: the clock did not move
        clock.t += 0.001
        drv.read_motion()
    drv.read_all_registers()
    for _ in range(200):
        clock.t += 0.001
        drv.read_motion()
    drv.initialise(1600, firmware=list(BLOB))  # again, straight after a burst
    assert emu.stats.protocol_errors == 0 and not emu.timing_errors
    assert emu.srom_intact and drv.srom_version == 0x04


def test_a_power_cycle_makes_the_chip_deaf_for_50_ms():
    clock = FakeClock()
    emu = make_emulator("pmw3360", clock=clock)
    drv = make_driver("pmw3360", emu, name="/dev/spidev1.0", sleep=clock.sleep)
    drv.initialise(1600)
    emu.power_cycle()
    emu.xfer_segments([([0x00], 160), ([0], 20)])
    assert emu.timing_errors == {T.POWER_UP_WAIT: 1}
    clock.t += 0.050
    assert emu.xfer_segments([([0x00], 160), ([0], 20)])[1] == [0x42]


def qmk_style_init(chip: str, emu, clock) -> list:
    """The bring-up as QMK's pmw33xx driver times it (its waits, read for facts, no code):
    1 us after chip select falls; a write keeps it low 35 us, then 145 us high; a read waits
    160 us, 1 us, then 19 us high; the upload 15 us per byte and 200 us after the last,
    SROM_ID read straight after; reset 50 ms, SROM init 10 ms. Returns the SROM_ID read."""

    def write(reg: int, value: int) -> None:
        emu.xfer_segments([([], 1), ([reg | W, value], 35)])
        clock.t += 145e-6

    def read(reg: int) -> int:
        rx = emu.xfer_segments([([], 1), ([reg], 160), ([0], 1)])
        clock.t += 19e-6
        return rx[2][0]

    emu.xfer_segments([([], 40)])  # chip select low 40 us, then high 40 us: the port reset
    clock.t += 40e-6
    write(0x3A, 0x5A)
    clock.t += 0.050
    for reg in (0x02, 0x03, 0x04, 0x05, 0x06):
        read(reg)
    write(0x13, 0x1D)
    clock.t += 0.010
    write(0x13, 0x18)
    segs = [([], 1), ([0x62 | W], 15)] + [([b], 15) for b in BLOB]
    segs += [([], 200), ([0x2A], 160), ([0], 1)]  # SROM_ID before chip select rises
    srom_id = emu.xfer_segments(segs)[-1][0]
    clock.t += 19e-6
    write(0x10, 0x00)
    clock.t += 0.010
    if chip == "pmw3389":
        write(0x0F, 0x00)  # Resolution_H, then _L: 1600 cpi
        write(0x0E, 0x1F)
    else:
        write(0x0F, 0x0F)  # Config1: 1600 cpi
    clock.t += 0.001
    write(0x10, 0x00)
    write(0x11, 0x00)  # Angle_Tune
    write(0x63, 0x02)  # Lift_Config
    for reg in (0x00, 0x3F, 0x2A):  # the signature
        read(reg)
    write(0x50, 0x00)
    for _ in range(10):  # bursts at 1 kHz, chip select raised after each
        emu.xfer_segments([([], 1), ([0x50], 35), ([0] * 12, 0)])
        clock.t += 0.001
    return [srom_id]


@pytest.mark.parametrize("chip", ["pmw3360", "pmw3389"])
def test_qmk_timed_bring_up_is_clean(chip):
    clock = FakeClock(1.0)
    emu = make_emulator(chip, clock=clock, srom=BLOB)
    assert qmk_style_init(chip, emu, clock) == [0x04]
    assert emu.stats.protocol_errors == 0 and not emu.timing_errors
    assert emu.srom_intact and emu.cpi_y == 1600


def arduino_sketch_init(emu, clock, bursts: list, cpi: int = 1200) -> list[int]:
    """The bring-up as the widely used PMW3360 Arduino sketch times it ([ARD]
    PMW3360DM-Burst.ino, read for its waits, no code): reads wait 35 us (tSRAD) + 1 us, then
    19 us high; writes keep chip select low 20 us, then 100 us high; the upload 15 us per
    byte and SROM_ID read 15 us after the last one BEFORE chip select rises (its result
    unused); then dispRegisters' four reads in one frame, 1 ms around each data byte, and
    ten motion bursts at 1 kHz (35 us), appended to ``bursts``. Returns what dispRegisters
    printed: Product_ID, Inverse_Product_ID, SROM_Version."""

    def write(reg: int, value: int) -> None:
        emu.xfer_segments([([], 1), ([reg | W, value], 20)])
        clock.t += 100e-6

    def read(reg: int) -> int:
        rx = emu.xfer_segments([([], 1), ([reg], 35), ([0], 1)])
        clock.t += 19e-6
        return rx[2][0]

    write(0x3A, 0x5A)  # Power_Up_Reset
    clock.t += 0.050
    for reg in (0x02, 0x03, 0x04, 0x05, 0x06):
        read(reg)
    write(0x10, 0x20)  # Config2
    write(0x13, 0x1D)  # SROM_Enable: init
    clock.t += 0.010
    write(0x13, 0x18)  # start the download
    segs = [([], 1), ([0x62 | W], 15)] + [([b], 15) for b in BLOB]
    segs += [([0x2A], 35), ([0], 1)]  # SROM_ID, chip select still low from the upload
    emu.xfer_segments(segs)
    clock.t += 19e-6
    write(0x10, 0x00)  # Config2: wired
    write(0x0F, cpi // 100 - 1)  # Config1
    clock.t += 0.010 + 2.0
    segs = []
    for reg in (0x00, 0x3F, 0x2A, 0x02):  # dispRegisters: one frame
        segs += [([reg], 1000), ([0], 1000)]
    rx = emu.xfer_segments(segs)
    write(0x50, 0x00)  # startBurst
    for _ in range(10):
        clock.t += 0.001
        burst = emu.xfer_segments([([], 1), ([0x50], 35), ([0] * 12, 1)])[2]
        bursts.append(burst)
    return [rx[1][0], rx[3][0], rx[5][0]]


def test_arduino_sketch_bring_up_runs_the_srom_and_counts_only_its_short_waits():
    """Users report the sketch works on hardware, so its SROM must run here too; its waits
    from the older ADNS-9800 sheet are counted against the PMW3360's table, each by name."""
    clock = FakeClock(1.0)
    emu = make_emulator("pmw3360", motion=ConstantVelocity(0.0, 0.1), clock=clock, srom=BLOB)
    bursts: list[list[int]] = []
    assert arduino_sketch_init(emu, clock, bursts) == [0x42, 0xBD, 0x04]  # its banner
    assert emu.srom_running and emu.srom_intact and emu.cpi_y == 1200
    # the bursts are data, not garbage: every one moved, with the SROM running, and those
    # after the first hold the 9 ms of motion since it (0.1 m/s at 1200 cpi)
    assert all(b[0] & R.MOT and b[1] & R.OB_SROM_RUN for b in bursts)
    dy = [int.from_bytes(bytes(b[4:6]), "little", signed=True) for b in bursts]
    assert sum(dy[1:]) == pytest.approx(0.1 * 0.009 / 0.0254 * 1200, abs=1)  # 42.5 counts
    assert emu.timing_errors == {
        T.TSRAD: 6,  # 35 us, not 160: the five reads after the reset and SROM_ID
        T.TSCLK_NCS_WRITE: 7,  # chip select raised 20 us after each of the 7 writes, not 35
        T.TSWW: 3,  # 120 us between writes: Config2 -> 0x1D, 0x18 -> the upload, -> Config1
        T.SROM_END_WAIT: 1,  # SROM_ID read 15 us after the last byte, not 200
    }
    assert emu.stats.protocol_errors == 17


def test_pinned_not_modelled_read_hold_srom_chip_select_hold_and_shutdown():
    """docs/sensors.md "The timing model", not modelled: tSCLK-NCS after a read (120 ns),
    the 15 us before chip select rises after the last SROM byte, Shutdown mode. Pinned, so
    that modelling any of them is a deliberate change."""
    clock = FakeClock(1.0)
    emu = make_emulator("pmw3360", motion=ConstantVelocity(0.0, 0.1), clock=clock, srom=BLOB)
    emu.xfer_segments([([0x3A | W, 0x5A], 180)])
    clock.t += 0.050
    for _ in range(2):  # chip select rises straight after the data byte (0 us, not 120 ns)
        assert emu.xfer_segments([([0x00], 160), ([0], 0)])[1] == [0x42]
        clock.t += 20e-6
    emu.xfer_segments([([0x13 | W, 0x1D], 180)])
    clock.t += 0.010
    emu.xfer_segments([([0x13 | W, 0x18], 180)])
    segs = [([0x62 | W], 15)] + [([b], 15) for b in BLOB[:-1]] + [([BLOB[-1]], 0)]
    emu.xfer_segments(segs)  # chip select rises at the last byte's last clock, not 15 us on
    clock.t += 200e-6
    assert emu.xfer_segments([([0x2A], 160), ([0], 20)])[1] == [0x04]
    emu.xfer_segments([([0x3B | W, R.SHUTDOWN_VALUE], 180)])  # Shutdown: the chip sleeps
    clock.t += 0.010
    assert emu.xfer_segments([([0x00], 160), ([0], 20)])[1] == [0x42]  # it still answers
    clock.t += 0.001
    emu.xfer_segments([([0x02], 160), ([0], 20)])
    clock.t += 20e-6
    rx = emu.xfer_segments([([0x05], 160), ([0], 20), ([0x06], 160), ([0], 20)])
    assert rx[1][0] | rx[3][0] << 8 > 0  # and it still counts
    assert emu.stats.protocol_errors == 0 and not emu.timing_errors


def test_pinned_bus_assumptions_half_a_clock_setup_1_us_high_bytes_at_the_clock_rate():
    """The emulator's assumptions about the host's controller (docs/sensors.md "The timing
    model"): chip select falls half a clock before the first SCLK (0.25 us at 2 MHz, meets
    tNCS-SCLK's 120 ns), stays high at least 1 us between two calls at one fake instant
    (meets tBEXIT's 500 ns), and a byte takes 8 clocks at ``sclk_hz`` (default 2 MHz)."""
    clock = FakeClock(1.0)
    emu = make_emulator("pmw3360", clock=clock)
    assert (emu.cs_setup_us, emu.min_cs_high_us, emu.byte_us) == (0.25, 1.0, 4.0)
    slow = make_emulator("pmw3360", clock=clock, sclk_hz=1_000_000)
    assert (slow.cs_setup_us, slow.byte_us) == (0.5, 8.0)
    emu.xfer_segments([([0x50 | W, 0x00], 180)])  # arm the burst
    clock.t += 0.001
    for _ in range(3):  # back to back, no leading delay, the clock standing still
        emu.xfer_segments([([0x50], 35), ([0] * 12, 0)])
    assert emu.stats.protocol_errors == 0 and not emu.timing_errors
