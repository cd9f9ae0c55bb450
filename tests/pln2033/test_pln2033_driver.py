"""The real PLN2033 driver against the register-level emulator.

Bytes on the wire, displacement counts against the emulator's ground truth,
CPI, power, reset, presence, the vendor patch and the patch file reader.
Every bad input is checked for its exception type, its message, and that
nothing changed (usually: not a single SPI transfer happened).
"""

from __future__ import annotations

import math

import pytest
from fakes import FakeClock
from hypothesis import given, settings
from hypothesis import strategies as st

from pln2033 import (
    INCH_M,
    InvalidCpiError,
    PatchError,
    SensorError,
    SensorNotRespondingError,
    SpiError,
)
from pln2033.motion import ConstantVelocity, Stationary
from pln2033.pln2033 import (
    PLN2033,
    REGISTER_NAMES,
    EmulatedPLN2033,
    RegisterMap,
    read_patch_file,
)

ALLOWED = "allowed: 100..6400 in steps of 100"
ALLOWED_CPI = list(range(100, 6401, 100))



class ZeroBus:
    """A bus with nothing on it: MISO tied low, every byte reads 0."""

    def __init__(self) -> None:
        self.sent: list[list[int]] = []

    def xfer2(self, data: list[int]) -> list[int]:
        self.sent.append(list(data))
        return [0] * len(data)

    def close(self) -> None:
        pass


class ShortBus:
    """Passes transfers to a real emulator but drops the last byte of the reply."""

    def __init__(self, inner: EmulatedPLN2033) -> None:
        self.inner = inner

    def xfer2(self, data: list[int]) -> list[int]:
        return self.inner.xfer2(data)[:-1]

    def close(self) -> None:
        pass


MAP = RegisterMap.default()  # parsed once: building it reads the YAML defaults


def make(motion=None, record=False, **kw):
    clock = FakeClock()
    emu = EmulatedPLN2033(motion or Stationary(), regmap=MAP, clock=clock, record=record, **kw)
    return clock, emu, PLN2033(emu, regmap=MAP)


def counts(metres: float, cpi: int) -> float:
    return metres * cpi / INCH_M


def frames(emu: EmulatedPLN2033) -> list[tuple[int, ...]]:
    """The bytes sent, one tuple per transfer."""
    return [tx for tx, _rx in emu.stats.history]


# --- bytes on the wire ------------------------------------------------------------------


def test_read_motion_sends_status_dx_dy_in_one_transfer():
    _clock, emu, drv = make(record=True)
    drv.read_motion()
    a = RegisterMap.default().addresses
    expected = (a["status"], 0, 0, a["delta_x_disp"], 0, 0, a["delta_y_disp"], 0, 0)
    assert expected == (0x00, 0, 0, 0x01, 0, 0, 0x02, 0, 0)
    assert frames(emu) == [expected]
    assert emu.stats.transfers == 1


def test_write_register_frame_is_address_or_write_flag_then_msb_first():
    _clock, emu, drv = make(record=True)
    drv.write_register("mode_control", 0xABCD)
    drv.write_register("interrupt_output", 0x0102)
    assert frames(emu) == [(0x07 | 0x80, 0xAB, 0xCD), (0x0C | 0x80, 0x01, 0x02)]
    assert emu.regs[0x07] == 0xABCD
    assert emu.regs[0x0C] == 0x0102


def test_read_register_frame_and_msb_first_decode():
    _clock, emu, drv = make(record=True)
    emu.regs[0x0B] = 0x8001
    assert drv.read_register("miscellaneous") == 0x8001
    assert emu.stats.history == [((0x0B, 0, 0), (0, 0x80, 0x01))]


@pytest.mark.parametrize("value", [-1, 0x10000, 1 << 20])
def test_write_register_rejects_values_over_16_bits(value):
    _clock, emu, drv = make(record=True)
    emu.regs[0x07] = 0x1111
    with pytest.raises(ValueError) as info:
        drv.write_register("mode_control", value)
    assert str(info.value) == f"register value {value} does not fit 16 bits"
    assert emu.stats.transfers == 0
    assert emu.regs[0x07] == 0x1111


