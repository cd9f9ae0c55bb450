"""A chip that resets itself during a glitch of one or two failed polls (issue 27 item 8's
follow-up, h27ring task 3): shorter than the ERRORS_BEFORE_DOWN polls that declare a sensor
down, it was only found by the CPI read-back every HEALTH_CHECK_S, so up to 1 s of counts at
the chip's default CPI were scaled by the configured one (PLN2033: ~37 % short). Now the CPI is
read back before the first poll after a failed one: the chip is re-initialised at once (the
counts it made at its default CPI dropped), the reset reported as a down/up pair.

A real :class:`Poller` on a plain bytearray, the PLN2033 emulator on a fake clock (as
tests/beagle/test_power_cycle.py), moving at a constant speed; the emulator's fault window
makes the transfers of one or two polls fail and power-cycles the chip at its end.
"""

from __future__ import annotations

from multiprocessing import Pipe

import numpy as np
import pytest
from fakes import FakeClock

from mm_beagle.poller import shared_state as ss
from mm_beagle.poller.poller import ERRORS_BEFORE_DOWN, Poller, PollerConfig
from mm_beagle.poller.sim_backend import SimConfig
from pln2033 import INCH_M
from pln2033 import chips as registry
from pln2033.motion import ConstantVelocity

T0 = 100.0
PERIOD = 1e-3
VX, VY = 0.1, 0.3  # m/s, sensor frame
CPI = 1600
STEP_Y = VY * PERIOD * CPI / INCH_M  # counts per poll at the configured CPI (18.9)


class Rig:
    """A Poller over the PLN2033 emulator on a fake clock; each poll one PERIOD later."""

    def __init__(self, **emu_kw) -> None:
        self.clock = FakeClock(T0)
        ring = 4096
        self.state = ss.SharedState(bytearray(ss.SharedState.size(1, ring)), 1, ring)
        _cmd, cmd_child = Pipe()
        self.ev, ev_child = Pipe()
        cfg = PollerConfig(
            devices=["/dev/spidev1.0"], backend="sim", cpi=CPI, chips=["pln2033"],
            ring_size=ring, retry_interval=1.0, sim=SimConfig(trajectory="straight"),
        )  # fmt: skip
        self.poller = Poller(cfg, self.state, cmd_child, ev_child)
        self.poller.driver_extra = {"sleep": self.clock.sleep}
        self.ch = self.poller.channels[0]
        self.emu = registry.make_emulator("pln2033", clock=self.clock, **emu_kw)
        self.ch.bus = self.emu
        self.poller.try_init(self.ch, self.clock.t)

    def run(self, seconds: float) -> None:
        end = self.clock.t + seconds
        while self.clock.t < end:
            self.clock.t += PERIOD
            self.poller.poll(self.ch, round(self.clock.t * 1e9), self.clock.t)

    def events(self) -> list[tuple]:
        out = []
        while self.ev.poll():
            out.append(self.ev.recv())
        return out


@pytest.mark.parametrize("failed", [1, 2])
def test_a_reset_within_a_short_glitch_is_found_before_its_counts_are_taken(failed):
    assert failed < ERRORS_BEFORE_DOWN  # the case the down/up path never saw
    start = T0 + 0.3 + 0.25 * PERIOD  # between two polls
    rig = Rig(
        motion=ConstantVelocity(VX, VY),
        fault_windows=[(start, start + failed * PERIOD, "raise")],
        reset_after_fault=True,
    )
    assert rig.emu.map.cpi_default != CPI  # a reset changes the chip's CPI
    resets = rig.emu.stats.resets  # (the bring-up's own reset counts too)
    rig.run(0.6)  # well inside one HEALTH_CHECK_S: only the new read-back can find it
    ev = rig.events()
    t = rig.state.snapshot(0)

    # the glitch: `failed` failed polls, and the chip really reset at its end
    assert t.spi_errors == failed and rig.emu.stats.resets > resets
    # reported: down because it reset itself, up again re-initialised, at the set CPI
    downs = [e for e in ev if e[0] == "down"]
    assert len(downs) == 1 and "reset itself" in downs[0][2], ev
    assert [e[0] for e in ev if e[0] in ("up", "down")] == ["up", "down", "up"], ev
    assert t.state == ss.STATE_UP and t.reinits == 2
    assert rig.ch.driver.get_cpi() == (CPI, CPI) == (t.cpi_x, t.cpi_y)

    # no count scaled by the wrong CPI: every good poll carries one period of motion at the
    # configured CPI (counts at the chip's default CPI would be ~37 % short), and its CPI
    _f, _n, _d, arr = rig.state.samples(0, 0, 0)
    good = (arr["flags"] & (ss.FLAG_SPI_ERROR | ss.FLAG_COMMAND_READ)) == 0
    assert int((~good).sum()) == failed
    assert np.all(arr["cpi"][good] == CPI)
    dy = arr["dy"][good].astype(float)
    assert np.all(np.abs(dy - STEP_Y) <= 1.5), dy[np.abs(dy - STEP_Y) > 1.5]
    # and the metres agree with the counts at that CPI
    assert t.y_total_m == pytest.approx(t.y_total * INCH_M / CPI, rel=1e-9)
