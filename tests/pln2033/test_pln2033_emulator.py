"""The register-level PLN2033 emulator: frames, counter latch, lifts, overflow,
noise, faults and its ground-truth statistics.

Where a driver call expresses the access, the real driver is used; raw
``xfer2`` frames are used only for what the driver never sends.
"""

from __future__ import annotations

import math

import pytest
from fakes import FakeClock
from hypothesis import given, settings
from hypothesis import strategies as st

from pln2033 import INCH_M, SensorNotRespondingError, SpiError
from pln2033.motion import ConstantVelocity, Stationary
from pln2033.pln2033 import PLN2033, EmulatedPLN2033, RegisterMap

MAP = RegisterMap.default()



def make(motion=None, **kw):
    clock = FakeClock()
    emu = EmulatedPLN2033(motion or Stationary(), regmap=MAP, clock=clock, **kw)
    return clock, emu, PLN2033(emu, regmap=MAP)


def counts(metres: float, cpi: int = 1000) -> float:
    return metres * cpi / INCH_M


def poll(clock, drv, until: float, step: float = 0.001, start: int = 1):
    """read_motion every ``step`` seconds up to ``until``; returns [(t, Motion)]."""
    out = []
    i = start
    while True:
        t = round(i * step, 9)
        if t > until:
            return out
        clock.t = t
        out.append((t, drv.read_motion()))
        i += 1


# --- power-up state and frames ------------------------------------------------------------


def test_power_up_state():
    _clock, emu, _drv = make()
    assert (emu.cpi_x, emu.cpi_y) == (1000, 1000)
    assert emu.powered
    assert not emu.patch_enabled
    assert emu.ram == [0] * 4096
    assert emu.regs[MAP.addresses["mode_status"]] == 0x0001
    assert emu.stats.resets == 0
    assert emu.stats.transfers == 0


def test_unknown_fault_mode_is_rejected():
    with pytest.raises(ValueError) as info:
        EmulatedPLN2033(fault_windows=[(0.0, 1.0, "melt")])
    assert str(info.value) == (
        "fault mode 'melt' unknown; allowed: ('raise', 'no_response', 'corrupt')"
    )


def test_partial_frame_is_a_protocol_error():
    _clock, emu, _drv = make()
    emu.regs[MAP.addresses["mode_control"]] = 0x1234
    rx = emu.xfer2([0x07, 0, 0, 0x09])
    assert rx == [0, 0x12, 0x34, 0]
    assert emu.stats.protocol_errors == 1
    assert emu.stats.transfers == 1


def test_read_only_registers_ignore_writes():
    clock, _emu, drv = make(ConstantVelocity(0.01, 0.0))
    clock.t = 1.0
    for name in ("status", "delta_x_disp", "delta_y_disp"):
        drv.write_register(name, 0x7777)
    m = drv.read_motion()
    assert m.dx == math.floor(counts(0.01))
    assert m.status == MAP.status_motion


def test_unmapped_address_reads_zero():
    _clock, emu, _drv = make()
    assert emu.xfer2([0x7E, 0xAA, 0xBB]) == [0, 0, 0]
    emu.xfer2([0x80 | 0x7E, 0x12, 0x34])  # a write to nowhere changes nothing
    assert 0x7E not in emu.regs


def test_memory_pointer_auto_increments_and_wraps():
    _clock, emu, drv = make()
    drv.write_register("memory_pointer", 4095)
    drv.write_register("memory_data", 0xAAAA)
    drv.write_register("memory_data", 0xBBBB)
    assert (emu.ram[4095], emu.ram[0]) == (0xAAAA, 0xBBBB)
    assert drv.read_register("memory_pointer") == 1
    drv.write_register("memory_pointer", 4095)
    assert [drv.read_register("memory_data") for _ in range(2)] == [0xAAAA, 0xBBBB]


def test_record_off_keeps_no_history():
    _clock, emu, drv = make()
    drv.read_motion()
    assert emu.stats.history == []
    assert emu.stats.transfers == 1


# --- the counter latch ---------------------------------------------------------------------