@pytest.mark.parametrize("method", ["read_register", "write_register"])
def test_unknown_register_name_sends_nothing(method):
    _clock, emu, drv = make()
    args = ("stauts",) if method == "read_register" else ("stauts", 1)
    with pytest.raises(KeyError) as info:
        getattr(drv, method)(*args)
    assert "stauts" in str(info.value)
    assert emu.stats.transfers == 0


def test_read_all_registers_reads_all_13_in_order_in_one_transfer():
    _clock, emu, drv = make(record=True)
    emu.regs[0x07] = 0x0042  # mode_control
    emu.regs[0x0C] = 0xFEDC  # interrupt_output
    motion, values = drv.read_all_registers()
    assert frames(emu) == [tuple(b for i in range(13) for b in (i, 0, 0))]
    assert tuple(values) == REGISTER_NAMES
    assert values["mode_control"] == 0x0042
    assert values["interrupt_output"] == 0xFEDC
    assert values["mode_status"] == 0x0001
    assert (motion.dx, motion.dy, motion.moved, motion.lifted) == (0, 0, False, False)


def test_set_x_cpi_bytes():
    _clock, emu, drv = make(record=True)
    drv.set_x_cpi(800)
    assert frames(emu) == [
        (0x84, 0x00, 0x08),  # command_low <- 800 / 100
        (0x83, 0x00, 0x01),  # command_high <- set_x_cpi
        (0x04, 0x00, 0x00),  # read command_low
        (0x84, 0x00, 0x00),  # command_low <- 0
        (0x83, 0x00, 0x03),  # command_high <- get_x_cpi
        (0x04, 0x00, 0x00),  # read command_low: the answer
    ]
    assert emu.stats.history[-1][1] == (0, 0, 8)


def test_short_reply_is_an_spi_error():
    emu = EmulatedPLN2033(clock=FakeClock())
    drv = PLN2033(ShortBus(emu), name="left")
    with pytest.raises(SpiError) as info:
        drv.read_motion()
    assert str(info.value) == "left: sent 9 bytes, received 8"
    with pytest.raises(SpiError) as info:
        drv.read_register("mode_status")
    assert str(info.value) == "left: sent 3 bytes, received 2"


# --- counts -------------------------------------------------------------------------------


@given(st.integers(-0x8000, 0x7FFF), st.integers(-0x8000, 0x7FFF))
@settings(max_examples=200)
def test_signed_16_bit_round_trip(vx_counts, vy_counts):
    """Counts the emulator latched come back through the driver with their sign."""
    cpi = 1000
    # Half a count over the target, so the floor lands on it for either sign.
    motion = ConstantVelocity((vx_counts + 0.5) * INCH_M / cpi, (vy_counts + 0.5) * INCH_M / cpi)
    clock, _emu, drv = make(motion)
    clock.t = 1.0
    m = drv.read_motion()
    assert (m.dx, m.dy) == (vx_counts, vy_counts)
    assert not m.overflow
    assert m.moved == bool(vx_counts or vy_counts)


@pytest.mark.parametrize("cpi", [100, 400, 1000, 3200, 6400])
@pytest.mark.parametrize(("vx", "vy"), [(0.0, 0.5), (0.3, -0.2), (-0.7, 0.05), (-0.1, -1.0)])
def test_counts_follow_true_motion_within_one_count(cpi, vx, vy):
    clock, emu, drv = make(ConstantVelocity(vx, vy))
    drv.set_cpi(cpi)
    drv.read_motion()  # start from clean counters at t = 0
    sx = sy = 0
    reads = 500
    for i in range(1, reads + 1):
        clock.t = i * 0.002
        m = drv.read_motion()
        assert not m.overflow and not m.lifted
        sx += m.dx
        sy += m.dy
    t = clock.t
    assert abs(sx - math.floor(counts(vx * t, cpi))) <= 1
    assert abs(sy - math.floor(counts(vy * t, cpi))) <= 1
    # Conservation: every count the sensor made was read, none twice.
    assert (sx, sy) == (emu.stats.counted_x, emu.stats.counted_y)
    assert emu.stats.overwritten_x == emu.stats.overwritten_y == 0


