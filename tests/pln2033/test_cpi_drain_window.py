"""A CPI change drains the counters in the CPI write's own transfer (issue 28 item 2).

The emulators advance the motion once per transfer; the clock here moves on at every
transfer (:class:`TickingClock`: the host's time between two calls, long on a loaded
machine). A drain read followed by separate CPI writes leaves a window: the counts made
in between are read after the write and scaled at the new CPI. ``set_cpi(cpi, on_drain)``
drains and writes in one transfer (the PLN2033) or one chip-select frame (the PMW33xx),
so every count is scaled at the CPI it was counted at.
"""

from __future__ import annotations

import pytest
from fakes import FakeClock

from pln2033 import INCH_M
from pln2033.chips import make_driver, make_emulator
from pln2033.motion import ConstantVelocity
from pln2033.sensor import Motion

CHIPS = ("pln2033", "pmw3360", "pmw3389")
V = (0.2, 0.5)  # m/s, sensor frame
DELTAS = ("Delta_X_L", "Delta_X_H", "Delta_Y_L", "Delta_Y_H", "SQUAL")
TRANSFER_S = 0.5e-3  # host time per transfer (a loaded machine between two Python calls)


class TickingClock(FakeClock):
    """A FakeClock that moves on by ``tick`` seconds at every reading (every transfer)."""

    tick = 0.0

    def __call__(self) -> float:
        t = self.t
        self.t += self.tick
        return t


def make(chip: str):
    clock = TickingClock()
    emu = make_emulator(chip, motion=ConstantVelocity(*V), clock=clock)
    options = {} if chip == "pln2033" else {"sleep": clock.sleep}
    drv = make_driver(chip, emu, name="/dev/spidev1.0", **options)
    drv.initialise(1600)
    return clock, emu, drv


def metres(m: Motion, cpi: int) -> tuple[float, float]:
    return m.dx * INCH_M / cpi, m.dy * INCH_M / cpi


def change_cpi(chip: str, one_transfer: bool) -> tuple[float, float, float, int]:
    """Drive at V, change 1600 -> 800 with the clock ticking, read on: (error x, error y
    (m, each read at the CPI it was counted at, against the true displacement), seconds,
    transfers of the change)."""
    clock, emu, drv = make(chip)
    clock.t += 0.010
    drv.read_motion()  # clean counters; the truth starts at the emulator's time of it
    t0 = emu._t
    x = y = 0.0
    clock.t += 0.004  # counts waiting at 1600
    clock.tick = TRANSFER_S
    before = emu.stats.transfers
    if one_transfer:
        drained: list[Motion] = []
        drv.set_cpi(800, on_drain=drained.append)
        assert len(drained) == 1
        m = drained[0]
    else:  # the poller before: a drain read, then the writes (and their read-backs)
        m = drv.read_motion()
        drv.set_cpi(800)
    transfers = emu.stats.transfers - before
    x, y = metres(m, 1600)
    clock.tick = 0.0
    assert drv.get_cpi() == (800, 800)
    for _ in range(5):
        clock.t += 0.001
        dx, dy = metres(drv.read_motion(), 800)
        x, y = x + dx, y + dy
    dt = emu._t - t0
    return x - V[0] * dt, y - V[1] * dt, dt, transfers


@pytest.mark.parametrize("chip", CHIPS)
def test_counts_made_at_the_old_cpi_are_scaled_at_it(chip):
    ex, ey, dt, _ = change_cpi(chip, one_transfer=True)
    # within a count at 1600 (the start's fraction) and one at 800 (the end's)
    bound = INCH_M / 1600 + INCH_M / 800
    assert abs(ex) < bound and abs(ey) < bound, (ex, ey)
    assert dt > 0.009 + TRANSFER_S  # the change took host time: a window would show


@pytest.mark.parametrize("chip", CHIPS)
def test_a_drain_read_before_separate_writes_scales_the_window_at_the_new_cpi(chip):
    """What the test above guards against: the old sequence's counts between the drain
    read and the write count twice their distance (read at 800, made at 1600)."""
    ex, ey, _dt, _ = change_cpi(chip, one_transfer=False)
    # at least one transfer (the X write) between the drain and the write: 0.5 ms of
    # motion, scaled twice; the one-transfer change above stays within 0.05 mm
    assert ey > 0.5 * V[1] * TRANSFER_S > 2 * (INCH_M / 1600 + INCH_M / 800), (ex, ey)


def test_pln2033_drain_and_both_writes_are_one_transfer():
    _clock, emu, drv = make("pln2033")
    emu.record = True
    drv.set_cpi(3200, on_drain=lambda m: None)
    frames = [tx for tx, _rx in emu.stats.history]
    a, m = drv.map.addresses, drv.map
    code = m.encode_cpi(3200)
    low = (a["command_low"] | m.write_flag, code >> 8, code & 0xFF)
    high = a["command_high"] | m.write_flag
    x_op, y_op = m.commands["set_x_cpi"], m.commands["set_y_cpi"]
    assert frames[0] == (
        *drv.motion_tx, *low, high, x_op >> 8, x_op & 0xFF, *low, high, y_op >> 8, y_op & 0xFF
    )  # fmt: skip
    assert len(frames) == 1 + 3 + 3  # then the read-back of X and of Y
    assert (emu.cpi_x, emu.cpi_y) == (3200, 3200)


@pytest.mark.parametrize("chip", ("pmw3360", "pmw3389"))
def test_pmw33xx_drain_frame_keeps_the_timing(chip):
    clock, emu, drv = make(chip)
    before = emu.stats.protocol_errors
    emu.record = True
    drv.set_cpi(400, on_drain=lambda m: None)
    assert emu.stats.protocol_errors == before == 0
    # Motion (the freeze), the resolution writes right after it, then the frozen deltas
    frame = emu.stats.history[0][0]
    a, enc = drv.regs.addresses, drv.regs.cpi
    writes = [a[n] | 0x80 for n in enc.registers]
    sent = [seg[0] for seg in frame if len(seg) == 2 or seg != (0,)]
    assert sent == [a["Motion"], *writes, *(a[n] for n in DELTAS)], sent
    emu.record = False
    assert drv.get_cpi() == (400, 400)
    clock.t += 0.002
    m = drv.read_motion()  # the burst is armed again after the frame's plain reads
    assert m.dy == pytest.approx(V[1] * 0.002 * 400 / INCH_M, abs=1.5)


@pytest.mark.parametrize("chip", ("pmw3901", "paa5100", "otos"))
def test_a_fixed_cpi_chip_drains_nothing(chip):
    """No write, so no count changes scale: ``on_drain`` is never called."""
    from pln2033.chips import chip_info

    info = chip_info(chip)
    clock = FakeClock()
    emu = make_emulator(chip, motion=ConstantVelocity(*V), clock=clock)
    drv = make_driver(chip, emu, name="/dev/spidev1.0")
    drained: list[Motion] = []
    drv.set_cpi(info.cpi.min, on_drain=drained.append)
    assert drained == []