def test_status_latches_and_delta_reads_clear():
    clock, emu, drv = make(ConstantVelocity(0.01, -0.005))
    clock.t = 1.0
    nx, ny = math.floor(counts(0.01)), math.floor(counts(-0.005))
    assert drv.read_register("status") == MAP.status_motion
    assert (emu.acc_x, emu.acc_y, emu.latch_x, emu.latch_y) == (0, 0, nx, ny)
    assert drv.read_register("delta_x_disp") == nx
    assert drv.read_register("delta_x_disp") == 0  # read-and-clear
    assert drv.read_register("delta_y_disp") == ny & 0xFFFF
    assert drv.read_register("delta_y_disp") == 0
    assert emu.stats.overwritten_x == emu.stats.overwritten_y == 0


def test_second_status_read_overwrites_the_latch():
    clock, emu, drv = make(ConstantVelocity(0.01, 0.02))
    clock.t = 0.5
    drv.read_register("status")
    clock.t = 1.0
    drv.read_register("status")
    first_x, first_y = math.floor(counts(0.005)), math.floor(counts(0.01))
    assert (emu.stats.overwritten_x, emu.stats.overwritten_y) == (first_x, first_y)
    m = drv.read_motion()
    assert (m.dx, m.dy) == (0, 0)
    # The latch of the second status read was overwritten by read_motion's own.
    assert emu.stats.overwritten_x + m.dx == emu.stats.counted_x
    assert emu.stats.overwritten_y + m.dy == emu.stats.counted_y


def test_motion_bit_only_after_a_whole_count():
    clock, _emu, drv = make(ConstantVelocity(0.0, 1e-6))  # 0.039 counts per second
    clock.t = 1.0
    m = drv.read_motion()
    assert (m.moved, m.dy) == (False, 0)
    clock.t = 30.0  # 1.18 counts in all: the fraction was kept
    m = drv.read_motion()
    assert (m.moved, m.dy) == (True, 1)
    m = drv.read_motion()
    assert (m.moved, m.dy) == (False, 0)


def test_time_going_backwards_counts_nothing():
    clock, emu, drv = make(ConstantVelocity(0.1, 0.0))
    clock.t = 1.0
    first = drv.read_motion().dx
    clock.t = 0.5
    assert drv.read_motion().dx == 0
    clock.t = 1.0
    assert drv.read_motion().dx == 0
    assert emu.stats.counted_x == first


def test_cpi_change_keeps_the_position():
    """The sub-count fraction is rescaled: metres from counts stay within one count."""
    clock, emu, drv = make(ConstantVelocity(0.0, 0.1))
    drv.set_cpi(400)
    metres = 0.0
    for i, cpi in enumerate([3200, 100, 6400, 1100]):
        clock.t = 0.25 * (i + 1)
        metres += drv.read_motion().dy * INCH_M / emu.cpi_y
        drv.set_cpi(cpi)
    clock.t = 1.25
    metres += drv.read_motion().dy * INCH_M / 1100
    assert metres == pytest.approx(0.125, abs=INCH_M / 1100)


# --- noise ------------------------------------------------------------------------------------


def test_noise_keeps_conservation_and_is_reproducible():
    def run(seed):
        clock, emu, drv = make(ConstantVelocity(0.0, 0.05), noise_counts=20.0, seed=seed)
        reads = [m for _t, m in poll(clock, drv, 1.0)]
        return reads, emu

    reads, emu = run(7)
    sy = sum(m.dy for m in reads)
    assert sy == emu.stats.counted_y
    assert sum(m.dx for m in reads) == emu.stats.counted_x
    # Random-walk noise of 20 counts/sqrt(s) over 1 s: far below 2000 counts of motion.
    assert sy == pytest.approx(counts(0.05), abs=100)
    assert any(m.dx for m in reads)  # noise moved X although the sensor did not
    again, _ = run(7)
    assert [(m.dx, m.dy) for m in again] == [(m.dx, m.dy) for m in reads]
    other, _ = run(8)
    assert [(m.dx, m.dy) for m in other] != [(m.dx, m.dy) for m in reads]


def test_no_noise_no_counts_when_stationary():
    clock, emu, drv = make()
    reads = [m for _t, m in poll(clock, drv, 0.2)]
    assert all((m.dx, m.dy, m.moved) == (0, 0, False) for m in reads)
    assert emu.stats.counted_x == emu.stats.counted_y == 0


# --- lifts ---------------------------------------------------------------------------------------