@given(
    vx=st.floats(-2.0, 2.0),
    vy=st.floats(-2.0, 2.0),
    cpi=st.sampled_from(ALLOWED_CPI),
    intervals=st.lists(st.floats(1e-4, 0.05), min_size=1, max_size=60),
)
@settings(max_examples=100, deadline=None)
def test_conservation_of_counts_for_random_motion_and_poll_intervals(vx, vy, cpi, intervals):
    clock, emu, drv = make(ConstantVelocity(vx, vy))
    drv.set_cpi(cpi)
    drv.read_motion()
    t0 = clock.t
    sx = sy = 0
    for dt in intervals:
        clock.t += dt
        m = drv.read_motion()
        assert not m.overflow  # at most 2 m/s * 50 ms * 6400 CPI = 25197 counts per read
        sx += m.dx
        sy += m.dy
    assert (sx, sy) == (emu.stats.counted_x, emu.stats.counted_y)
    true_x = counts(vx * (clock.t - t0), cpi)
    true_y = counts(vy * (clock.t - t0), cpi)
    assert true_x - 1 - 1e-6 < sx <= true_x + 1e-6
    assert true_y - 1 - 1e-6 < sy <= true_y + 1e-6


def test_read_clears_the_counters():
    clock, _emu, drv = make(ConstantVelocity(0.01, 0.02))
    clock.t = 0.5
    first = drv.read_motion()
    assert first.dx == math.floor(counts(0.005, 1000))
    assert first.dy == math.floor(counts(0.010, 1000))
    assert first.moved
    second = drv.read_motion()  # no time passed
    assert (second.dx, second.dy, second.moved) == (0, 0, False)


def test_status_only_read_loses_the_latched_counts():
    """The original's bug: a settings read (status) ate the counters."""
    clock, emu, drv = make(ConstantVelocity(0.01, -0.02))
    clock.t = 1.0
    expected_x = math.floor(counts(0.01, 1000))
    expected_y = math.floor(counts(-0.02, 1000))
    status = drv.read_register("status")
    assert status & emu.map.status_motion
    m = drv.read_motion()
    assert (m.dx, m.dy) == (0, 0)
    assert (emu.stats.overwritten_x, emu.stats.overwritten_y) == (expected_x, expected_y)
    assert (emu.stats.counted_x, emu.stats.counted_y) == (expected_x, expected_y)


def test_read_all_registers_hands_on_the_counts_it_cleared():
    """Our fix: the settings read returns the displacement it latched."""
    clock, emu, drv = make(ConstantVelocity(0.01, -0.02))
    clock.t = 1.0
    expected_x = math.floor(counts(0.01, 1000))
    expected_y = math.floor(counts(-0.02, 1000))
    motion, values = drv.read_all_registers()
    assert (motion.dx, motion.dy, motion.moved) == (expected_x, expected_y, True)
    assert values["status"] == motion.status
    assert values["delta_x_disp"] == expected_x & 0xFFFF
    assert values["delta_y_disp"] == expected_y & 0xFFFF
    after = drv.read_motion()
    assert (after.dx, after.dy) == (0, 0)
    assert emu.stats.overwritten_x == emu.stats.overwritten_y == 0
    assert (motion.dx + after.dx, motion.dy + after.dy) == (
        emu.stats.counted_x,
        emu.stats.counted_y,
    )


def test_settings_reads_between_motion_reads_conserve_counts():
    clock, emu, drv = make(ConstantVelocity(-0.3, 0.4))
    drv.set_cpi(2400)
    sx = sy = 0
    for i in range(1, 301):
        clock.t = i * 0.001
        m = drv.read_all_registers()[0] if i % 7 == 0 else drv.read_motion()
        sx += m.dx
        sy += m.dy
    assert (sx, sy) == (emu.stats.counted_x, emu.stats.counted_y)
    assert sy > 0 > sx


def test_overflow_when_reading_too_rarely():
    clock, emu, drv = make(ConstantVelocity(0.5, 0.0))
    drv.set_cpi(6400)
    drv.read_motion()
    clock.t = 1.0
    m = drv.read_motion()
    true = math.floor(counts(0.5, 6400))
    assert true == 125984
    assert m.dx == ((true + 0x8000) & 0xFFFF) - 0x8000 == -5088
    assert m.overflow
    assert m.status & emu.map.status_overflow_x
    assert not m.status & emu.map.status_overflow_y
    assert emu.stats.overflow_events == 1
    clock.t = 1.001
    m2 = drv.read_motion()
    assert not m2.overflow
    assert m2.dx == pytest.approx(counts(0.5 * 0.001, 6400), abs=1)


