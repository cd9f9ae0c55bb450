"""The poller's CPI change with host time passing between transfers (issue 28 item 2).

Before, ``set_cpi`` read the counters (the drain), then wrote the CPI in further transfers:
the counts the chip made in between (60-100 us in Python, milliseconds on a loaded
machine) were read by the next poll and scaled at the new CPI. Now the driver drains in
the CPI write's own transfer (frame), and the drain is recorded as a command read
(``FLAG_COMMAND_READ``, as ``Channel.record`` says) at the old CPI.

A real :class:`Poller` on a plain bytearray, each chip's emulator on a clock that moves on
by TRANSFER_S at every transfer while the command runs (as a loaded host would).
"""

from __future__ import annotations

from multiprocessing import Pipe

import numpy as np
import pytest
from fakes import FakeClock

from mm_beagle.poller import shared_state as ss
from mm_beagle.poller.poller import Poller, PollerConfig
from mm_beagle.poller.sim_backend import SimConfig
from pln2033 import INCH_M
from pln2033 import chips as registry
from pln2033.motion import ConstantVelocity

T0 = 100.0
PERIOD = 1e-3
VX, VY = 0.2, 0.5  # m/s, sensor frame
TRANSFER_S = 0.5e-3


class TickingClock(FakeClock):
    """A FakeClock that moves on by ``tick`` seconds at every reading (every transfer)."""

    tick = 0.0

    def __call__(self) -> float:
        t = self.t
        self.t += self.tick
        return t


class Rig:
    """A Poller over one emulated chip; each poll one PERIOD later."""

    def __init__(self, chip: str) -> None:
        self.clock = TickingClock(T0)
        ring = 4096
        self.state = ss.SharedState(bytearray(ss.SharedState.size(1, ring)), 1, ring)
        _cmd, cmd_child = Pipe()
        _ev, ev_child = Pipe()
        cfg = PollerConfig(
            devices=["/dev/spidev1.0"], backend="sim", cpi=1600, chips=[chip],
            ring_size=ring, retry_interval=1.0, sim=SimConfig(trajectory="straight"),
        )  # fmt: skip
        self.poller = Poller(cfg, self.state, cmd_child, ev_child)
        self.poller.driver_extra = {"sleep": self.clock.sleep}
        self.ch = self.poller.channels[0]
        self.emu = registry.make_emulator(chip, motion=ConstantVelocity(VX, VY), clock=self.clock)
        self.ch.bus = self.emu
        self.poller.try_init(self.ch, self.clock.t)

    def run(self, polls: int) -> None:
        for _ in range(polls):
            self.clock.t += PERIOD
            self.poller.poll(self.ch, round(self.clock.t * 1e9), self.clock.t)


@pytest.mark.parametrize("chip", ["pln2033", "pmw3360"])
def test_counts_before_the_cpi_write_keep_the_old_scale(chip):
    rig = Rig(chip)
    rig.run(3)  # the first poll after bring-up: clean counters from here
    t_first = rig.emu._t
    before = rig.state.snapshot(0)
    rig.run(20)
    rig.clock.t += PERIOD / 2  # counts waiting in the chip at 1600
    rig.clock.tick = TRANSFER_S
    assert rig.poller.serve_command(("set_cpi", 0, 800)) == ("ok", 800)
    rig.clock.tick = 0.0
    rig.run(20)
    t = rig.state.snapshot(0)
    dt = rig.emu._t - t_first
    assert (t.cpi_x, t.cpi_y) == (800, 800)
    # within a count at 1600 (the start's fraction) and one at 800 (the end's); the old
    # sequence was off by the window's motion (>= 0.25 mm here), read at twice its scale
    bound = INCH_M / 1600 + INCH_M / 800
    assert t.x_total_m - before.x_total_m == pytest.approx(VX * dt, abs=bound)
    assert t.y_total_m - before.y_total_m == pytest.approx(VY * dt, abs=bound)
    # the ring: the drain is a command read at the old CPI, then the polls at the new
    _first, _next, _dropped, a = rig.state.samples(0, before.seq, 0)
    cmd = (a["flags"] & ss.FLAG_COMMAND_READ) != 0
    assert np.flatnonzero(cmd).tolist() == [20]
    assert a["cpi"].tolist() == [1600] * 21 + [800] * 20
    assert a["dy"][20] > 0  # the half poll of counts waiting went with the drain
    ring_m = float((a["dy"].astype(float) * INCH_M / a["cpi"]).sum())
    assert ring_m == pytest.approx(t.y_total_m - before.y_total_m, rel=1e-12)