def test_lift_window_sets_the_lift_bit_and_reads_zero():
    clock, emu, drv = make(ConstantVelocity(0.02, 0.1), lift_windows=[(0.5, 0.7)])
    reads = poll(clock, drv, 1.0)
    during = [m for t, m in reads if 0.5 < t <= 0.7]
    after = [m for t, m in reads if t > 0.7]
    before = [m for t, m in reads if t <= 0.5]
    # Exactly the 200 polls whose interval touched the window are lifted.
    assert len(during) == 200
    assert all(m.lifted and (m.dx, m.dy) == (0, 0) for m in during)
    assert all(m.status & MAP.status_lift for m in during)
    assert not any(m.lifted for m in before)
    assert not any(m.lifted for m in after)
    assert all(m.dy > 0 for m in before + after)
    assert emu.stats.lift_events == 1
    total_y = sum(m.dy for _t, m in reads)
    assert (total_y, sum(m.dx for _t, m in reads)) == (emu.stats.counted_y, emu.stats.counted_x)
    # About 0.2 s of motion never counted.
    assert total_y == pytest.approx(counts(0.1 * 0.8), abs=2 * counts(0.1 * 0.001) + 1)


def test_lift_clears_counts_nobody_read():
    clock, emu, drv = make(ConstantVelocity(0.01, -0.02), lift_windows=[(0.5, 0.7)])
    clock.t = 0.4
    first = drv.read_motion()
    clock.t = 0.45
    drv.read_register("mode_control")  # a transfer: the sensor counts up to now
    pending_x, pending_y = emu.acc_x, emu.acc_y
    assert pending_x == pytest.approx(counts(0.01 * 0.05), abs=1)
    assert pending_y == pytest.approx(counts(-0.02 * 0.05), abs=1)
    clock.t = 0.6
    m = drv.read_motion()
    assert m.lifted and (m.dx, m.dy) == (0, 0)
    assert (emu.stats.lift_cleared_x, emu.stats.lift_cleared_y) == (pending_x, pending_y)
    clock.t = 0.7
    end = drv.read_motion()
    assert end.lifted and (end.dx, end.dy) == (0, 0)
    clock.t = 1.0
    last = drv.read_motion()
    assert not last.lifted
    assert last.dx == pytest.approx(counts(0.01 * 0.3), abs=1)
    assert last.dy == pytest.approx(counts(-0.02 * 0.3), abs=1)
    s = emu.stats
    assert s.lift_events == 1
    assert first.dx + last.dx + s.lift_cleared_x == s.counted_x
    assert first.dy + last.dy + s.lift_cleared_y == s.counted_y


def test_lift_also_clears_the_latched_deltas():
    """Counts latched by a status read but not yet read are gone with the lift."""
    clock, emu, drv = make(ConstantVelocity(0.01, 0.0), lift_windows=[(0.5, 0.7)])
    clock.t = 0.45
    drv.read_register("status")
    latched = emu.latch_x
    assert latched == math.floor(counts(0.01 * 0.45))
    clock.t = 0.6
    assert drv.read_register("delta_x_disp") == 0
    assert emu.stats.lift_cleared_x == latched
    assert emu.stats.overwritten_x == 0


def test_lift_spanned_by_one_rare_read_is_still_reported():
    clock, emu, drv = make(ConstantVelocity(0.0, 0.01), lift_windows=[(0.2, 0.3)])
    drv.read_motion()
    clock.t = 1.0
    m = drv.read_motion()
    assert m.lifted
    assert m.dy == 0  # this model drops the whole interval that touched the lift
    assert emu.stats.lift_events == 1
    clock.t = 2.0
    m = drv.read_motion()
    assert not m.lifted
    assert m.dy == math.floor(counts(0.01))


def test_several_lift_windows():
    clock, emu, drv = make(
        ConstantVelocity(0.0, 0.05), lift_windows=[(0.3, 0.35), (0.1, 0.15), (0.6, 0.61)]
    )
    reads = poll(clock, drv, 1.0)
    assert emu.stats.lift_events == 3
    lifted_times = [t for t, m in reads if m.lifted and m.dy == 0]
    assert min(lifted_times) > 0.1 and max(lifted_times) <= 0.61
    assert sum(m.dy for _t, m in reads) == emu.stats.counted_y


# --- overflow -----------------------------------------------------------------------------------


def test_overflow_counts_every_wrap_event_and_keeps_the_wrapped_value():
    clock, emu, drv = make(ConstantVelocity(0.3, 0.3))
    drv.set_cpi(6400)
    drv.read_motion()
    for k in range(1, 4):
        clock.t = float(k)
        m = drv.read_motion()
        assert m.overflow
        assert m.status & MAP.status_overflow_x and m.status & MAP.status_overflow_y
    assert emu.stats.overflow_events == 3  # one per counting step that wrapped
    # Without overflow (frequent reads) the bit stays clear.
    for _t, m in poll(clock, drv, 3.1, start=3001):
        assert not m.overflow