def test_overflow_on_y_sets_the_y_bit_and_negative_wraps():
    clock, emu, drv = make(ConstantVelocity(0.0, -0.2))
    drv.set_cpi(6400)
    drv.read_motion()
    clock.t = 1.0
    m = drv.read_motion()
    true = math.floor(counts(-0.2, 6400))
    assert true < -0x8000
    assert m.dy == ((true + 0x8000) & 0xFFFF) - 0x8000
    assert m.overflow
    assert m.status & emu.map.status_overflow_y
    assert not m.status & emu.map.status_overflow_x
    assert emu.stats.overflow_events == 1


# --- CPI ------------------------------------------------------------------------------------


@pytest.mark.parametrize("cpi", [100, 6400])
def test_set_cpi_extremes_round_trip(cpi):
    _clock, emu, drv = make()
    drv.set_cpi(cpi)
    assert (drv.get_x_cpi(), drv.get_y_cpi()) == (cpi, cpi)
    assert (emu.cpi_x, emu.cpi_y) == (cpi, cpi)


def test_every_allowed_cpi_round_trips():
    _clock, emu, drv = make()
    for cpi in ALLOWED_CPI:
        drv.set_cpi(cpi)
        assert (drv.get_x_cpi(), drv.get_y_cpi(), emu.cpi_x, emu.cpi_y) == (cpi,) * 4


def test_default_cpi_after_power_up():
    _clock, _emu, drv = make()
    assert (drv.get_x_cpi(), drv.get_y_cpi()) == (1000, 1000)


def test_set_x_cpi_alone_leaves_y():
    _clock, emu, drv = make()
    drv.set_y_cpi(400)
    drv.set_x_cpi(3200)
    assert (drv.get_x_cpi(), drv.get_y_cpi()) == (3200, 400)
    assert (emu.cpi_x, emu.cpi_y) == (3200, 400)
    drv.set_y_cpi(6400)
    assert (emu.cpi_x, emu.cpi_y) == (3200, 6400)


BAD_CPI = [
    (0, "CPI 0 is out of range"),
    (99, "CPI 99 is out of range"),
    (150, "CPI 150 is not supported by the sensor's encoding"),
    (6401, "CPI 6401 is out of range"),
    (65535, "CPI 65535 is out of range"),
    (-100, "CPI -100 is out of range"),
    (1.5, "CPI must be an integer, got 1.5"),
    ("800", "CPI must be an integer, got '800'"),
    (True, "CPI must be an integer, got True"),
]


@pytest.mark.parametrize(("cpi", "fragment"), BAD_CPI)
@pytest.mark.parametrize("method", ["set_cpi", "set_x_cpi", "set_y_cpi", "initialise"])
def test_bad_cpi_is_rejected_before_any_transfer(method, cpi, fragment):
    _clock, emu, drv = make()
    drv.set_cpi(2000)
    before = emu.stats.transfers
    with pytest.raises(InvalidCpiError) as info:
        getattr(drv, method)(cpi)
    message = str(info.value)
    assert fragment in message
    assert ALLOWED in message
    assert emu.stats.transfers == before
    assert (emu.cpi_x, emu.cpi_y) == (2000, 2000)
    assert emu.stats.resets == 0


def test_invalid_cpi_error_is_a_value_error():
    _clock, _emu, drv = make()
    with pytest.raises(ValueError, match="out of range"):
        drv.set_cpi(0)


def test_cpi_that_does_not_stick_is_reported():
    """The driver reads the resolution back: a chip that ignored it is caught."""
    clock = FakeClock()
    emu = EmulatedPLN2033(clock=clock)  # the chip knows only up to 6400 CPI
    wide = RegisterMap.from_dict({"cpi": {"max": 12800}})
    drv = PLN2033(emu, regmap=wide, name="rear")
    with pytest.raises(SensorError) as info:
        drv.set_x_cpi(12800)
    assert str(info.value) == "rear: X resolution reads back 1000 CPI, set 12800"
    assert emu.cpi_x == 1000


