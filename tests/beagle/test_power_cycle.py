"""A sensor power-cycled for 2.5 s while moving (issue 27 item 5): found, re-initialised,
reported with the counts lost estimated, totals exact outside the outage.

A real :class:`Poller` on a plain bytearray, each chip's emulator on a fake clock (as
tests/beagle/test_poller_chips.py), moving at a constant speed; the emulator's fault window
makes every transfer fail for 2.5 s and power-cycles the chip at its end (registers at
their defaults, counters cleared). The report is what /diagnostics says:
:func:`mm_beagle.node.health.outage_estimate` over the ring and
:func:`~mm_beagle.node.health.sensor_status` with its :func:`~mm_beagle.node.health.reset_report`.
"""

from __future__ import annotations

from multiprocessing import Pipe

import numpy as np
import pytest
from fakes import FakeClock

from mm_beagle.node import health
from mm_beagle.poller import chip_config
from mm_beagle.poller import shared_state as ss
from mm_beagle.poller.poller import Poller, PollerConfig
from mm_beagle.poller.sim_backend import SimConfig
from pln2033 import INCH_M
from pln2033 import chips as registry
from pln2033.motion import ConstantVelocity

T0 = 100.0
PERIOD = 1e-3
VX, VY = 0.1, 0.3  # m/s, sensor frame
FAULT_AT, FAULT_S = 1.0, 2.5  # s after the bring-up
#: |estimate - true loss| allowed: 0.3 % of the loss + 10 counts (measured: PLN2033 8 of
#: 56 750, PMW3360 0 of 57 694, OTOS 87 of 42 850 y counts: the OTOS's steps of 12-36 counts)
REL_TOL = 0.003
#: the OTOS's counts follow its position registers, which are its newest 2.4 ms update's
#: (truncated: tests/beagle/test_power_cycle_otos.py): against the true motion at the poll
#: times each segment's ends may lag one update (0.32 m/s x 2.4 ms = 30 counts) + 1 LSB (12)
OTOS_BOUND = 2 * 30 + 12 + 3


class Rig:
    """A Poller over one emulator per device on a fake clock; each poll one PERIOD later
    than the clock (a bring-up's waits move the clock on)."""

    def __init__(self, chip: str, **emu_kw) -> None:
        self.clock = FakeClock(T0)
        ring = 16384
        self.state = ss.SharedState(bytearray(ss.SharedState.size(1, ring)), 1, ring)
        _cmd, cmd_child = Pipe()
        self.ev, ev_child = Pipe()
        cfg = PollerConfig(
            devices=["/dev/spidev1.0"], backend="sim", cpi=1600, chips=[chip],
            ring_size=ring, retry_interval=1.0, sim=SimConfig(trajectory="straight"),
        )  # fmt: skip
        self.poller = Poller(cfg, self.state, cmd_child, ev_child)
        self.poller.driver_extra = {"sleep": self.sleep}
        self.ch = self.poller.channels[0]
        self.emu = registry.make_emulator(chip, clock=self.clock, **emu_kw)
        self.ch.bus = self.emu
        self.poller.try_init(self.ch, self.clock.t)
        self.t_init = self.clock.t

    def sleep(self, s: float) -> None:
        self.clock.t += s

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


def counts(metres: float, cpi: int) -> float:
    return metres * cpi / INCH_M