@given(intervals=st.lists(st.floats(0.001, 0.3), min_size=1, max_size=20))
@settings(max_examples=60, deadline=None)
def test_counts_read_match_the_counter_modulo_2_16(intervals):
    """With wraps, each read is the true count modulo 2**16 (signed)."""
    clock, emu, drv = make(ConstantVelocity(0.5, -0.4))
    drv.set_cpi(6400)
    for dt in intervals:
        before_x, before_y = emu.stats.counted_x, emu.stats.counted_y
        clock.t += dt
        m = drv.read_motion()
        true_x = emu.stats.counted_x - before_x
        true_y = emu.stats.counted_y - before_y
        assert (m.dx - true_x) % 0x10000 == 0
        assert (m.dy - true_y) % 0x10000 == 0
        wrapped = not (-0x8000 <= true_x <= 0x7FFF and -0x8000 <= true_y <= 0x7FFF)
        assert m.overflow == wrapped


# --- faults ------------------------------------------------------------------------------------


def test_fault_window_raise_then_power_cycle():
    clock, emu, drv = make(ConstantVelocity(0.01, 0.0), fault_windows=[(1.0, 1.5, "raise")])
    drv.set_cpi(3200)
    drv.load_patch([0xBEEF])
    clock.t = 0.9
    drv.read_motion()
    for t in (1.0, 1.2, 1.4999):
        clock.t = t
        with pytest.raises(SpiError, match="emulated fault"):
            drv.read_motion()
    assert emu.stats.faulted_transfers == 3
    assert emu.stats.resets == 0
    clock.t = 1.6
    m = drv.read_motion()
    assert emu.stats.resets == 1
    assert (drv.get_x_cpi(), drv.get_y_cpi()) == (1000, 1000)
    assert not emu.patch_enabled
    assert emu.ram[0] == 0
    # The power-cycled chip counts again at its default resolution, and only the
    # motion after power came back (1.5 s .. 1.6 s).
    assert m.dx == pytest.approx(counts(0.01 * 0.1, 1000), abs=1)


def test_fault_window_no_response_reads_all_ones():
    clock, emu, drv = make(fault_windows=[(1.0, 2.0, "no_response")])
    clock.t = 1.5
    assert emu.xfer2([0x09, 0, 0]) == [0xFF, 0xFF, 0xFF]
    with pytest.raises(SensorNotRespondingError, match="0xffff"):
        drv.read_motion()
    with pytest.raises(SensorNotRespondingError, match="wiring"):
        drv.check_presence()
    clock.t = 2.0  # windows are [start, end)
    drv.check_presence()
    assert emu.stats.resets == 1


def test_fault_window_without_reset():
    clock, emu, drv = make(fault_windows=[(1.0, 2.0, "raise")], reset_after_fault=False)
    drv.set_cpi(3200)
    clock.t = 1.5
    with pytest.raises(SpiError):
        drv.read_motion()
    clock.t = 2.5
    drv.read_motion()
    assert emu.stats.resets == 0
    assert (drv.get_x_cpi(), emu.cpi_y) == (3200, 3200)


def test_corrupt_mode_flips_at_most_one_bit_per_transfer():
    clock, emu, drv = make(fault_windows=[(0.0, 10.0, "corrupt")], seed=3)
    seen = []
    for i in range(200):
        clock.t = i * 0.01
        seen.append(drv.read_register("mode_status"))
    diffs = [bin(v ^ 0x0001).count("1") for v in seen]
    assert all(d <= 1 for d in diffs)
    assert sum(d == 1 for d in diffs) > 100  # two of three bytes are the value
    assert emu.stats.faulted_transfers == 200


def test_fault_on_demand_overrides_and_clears():
    _clock, emu, drv = make()
    emu.fault = "raise"
    with pytest.raises(SpiError):
        drv.read_register("mode_status")
    emu.fault = None
    assert drv.read_register("mode_status") == 0x0001
    assert emu.stats.resets == 0  # on-demand faults do not power-cycle


def test_default_clock_is_monotonic_time():
    emu = EmulatedPLN2033(ConstantVelocity(0.0, 0.0))
    drv = PLN2033(emu)
    drv.check_presence()
    assert drv.read_motion().dy == 0