def test_counts_scale_with_cpi():
    got = {}
    for cpi in (400, 3200):
        clock, _emu, drv = make(ConstantVelocity(0.0, 0.1))
        drv.set_cpi(cpi)
        clock.t = 0.25
        got[cpi] = drv.read_motion().dy
    assert got[400] == math.floor(counts(0.025, 400))
    assert got[3200] == math.floor(counts(0.025, 3200))
    assert got[3200] == pytest.approx(8 * got[400], abs=8)


# --- power, reset, presence ----------------------------------------------------------------


def test_soft_reset_restores_the_power_up_state():
    clock, emu, drv = make(ConstantVelocity(0.01, 0.01))
    drv.set_cpi(3200)
    drv.load_patch([0x1111, 0x2222])
    drv.write_register("mode_control", 0x00F0)
    drv.power_down()
    assert not emu.powered and emu.patch_enabled
    drv.power_up()
    clock.t = 0.5
    emu.advance()  # counts waiting in the sensor
    assert emu.acc_x > 0
    drv.soft_reset()
    assert emu.stats.resets == 1
    assert (drv.get_x_cpi(), drv.get_y_cpi()) == (1000, 1000)
    assert drv.read_register("mode_control") == 0
    assert drv.read_register("mode_status") == 0x0001
    assert emu.powered
    assert not emu.patch_enabled
    assert emu.ram[:2] == [0, 0]
    m = drv.read_motion()  # the counters went with the reset
    assert (m.dx, m.dy) == (0, 0)


def test_power_down_stops_counting_and_power_up_resumes():
    clock, emu, drv = make(ConstantVelocity(0.0, 0.1))
    drv.write_register("power_control", 0x0100)  # an unrelated bit, kept throughout
    drv.read_motion()
    drv.power_down()
    assert not emu.powered
    assert drv.read_register("power_control") == 0x0101
    clock.t = 1.0
    m = drv.read_motion()
    assert (m.dx, m.dy) == (0, 0)
    assert emu.stats.counted_y == 0
    drv.power_up()
    assert emu.powered
    assert drv.read_register("power_control") == 0x0100
    clock.t = 1.5
    m = drv.read_motion()
    assert m.dy == math.floor(counts(0.05, 1000))
    assert emu.stats.counted_y == m.dy


def test_check_presence_passes_on_the_emulator_and_leaves_the_pointer_at_zero():
    _clock, emu, drv = make(record=True)
    drv.check_presence()
    assert frames(emu)[0] == (0x85, 0x0A, 0x5A)
    assert drv.read_register("memory_pointer") == 0


def test_check_presence_without_response():
    _clock, emu, drv = make()
    emu.fault = "no_response"
    with pytest.raises(SensorNotRespondingError) as info:
        drv.check_presence()
    message = str(info.value)
    assert "wrote 0x0a5a to the memory pointer, read back 0xffff" in message
    assert "wiring" in message


def test_check_presence_on_an_empty_bus():
    bus = ZeroBus()
    drv = PLN2033(bus, name="/dev/spidev1.1")
    with pytest.raises(SensorNotRespondingError) as info:
        drv.check_presence()
    message = str(info.value)
    assert message.startswith("/dev/spidev1.1: no PLN2033 answers")
    assert "read back 0x0000" in message
    assert "wiring" in message
    assert bus.sent[0] == [0x85, 0x0A, 0x5A]


def test_read_motion_with_status_all_ones_is_sensor_not_responding():
    _clock, emu, drv = make()
    emu.fault = "no_response"
    with pytest.raises(SensorNotRespondingError) as info:
        drv.read_motion()
    message = str(info.value)
    assert "status register reads 0xffff (reserved bits set)" in message
    assert "wiring" in message
    with pytest.raises(SensorNotRespondingError, match="0xffff"):
        drv.read_all_registers()
    emu.fault = None
    assert drv.read_motion().dx == 0


def test_fault_raise_is_an_spi_error():
    clock, emu, drv = make(ConstantVelocity(0.01, 0.0))
    emu.fault = "raise"
    clock.t = 0.1
    with pytest.raises(SpiError, match="Remote I/O error"):
        drv.read_motion()
    with pytest.raises(SpiError):
        drv.set_cpi(800)
    assert emu.cpi_x == 1000
    assert emu.stats.faulted_transfers == 2
    emu.fault = None
    # The counts waited in the sensor; nothing was lost to the failed reads.
    assert drv.read_motion().dx == math.floor(counts(0.001, 1000))