@pytest.mark.parametrize("chip", ["pln2033", "pmw3360", "otos"])
def test_power_cycle_is_reported_with_the_counts_lost_estimated(chip):
    if not chip_config.available(chip):
        pytest.skip(f"the {chip} driver is not in this tree")
    start = T0 + 0.4 + FAULT_AT  # after any bring-up wait (the OTOS's IMU calibration)
    rig = Rig(chip, motion=ConstantVelocity(VX, VY),
              fault_windows=[(start, start + FAULT_S, "raise")])  # fmt: skip
    assert rig.t_init < start - 0.5
    rig.run(start - rig.clock.t + FAULT_S + 2.0)  # the outage, a retry, a second of polls
    ev = rig.events()
    kinds = [e[0] for e in ev if e[0] in ("up", "down")]
    assert kinds[0] == kinds[-1] == "up" and kinds[1] == "down", ev  # (a retry may fail)
    assert "polls failed" in next(e for e in ev if e[0] == "down")[2]
    t = rig.state.snapshot(0)
    assert t.state == ss.STATE_UP and t.reinits == 2 and rig.emu.stats.resets >= 1
    cpi = t.cpi_y
    assert cpi == (1000 if chip == "otos" else 1600)  # re-initialised at the configured CPI

    _f, _n, _d, arr = rig.state.samples(0, 0, 0)
    out = health.outage_estimate(arr["stamp_ns"], arr["dx"], arr["dy"], arr["flags"])
    assert out is not None and out.n_after == health.OUTAGE_WINDOW
    # the outage: power lost at `start`, back at its end, the next retry re-initialises
    # (a retry every 1 s; the OTOS's bring-up calibrates its IMU, ~0.5 s)
    assert FAULT_S < out.seconds < FAULT_S + 1.7
    good = (arr["flags"] & (ss.FLAG_SPI_ERROR | ss.FLAG_COMMAND_READ)) == 0
    stamps = arr["stamp_ns"][good] / 1e9
    k = int(np.argmax(np.diff(stamps)))
    t_a, t_b = stamps[k], stamps[k + 1]  # last good poll before, first good poll after
    assert out.seconds == pytest.approx(t_b - t_a)
    # what the chip would have counted from t_a to the period that the first poll after
    # covers: the true loss (the chip counted nothing while off; what it counted after
    # power-on went with the bring-up's read)
    true_x = counts(VX * (t_b - PERIOD - t_a), cpi)
    true_y = counts(VY * (t_b - PERIOD - t_a), cpi)
    for est, true, sigma in ((out.x, true_x, out.sigma_x), (out.y, true_y, out.sigma_y)):
        assert abs(est - true) <= REL_TOL * abs(true) + 10, (chip, est, true, sigma)
    assert true_y > 4000  # a real loss: 2.5 s at 0.3 m/s

    # totals exact outside the outage: the motion before t_a and after t_b - PERIOD
    inside = (VX * (t_a - rig.t_init) + VX * (rig.clock.t - t_b + PERIOD),
              VY * (t_a - rig.t_init) + VY * (rig.clock.t - t_b + PERIOD))  # fmt: skip
    bound = OTOS_BOUND if chip == "otos" else 2
    assert abs(t.x_total - counts(inside[0], cpi)) <= bound, (t.x_total, counts(inside[0], cpi))
    assert abs(t.y_total - counts(inside[1], cpi)) <= bound, (t.y_total, counts(inside[1], cpi))

    # /diagnostics: ERROR naming the reset and the estimate, in counts and metres
    text, values = health.reset_report(out, cpi, 1)
    r = health.PollerRound(1000.0, 1100.0, 0, 0, 5.0, 0, {})
    level, message, shown = health.sensor_status(
        r, chip, t, 1000.0, "", ("OK", "up", {}), "", (t.spi_errors, t.overflows), (text, values)
    )
    assert level == "ERROR" and message == text
    assert message.startswith(f"sensor reset: re-initialised after {out.seconds:.2f} s without")
    assert f"about {max(abs(out.x), abs(out.y)):.0f} counts" in message
    assert shown["est_reset_loss_y_counts"] == f"{out.y:.0f}"
    assert float(shown["reset_outage_s"]) == pytest.approx(out.seconds, abs=1e-3)
    metres = float(np.hypot(out.x, out.y)) * INCH_M / cpi
    assert float(shown["est_reset_loss_m"]) == pytest.approx(metres, abs=1e-3)
    # without a reset the same round is OK
    assert health.sensor_status(
        r, chip, t, 1000.0, "", ("OK", "up", {}), "", (t.spi_errors, t.overflows)
    )[0] == "OK"


def test_outage_estimate_needs_two_good_polls_and_skips_failed_ones():
    stamps = np.arange(10, dtype=np.int64) * 1_000_000
    flags = np.full(10, ss.FLAG_SPI_ERROR, dtype=np.uint8)
    dx = np.zeros(10)
    assert health.outage_estimate(stamps, dx, dx, flags) is None
    flags[[0, 1, 8, 9]] = 0
    dy = np.zeros(10)
    dy[[0, 1, 8, 9]] = 10
    out = health.outage_estimate(stamps, dx, dy, flags)
    # two good polls each side, 7 ms apart: 6 poll slots at the 10 counts per poll around them
    assert out is not None and out.seconds == pytest.approx(0.007) and out.polls == 6
    assert out.y == pytest.approx(60.0) and out.x == 0.0 and out.n_after == 2


def test_outage_estimate_goes_by_time_when_the_loop_skipped_slots():
    # 10 counts per ms throughout; before the gap every other slot was skipped (late
    # loop), so each of those polls carries 20 counts: per poll the speed would double
    before = np.arange(0, 400, 2) * 1_000_000  # 200 polls 2 ms apart
    after = (1400 + np.arange(200)) * 1_000_000  # 1 s outage, then 1 ms polls
    stamps = np.concatenate([before, after]).astype(np.int64)
    dy = np.concatenate([np.full(200, 20.0), np.full(200, 10.0)])
    flags = np.zeros(400, dtype=np.uint8)
    out = health.outage_estimate(stamps, np.zeros(400), dy, flags)
    assert out is not None and out.seconds == pytest.approx(1.002)
    # the true loss: 10 counts per ms over the gap less the first poll's own ms
    assert out.y == pytest.approx(10 * 1001, rel=0.002)