def test_initialise_brings_the_sensor_up():
    clock, emu, drv = make(ConstantVelocity(0.01, 0.0))
    drv.power_down()
    clock.t = 0.2
    emu.advance()
    drv.initialise(2400, firmware=[0xCAFE, 0xF00D, 0x0001])
    assert emu.stats.resets == 1
    assert emu.powered and emu.patch_enabled
    assert emu.ram[:3] == [0xCAFE, 0xF00D, 0x0001]
    assert (emu.cpi_x, emu.cpi_y) == (2400, 2400)
    assert drv.read_motion().dx == 0  # initialise left clean counters
    clock.t = 0.3
    assert drv.read_motion().dx == math.floor(counts(0.001, 2400))


def test_initialise_without_a_sensor():
    drv = PLN2033(ZeroBus())
    with pytest.raises(SensorNotRespondingError, match="wiring"):
        drv.initialise(1000)


# --- vendor patch ---------------------------------------------------------------------------


def test_load_patch_writes_verifies_and_enables():
    _clock, emu, drv = make(record=True)
    words = [0x0000, 0xFFFF, 0x1234, 0x8000, 0x00FF]
    drv.load_patch(words)
    assert emu.ram[: len(words)] == words
    assert emu.ram[len(words)] == 0
    assert emu.patch_enabled
    drv.verify_patch(words)
    sent = frames(emu)
    assert sent[0] == (0x85, 0, 0)  # memory pointer <- patch_start
    assert sent[1 : 1 + len(words)] == [(0x86, w >> 8, w & 0xFF) for w in words]


def test_load_patch_at_an_offset_keeps_other_system_control_bits():
    m = RegisterMap.from_dict({"memory": {"patch_start": 0x0100}})
    emu = EmulatedPLN2033(regmap=m, clock=FakeClock())
    drv = PLN2033(emu, regmap=m)
    drv.write_register("system_control", 0x0010)
    drv.load_patch([0xAAAA, 0x5555])
    assert emu.ram[0x100:0x102] == [0xAAAA, 0x5555]
    assert emu.ram[:2] == [0, 0]
    assert drv.read_register("system_control") == 0x0012


@pytest.mark.parametrize("index", [0, 3, 9])
def test_verify_patch_names_the_corrupted_word(index):
    _clock, emu, drv = make()
    words = list(range(0x100, 0x10A))
    drv.load_patch(words)
    emu.ram[index] ^= 0x0040
    with pytest.raises(PatchError) as info:
        drv.verify_patch(words)
    assert str(info.value) == (
        f"pln2033: patch code verify failed at word {index} (address {index:#06x}): "
        f"wrote {words[index]:#06x}, read {words[index] ^ 0x40:#06x}"
    )


def test_load_patch_does_not_enable_a_patch_that_failed_to_verify():
    class StuckBitBus:
        """The emulator behind a MOSI line whose bit 0 of the data LSB is stuck low."""

        def __init__(self, inner):
            self.inner = inner

        def xfer2(self, data):
            if data[0] == 0x86:
                data = [data[0], data[1], data[2] & 0xFE]
            return self.inner.xfer2(data)

        def close(self):
            pass

    emu = EmulatedPLN2033(clock=FakeClock())
    drv = PLN2033(StuckBitBus(emu))
    with pytest.raises(PatchError, match="word 1 "):
        drv.load_patch([0x1000, 0x2001])
    assert not emu.patch_enabled


BAD_PATCHES = [
    ([], "the patch code is empty"),
    ([0] * 4097, "the patch code has 4097 words; the DSP RAM holds 4096"),
    ([1, 0x10000], "patch words must be 16-bit, got 65536"),
    ([-1], "patch words must be 16-bit, got -1"),
    ([0x10, 1.5], "patch words must be 16-bit, got 1.5"),
    (["0x10"], "patch words must be 16-bit, got '0x10'"),
    ([True], "patch words must be 16-bit, got True"),
]


@pytest.mark.parametrize(("words", "message"), BAD_PATCHES)
@pytest.mark.parametrize("method", ["load_patch", "verify_patch"])
def test_bad_patch_is_rejected_before_any_transfer(method, words, message):
    _clock, emu, drv = make()
    drv.load_patch([0x0102, 0x0304])
    ram = list(emu.ram)
    before = emu.stats.transfers
    with pytest.raises(PatchError) as info:
        getattr(drv, method)(words)
    assert str(info.value) == message
    assert emu.stats.transfers == before
    assert emu.ram == ram


def test_patch_too_long_for_the_room_after_patch_start():
    m = RegisterMap.from_dict({"memory": {"patch_start": 0x0F00}})
    emu = EmulatedPLN2033(regmap=m, clock=FakeClock())
    drv = PLN2033(emu, regmap=m)
    with pytest.raises(PatchError) as info:
        drv.load_patch([1] * 257)
    assert str(info.value) == "the patch code has 257 words; the DSP RAM holds 256"
    assert emu.stats.transfers == 0
    drv.load_patch([1] * 256)
    assert emu.ram[0xF00:] == [1] * 256


# --- patch files ------------------------------------------------------------------------------


def test_read_patch_file_hex_text(tmp_path):
    path = tmp_path / "patch.txt"
    path.write_text(
        "// PLN2033 patch, arrayConverter output\n"
        "{ 0x12, 0x34, 0xAB,\n"
        "  0xcd, 00, ff; # trailing comment 0x99\n"
        "  0x0 0x1 }  // 0x77\n"
    )
    assert read_patch_file(path) == [0x1234, 0xABCD, 0x00FF, 0x0001]


def test_read_patch_file_windows_line_endings(tmp_path):
    path = tmp_path / "patch.txt"
    path.write_bytes(b"0x12,0x34\r\n0x56,0x78\r\n")
    assert read_patch_file(path) == [0x1234, 0x5678]


@pytest.mark.parametrize(
    "data",
    [
        bytes([0x12, 0x34, 0xFF, 0x80]),
        bytes([0x00, 0x10, 0x20, 0x30]),  # every byte < 0x80: still not text
        bytes([0x00, 0x00]),
        bytes([0x30, 0x78, 0x31, 0x00]),  # "0x1" and a NUL: binary, not text
    ],
)
def test_read_patch_file_raw_binary(tmp_path, data):
    path = tmp_path / "patch.bin"
    path.write_bytes(data)
    words = [(data[i] << 8) | data[i + 1] for i in range(0, len(data), 2)]
    assert read_patch_file(path) == words


def test_patch_file_round_trip_through_the_sensor(tmp_path):
    path = tmp_path / "patch.bin"
    data = bytes(range(256)) * 4
    path.write_bytes(data)
    words = read_patch_file(path)
    assert len(words) == 512
    _clock, emu, drv = make()
    drv.load_patch(words)
    assert emu.ram[:512] == words
    drv.verify_patch(words)


@pytest.mark.parametrize(
    ("content", "fragment"),
    [
        (b"0x12, 0x34, 0x56", "has 3 bytes; 16-bit words need an even count"),
        (b"\x12\x34\x56\xff", None),  # even: fine (control for the odd case below)
        (b"\x12\x34\xff", "has 3 bytes; 16-bit words need an even count"),
        (b"0x12, 0xZZ", "'0xZZ' is not a hex byte (like 0x1f)"),
        (b"0x12 0x123", "'0x123' is not a hex byte (like 0x1f)"),
        (b"0x12 banana", "'banana' is not a hex byte (like 0x1f)"),
        (b"// nothing here\n# nor here\n", "has no bytes"),
        (b"", "has no bytes"),
    ],
)
def test_read_patch_file_errors(tmp_path, content, fragment):
    path = tmp_path / "patch.txt"
    path.write_bytes(content)
    if fragment is None:
        assert read_patch_file(path) == [0x1234, 0x56FF]
        return
    with pytest.raises(PatchError) as info:
        read_patch_file(path)
    message = str(info.value)
    assert message.startswith(f"patch file {path}")
    assert fragment in message


def test_read_patch_file_missing(tmp_path):
    path = tmp_path / "missing.hex"
    with pytest.raises(PatchError) as info:
        read_patch_file(path)
    assert str(info.value) == f"cannot read patch file {path}: No such file or directory"
