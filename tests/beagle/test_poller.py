"""The 1 kHz poller, driven by hand: no process, no ROS, a fake clock.

Each test builds a real :class:`Poller` (sim backend) on a plain bytearray
and two pipes, swaps every channel's bus for an :class:`EmulatedPLN2033` on a
fake clock before the first ``try_init``, then advances the clock and calls
``poll`` itself. Ground truth: the emulator's ``stats`` and the motion
source's true metres.
"""

from __future__ import annotations

import math
import threading
from multiprocessing import Pipe

import numpy as np
import pytest
from fakes import FakeClock, scaled, wait_until

from mm_beagle.poller import poller as poller_mod
from mm_beagle.poller import shared_state as ss
from mm_beagle.poller.poller import ERRORS_BEFORE_DOWN, Poller, PollerConfig
from mm_beagle.poller.sim_backend import SimConfig, parse_fail_windows
from mm_beagle.poller.sim_channel import SimChannel, truth_of
from pln2033 import INCH_M, SpiError
from pln2033.motion import ConstantVelocity, SampledPath
from pln2033.pln2033 import PLN2033, EmulatedPLN2033, RegisterMap

MAP = RegisterMap.default()
DEVICES = ["/dev/spidev1.0", "/dev/spidev1.1"]
T0 = 100.0  # the fake clock's start; windows below are relative to it
PERIOD = 1e-3
# 10.0001 counts per ms at 1000 CPI (64.0006 at 6400): whole counts per poll, no
# matter how the float clock rounds, for a few dozen polls
TEN_PER_MS = 0.254 * 1.00001


class Rig:
    """A Poller with emulated sensors on a fake clock, polled by hand."""

    def __init__(
        self,
        sensors: list[dict],
        cpi: int = 1600,
        ring: int = 65536,
        retry: float = 0.5,
        bus_class: type = EmulatedPLN2033,
    ) -> None:
        n = len(sensors)
        self.clock = FakeClock(T0)
        self.state = ss.SharedState(bytearray(ss.SharedState.size(n, ring)), n, ring)
        self.cmd, cmd_child = Pipe()
        self.ev, ev_child = Pipe()
        self.cfg = PollerConfig(
            devices=DEVICES[:n],
            backend="sim",
            cpi=cpi,
            ring_size=ring,
            retry_interval=retry,
            sim=SimConfig(trajectory="straight"),
        )
        self.poller = Poller(self.cfg, self.state, cmd_child, ev_child)
        self.emus: list[EmulatedPLN2033] = []
        for ch, kw in zip(self.poller.channels, sensors, strict=True):
            emu = bus_class(clock=self.clock, regmap=MAP, **kw)
            ch.bus = emu
            self.emus.append(emu)
            self.poller.try_init(ch, self.clock.t)
        self.t_init = self.clock.t
        self.k = 0

    @property
    def channels(self):
        return self.poller.channels

    def step(self, channels=None) -> None:
        self.k += 1
        t = T0 + self.k * PERIOD
        self.clock.t = t
        for ch in channels if channels is not None else self.channels:
            self.poller.poll(ch, round(t * 1e9), t)

    def run(self, polls: int, channels=None) -> None:
        for _ in range(polls):
            self.step(channels)

    def events(self) -> list[tuple]:
        out = []
        while self.ev.poll():
            out.append(self.ev.recv())
        return out

    def snap(self, i: int) -> ss.Totals:
        return self.state.snapshot(i)

    def ring(self, i: int) -> dict[str, np.ndarray]:
        t = self.snap(i)
        first, nxt, dropped, a = self.state.samples(i, 0, 0)
        assert (first, nxt, dropped) == (0, t.seq, 0), "ring wrapped: make it bigger"
        return a


def measured(emu: EmulatedPLN2033, base: tuple[int, int, int, int] = (0, 0, 0, 0)):
    """Counts the poller should have: counted minus what lifts cleared."""
    s = emu.stats
    return (
        (s.counted_x - base[0]) - (s.lift_cleared_x - base[2]),
        (s.counted_y - base[1]) - (s.lift_cleared_y - base[3]),
    )


def lissajous(ax, bx, vy, ay, by, phase=0.0, seconds=30.0, dt=0.01):
    """A figure-eight-like sensor path: x swings both ways, y always forward."""
    t = np.arange(0.0, seconds + dt, dt)
    x = ax * np.sin(2 * math.pi * t / bx + phase)
    y = vy * t + ay * np.sin(2 * math.pi * t / by)
    assert np.all(np.diff(y) > 0)
    return SampledPath(x, y, dt, t_start=T0)


# --- parse_fail_windows -----------------------------------------------------------------------


def test_parse_fail_windows_good_specs():
    got = parse_fail_windows(
        ["/dev/spidev1.1@0-2.5", "/dev/spidev1.1@3-4", "/dev/spidev1.0@0.25-0.5"], DEVICES
    )
    assert got == {"/dev/spidev1.0": [(0.25, 0.5)], "/dev/spidev1.1": [(0.0, 2.5), (3.0, 4.0)]}
    assert parse_fail_windows([], DEVICES) == {d: [] for d in DEVICES}
    # a device name may itself hold an "@": the last one separates
    assert parse_fail_windows(["a@b@1-2"], ["a@b"]) == {"a@b": [(1.0, 2.0)]}


@pytest.mark.parametrize(
    "spec",
    [
        "/dev/spidev1.0",
        "/dev/spidev1.0:0-2",
        "/dev/spidev1.0@",
        "/dev/spidev1.0@2",
        "/dev/spidev1.0@a-b",
        "/dev/spidev1.0@1-2-3",
        "/dev/spidev1.0@-1-2",
        "/dev/spidev1.0@1-",
    ],
)
def test_parse_fail_windows_bad_format(spec):
    with pytest.raises(ValueError) as info:
        parse_fail_windows([spec], DEVICES)
    assert str(info.value) == f"fail window '{spec}' is not DEVICE@START-END (seconds)"


def test_parse_fail_windows_unknown_device():
    with pytest.raises(ValueError) as info:
        parse_fail_windows(["/dev/spidev2.0@0-1"], DEVICES)
    msg = str(info.value)
    assert "'/dev/spidev2.0@0-1'" in msg and "unknown device" in msg
    assert "/dev/spidev1.0" in msg and "/dev/spidev1.1" in msg


@pytest.mark.parametrize("span", ["2-1", "2-2", "0-0", "nan-1", "1-nan"])
def test_parse_fail_windows_start_not_before_end(span):
    spec = f"/dev/spidev1.0@{span}"
    with pytest.raises(ValueError, match=r"needs 0 <= START < END") as info:
        parse_fail_windows([spec], DEVICES)
    assert spec in str(info.value)


def test_sim_fail_windows_are_checked_when_the_poller_is_built():
    state = ss.SharedState(bytearray(ss.SharedState.size(1, 8)), 1, 8)
    cfg = PollerConfig(
        devices=DEVICES[:1], backend="sim", ring_size=8, sim=SimConfig(fail_windows=["x@0-1"])
    )
    a, b = Pipe()
    with pytest.raises(ValueError, match="unknown device"):
        Poller(cfg, state, a, b)


# --- bring-up ---------------------------------------------------------------------------------


def test_bring_up_state_cpi_and_events():
    rig = Rig([{"motion": ConstantVelocity(0.1, 0.2)}] * 2, cpi=2400)
    for i, emu in enumerate(rig.emus):
        t = rig.snap(i)
        assert (t.state, t.reinits, t.cpi_x, t.cpi_y, t.seq) == (ss.STATE_UP, 1, 2400, 2400, 0)
        assert (emu.cpi_x, emu.cpi_y) == (2400, 2400)
    assert rig.events() == [
        ("up", DEVICES[0], "Philips PLN2033 initialised at 2400 CPI"),
        ("up", DEVICES[1], "Philips PLN2033 initialised at 2400 CPI"),
    ]


def test_one_poll_per_call_with_ring_fields():
    rig = Rig([{"motion": ConstantVelocity(0.0, TEN_PER_MS)}], cpi=1000)
    rig.run(5)
    t = rig.snap(0)
    assert t.seq == 5
    assert t.y_total == 50 and t.x_total == 0
    assert t.y_total_m == pytest.approx(50 * INCH_M / 1000, abs=1e-12)
    assert t.stamp_ns == round((T0 + 5 * PERIOD) * 1e9)
    a = rig.ring(0)
    assert a["dy"].tolist() == [10] * 5
    assert a["cpi"].tolist() == [1000] * 5
    assert a["flags"].tolist() == [ss.FLAG_MOTION] * 5
    assert a["stamp_ns"].tolist() == [round((T0 + k * PERIOD) * 1e9) for k in range(1, 6)]


# --- conservation -----------------------------------------------------------------------------


def test_conservation_over_20000_polls_with_lifts_settings_reads_and_a_cpi_change():
    paths = [
        lissajous(0.05, 4.0, 0.2, 0.02, 2.0),
        lissajous(0.04, 5.0, 0.15, 0.03, 3.0, phase=1.0),
    ]
    lifts0 = [(T0 + a, T0 + a + d) for a, d in [(2, 0.012), (5.5, 0.02), (12.3, 0.01), (17, 0.03)]]
    rig = Rig(
        [{"motion": paths[0], "lift_windows": lifts0}, {"motion": paths[1]}],
        cpi=1600,
    )
    new_cpi = [3200, 800]
    base = [truth_of(ch).base for ch in rig.channels]
    at_change = None
    settings_reads = [0, 0]
    for k in range(1, 20_001):
        rig.step()
        if k % 1237 == 0 or k == 5510:  # 5510: in the middle of the second lift of sensor 0
            for i in (0, 1) if k % 1237 == 0 else (0,):
                # a settings read between two polls, with counts waiting in the sensor
                rig.clock.t += PERIOD / 2
                status, reply = rig.poller.serve_command(("settings", i))
                assert status == "ok"
                assert set(reply["registers"]) >= {"status", "delta_x_disp", "delta_y_disp"}
                assert (reply["cpi_x"], reply["cpi_y"]) == (rig.channels[i].cpi_x,) * 2
                if k == 5510 and i == 0:
                    assert reply["lifted"] is True
                settings_reads[i] += 1
        if k == 10_000:
            # half a poll of counts waits in each sensor; count it (at the old CPI) so the
            # split of the ground truth is exact, then change the CPI with it still unread
            rig.clock.t += PERIOD / 2
            for e in rig.emus:
                e.advance()
            at_change = [measured(e, b) for e, b in zip(rig.emus, base, strict=True)]
            for i, cpi in enumerate(new_cpi):
                assert rig.poller.serve_command(("set_cpi", i, cpi)) == ("ok", cpi)
            assert [measured(e, b) for e, b in zip(rig.emus, base, strict=True)] == at_change
    t_end = rig.clock.t
    assert at_change is not None

    for i, (emu, path) in enumerate(zip(rig.emus, paths, strict=True)):
        t = rig.snap(i)
        s = emu.stats
        assert t.seq == 20_000 + settings_reads[i] + 1  # + the drain read of the CPI change
        assert (s.overwritten_x, s.overwritten_y) == (0, 0)
        assert (t.x_total, t.y_total) == measured(emu, base[i])
        assert (t.gen_x, t.gen_y) == (s.counted_x - base[i][0], s.counted_y - base[i][1])
        assert (t.cpi_x, t.cpi_y) == (new_cpi[i], new_cpi[i]) == (emu.cpi_x, emu.cpi_y)
        # metres: every count at the CPI it was counted at
        old_x, old_y = at_change[i]
        want_x = old_x * INCH_M / 1600 + (t.x_total - old_x) * INCH_M / new_cpi[i]
        want_y = old_y * INCH_M / 1600 + (t.y_total - old_y) * INCH_M / new_cpi[i]
        assert t.x_total_m == pytest.approx(want_x, rel=1e-9, abs=1e-12)
        assert t.y_total_m == pytest.approx(want_y, rel=1e-9, abs=1e-12)
        # the ring holds the same story, poll by poll
        a = rig.ring(i)
        assert int(a["dx"].astype(np.int64).sum()) == t.x_total
        assert int(a["dy"].astype(np.int64).sum()) == t.y_total
        ring_m = (a["dy"].astype(np.float64) * INCH_M / a["cpi"]).sum()
        assert ring_m == pytest.approx(t.y_total_m, rel=1e-9)
        # the settings reads and the drain read of the CPI change: command reads
        assert int(np.count_nonzero(a["flags"] & ss.FLAG_COMMAND_READ)) == settings_reads[i] + 1
        assert int(np.count_nonzero(a["flags"] & ss.FLAG_LIFT)) == t.lift_total
        assert not np.any(a["flags"] & (ss.FLAG_OVERFLOW | ss.FLAG_SPI_ERROR))
        assert t.overflows == t.spi_errors == 0
        # the true path
        x0, y0 = path.position(rig.t_init)
        x1, y1 = path.position(t_end)
        one_count = INCH_M / new_cpi[i]
        if i == 1:  # no lifts: within one count of the truth, across the CPI change
            assert t.lift_total == 0 and t.x_est_counts == t.y_est_counts == 0.0
            assert abs(t.x_total_m - (x1 - x0)) < one_count
            assert abs(t.y_total_m - (y1 - y0)) < one_count
        else:
            assert t.lift_total > 0 and s.lift_events == len(lifts0)
            lost_y = (y1 - y0) - t.y_total_m  # metres the lifts ate
            lost_x = (x1 - x0) - t.x_total_m
            assert lost_y > 0.001
            assert t.y_est_counts > 0 and t.y_est_m > 0
            assert t.y_est_m == pytest.approx(lost_y, rel=0.2)
            assert abs(t.x_est_m - lost_x) <= 0.2 * abs(lost_x) + 2 * one_count


def test_settings_read_between_polls_never_loses_counts():
    rig = Rig([{"motion": ConstantVelocity(0.3, -0.2)}])
    emu = rig.emus[0]
    for _ in range(300):
        rig.step()
        rig.clock.t += PERIOD / 3  # counts pile up after the poll ...
        assert rig.poller.serve_command(("settings", 0))[0] == "ok"  # ... the read folds them in
    rig.step()
    t = rig.snap(0)
    assert (emu.stats.overwritten_x, emu.stats.overwritten_y) == (0, 0)
    assert (t.x_total, t.y_total) == measured(emu)
    assert t.seq == 601
    assert abs(t.x_total - 0.3 * (rig.clock.t - rig.t_init) * 1600 / INCH_M) < 1


@pytest.mark.parametrize("lift_ms", [5, 13, 40])
def test_lift_estimate_within_20_percent_at_constant_speed(lift_ms):
    v = (0.05, 0.3)
    lifts = [(T0 + a, T0 + a + lift_ms / 1000) for a in (0.5, 1.2, 2.0)]
    rig = Rig([{"motion": ConstantVelocity(*v), "lift_windows": lifts}], cpi=1600)
    rig.run(3000)
    t = rig.snap(0)
    true_x, true_y = (c * (rig.clock.t - rig.t_init) * 1600 / INCH_M for c in v)
    lost_x, lost_y = true_x - t.x_total, true_y - t.y_total
    assert lost_y >= 3 * lift_ms * 0.3 * 1600 / INCH_M / 1000 * 0.9
    assert t.lift_total >= 3 * (lift_ms - 1)
    assert t.x_est_counts > 0 and t.y_est_counts > 0
    assert t.x_est_counts == pytest.approx(lost_x, rel=0.2)
    assert t.y_est_counts == pytest.approx(lost_y, rel=0.2)
    assert t.y_est_m == pytest.approx(t.y_est_counts * INCH_M / 1600)
    # still: the measured totals hold only what the sensor counted
    assert (t.x_total, t.y_total) == measured(rig.emus[0])


def test_lift_estimate_from_windows_of_polls_is_within_its_sigma():
    """0.3 m/s at 1600 CPI, three 40 ms lifts: each gap is estimated from 20 polls each
    side; the estimate's variance is served with it, and the poller leaves the gap
    (busy False: the hot path again) once the after-window is in."""
    v = (0.05, 0.3)
    lifts = [(T0 + a, T0 + a + 0.04) for a in (0.5, 1.2, 2.0)]
    rig = Rig([{"motion": ConstantVelocity(*v), "lift_windows": lifts}], cpi=1600)
    rig.run(3000)
    t = rig.snap(0)
    true_y = v[1] * (rig.clock.t - rig.t_init) * 1600 / INCH_M
    lost_y = true_y - t.y_total
    sigma_y = t.y_est_var_counts**0.5
    assert 0 < sigma_y < 0.02 * lost_y
    assert abs(t.y_est_counts - lost_y) < 3 * sigma_y + 2  # + the totals' own rounding
    assert t.y_est_var_m == pytest.approx(t.y_est_var_counts * (INCH_M / 1600) ** 2)
    assert not rig.channels[0].gap.busy and not rig.channels[0].gap_m.busy


def test_sim_lift_lost_ground_truth_counts_what_a_lift_ate():
    lifts = [(T0 + 0.5, T0 + 0.52)]
    rig = Rig([{"motion": ConstantVelocity(0.0, 0.3), "lift_windows": lifts}], cpi=1600)
    rig.run(1000)
    t = rig.snap(0)
    true_y = 0.3 * (rig.clock.t - rig.t_init) * 1600 / INCH_M
    lost = true_y - t.y_total  # about 20 ms * 0.3 m/s = 6 mm = 378 counts
    assert lost > 300
    assert t.lift_lost_y == pytest.approx(lost, abs=2 * 0.3 * 1600 / INCH_M / 1000)


def test_settings_reads_during_a_lift_do_not_inflate_the_estimate():
    lifts = [(T0 + 0.5, T0 + 0.52)]
    rig = Rig([{"motion": ConstantVelocity(0.0, 0.3), "lift_windows": lifts}], cpi=1600)
    rig.run(505)
    for _ in range(10):
        assert rig.poller.serve_command(("settings", 0))[0] == "ok"
    rig.run(495)
    t = rig.snap(0)
    lost = 0.3 * (rig.clock.t - rig.t_init) * 1600 / INCH_M - t.y_total
    assert t.y_est_counts == pytest.approx(lost, rel=0.1)


def test_lift_estimate_across_a_cpi_change_keeps_each_count_at_its_scale():
    lifts = [(T0 + 0.5, T0 + 0.52)]
    rig = Rig([{"motion": ConstantVelocity(0.0, 0.3), "lift_windows": lifts}], cpi=1600)
    rig.run(510)  # in the middle of the lift
    assert rig.poller.serve_command(("set_cpi", 0, 3200)) == ("ok", 3200)
    rig.run(490)
    t = rig.snap(0)
    lost_m = 0.3 * (rig.clock.t - rig.t_init) - t.y_total_m
    assert lost_m > 0.005
    assert t.y_est_m == pytest.approx(lost_m, rel=0.1)


# --- overflow ---------------------------------------------------------------------------------


def test_rare_polls_at_high_speed_wrap_and_are_flagged():
    rig = Rig([{"motion": ConstantVelocity(0.3, 2.0)}], cpi=6400)  # 2 m/s: 504 counts per ms
    emu, ch = rig.emus[0], rig.channels[0]
    n_polls = 10
    want_dy = []
    for k in range(1, n_polls + 1):
        t = T0 + k * 0.1  # 100 ms between polls: about 50 394 counts > 32 767
        rig.clock.t = t
        before = emu.stats.counted_y
        rig.poller.poll(ch, round(t * 1e9), t)
        d = emu.stats.counted_y - before
        assert d > 0x7FFF
        want_dy.append((d + 0x8000) % 0x10000 - 0x8000)  # what a 16-bit counter keeps
    t = rig.snap(0)
    a = rig.ring(0)
    assert t.seq == n_polls
    assert t.overflows == n_polls == emu.stats.overflow_events
    assert np.all(a["flags"] & ss.FLAG_OVERFLOW)
    assert a["dy"].tolist() == want_dy
    # Y lost whole multiples of 2**16 to the wrap; X (7 559 counts a poll) did not wrap
    assert t.x_total == emu.stats.counted_x
    lost = emu.stats.counted_y - t.y_total
    assert lost == n_polls * 65536


def test_1khz_polling_at_2_m_s_and_6400_cpi_never_wraps():
    rig = Rig([{"motion": ConstantVelocity(-0.5, 2.0)}], cpi=6400)
    rig.run(3000)
    t = rig.snap(0)
    emu = rig.emus[0]
    assert t.overflows == 0 == emu.stats.overflow_events
    assert (t.x_total, t.y_total) == (emu.stats.counted_x, emu.stats.counted_y)
    assert abs(t.y_total - 2.0 * 3.0 * 6400 / INCH_M) < 2
    assert t.y_total_m == pytest.approx(6.0, abs=INCH_M / 6400 * 2)
    assert not np.any(rig.ring(0)["flags"] & ss.FLAG_OVERFLOW)


# --- concurrent readers -----------------------------------------------------------------------


def test_reader_thread_sees_consistent_monotone_totals_while_polling():
    rig = Rig([{"motion": ConstantVelocity(0.07, 0.23)}] * 2, ring=8192)
    state = rig.state
    stop = threading.Event()
    problems: list[str] = []
    checks = [0]

    def reader() -> None:
        last = [ss.Totals.zero(), ss.Totals.zero()]
        since = [0, 0]
        collected: list[list[int]] = [[], []]
        while not stop.is_set() or any(since[i] < state.snapshot(i).seq for i in (0, 1)):
            for i in (0, 1):
                t = state.snapshot(i, timeout_s=2.0)
                p = last[i]
                if not (
                    t.seq >= p.seq
                    and t.x_total >= p.x_total
                    and t.y_total >= p.y_total
                    and t.y_total_m >= p.y_total_m
                ):
                    problems.append(f"not monotone: {p} -> {t}")
                last[i] = t
                # the ring up to this snapshot's seq sums to its totals
                # (max_samples 0 would mean "no cap": nothing to check at seq 0)
                first, nxt, dropped, a = state.samples(i, 0, t.seq or 1)
                if not t.seq:
                    pass
                elif (first, nxt, dropped) != (0, t.seq, 0):
                    problems.append(f"ring read {first, nxt, dropped} for seq {t.seq}")
                elif (
                    int(a["dx"].astype(np.int64).sum()) != t.x_total
                    or int(a["dy"].astype(np.int64).sum()) != t.y_total
                ):
                    problems.append(f"ring sum != totals at seq {t.seq}")
                # and chaining next_seq sees every poll once
                first, nxt, dropped, a = state.samples(i, since[i], 100)
                if first != since[i] or dropped:
                    problems.append(f"chained read skipped: {since[i]} -> {first}, {dropped}")
                collected[i] += a["stamp_ns"].tolist()
                since[i] = nxt
                checks[0] += 1
        for i in (0, 1):
            stamps = collected[i]
            if stamps != sorted(set(stamps)) or len(stamps) != state.snapshot(i).seq:
                problems.append(f"chained reads of sensor {i} lost or repeated polls")

    def guarded_reader() -> None:
        try:
            reader()
        except Exception as exc:  # a crashed reader is a failure, not a warning
            problems.append(f"reader crashed: {exc!r}")

    th = threading.Thread(target=guarded_reader)
    th.start()
    try:
        rig.run(6000)
    finally:
        stop.set()
        th.join(30)
    assert not th.is_alive()
    assert problems == []
    assert checks[0] > 50
    for i, emu in enumerate(rig.emus):
        assert (rig.snap(i).x_total, rig.snap(i).y_total) == measured(emu)


# --- commands ----------------------------------------------------------------------------------


def frozen(rig: Rig) -> tuple:
    """Everything a command must not touch."""
    s = rig.state
    return (
        [rig.snap(i) for i in range(len(rig.emus))],
        [(ch.cpi_x, ch.cpi_y, ch.cpi_wanted, ch.seq) for ch in rig.channels],
        [(e.cpi_x, e.cpi_y, e.stats.transfers) for e in rig.emus],
        s.ring_stamp.copy(),
        s.ring_dx.copy(),
        s.ring_dy.copy(),
        s.ring_flags.copy(),
        s.ring_cpi.copy(),
    )


def assert_same(a: tuple, b: tuple) -> None:
    assert a[:3] == b[:3]
    for x, y in zip(a[3:], b[3:], strict=True):
        assert np.array_equal(x, y)


@pytest.fixture(scope="module")
def busy_rig() -> Rig:
    rig = Rig([{"motion": ConstantVelocity(0.1, 0.2)}] * 2)
    rig.run(200)
    rig.events()
    return rig


@pytest.mark.parametrize(
    "cpi", [0, 99, 150, 6401, 6500, 65535, -1, -100, "800", 1.5, 800.0, None, True, [800]]
)
def test_bad_cpi_is_invalid_and_changes_nothing(busy_rig, cpi):
    rig = busy_rig
    before = frozen(rig)
    status, msg = rig.poller.serve_command(("set_cpi", 1, cpi))
    assert status == "invalid"
    assert "100..6400" in msg
    assert repr(cpi) in msg or str(cpi) in msg  # says what was wrong
    assert_same(frozen(rig), before)
    assert rig.events() == []


def test_good_cpi_then_polls_keep_their_scale():
    rig = Rig([{"motion": ConstantVelocity(0.0, TEN_PER_MS)}], cpi=1000)
    rig.run(10)
    assert rig.poller.serve_command(("set_cpi", 0, 6400)) == ("ok", 6400)
    assert rig.channels[0].cpi_wanted == 6400
    rig.run(10)  # 64 counts/ms
    t = rig.snap(0)
    assert t.y_total == 100 + 640
    assert t.y_total_m == pytest.approx(100 * INCH_M / 1000 + 640 * INCH_M / 6400, abs=1e-12)
    a = rig.ring(0)
    assert a["cpi"].tolist() == [1000] * 11 + [6400] * 10
    assert a["dy"].tolist() == [10] * 10 + [0] + [64] * 10  # the drain read found nothing


def test_unknown_command_is_an_error_and_changes_nothing(busy_rig):
    rig = busy_rig
    before = frozen(rig)
    assert rig.poller.serve_command(("calibrate", 0)) == ("error", "unknown command 'calibrate'")
    assert_same(frozen(rig), before)


def test_command_pipe_survives_malformed_commands(busy_rig):
    rig = busy_rig
    before = frozen(rig)
    for msg in [("bogus",), ("set_cpi", 0), ("settings", 7), ("set_cpi", 0, "fast")]:
        rig.cmd.send(msg)
    rig.poller.handle_commands()
    replies = [rig.cmd.recv() for _ in range(4)]
    assert [r[0] for r in replies] == ["error", "error", "error", "invalid"]
    assert "'bogus'" in replies[0][1] and "'set_cpi'" in replies[1][1]
    assert "'settings'" in replies[2][1]
    assert rig.poller.running
    logs = rig.events()
    assert len(logs) == 3 and all(e[0] == "log" and "Traceback" in e[1] for e in logs)
    assert_same(frozen(rig), before)
    # and it still serves a good command afterwards
    rig.cmd.send(("settings", 0))
    rig.poller.handle_commands()
    assert rig.cmd.recv()[0] == "ok"


def test_stop_command():
    rig = Rig([{"motion": ConstantVelocity(0.0, 0.0)}])
    assert rig.poller.serve_command(("stop",)) == ("ok", None)
    assert rig.poller.running is False


class FailingBus(EmulatedPLN2033):
    """An emulator whose ``fail_in``-th transfer from now raises."""

    fail_in: int | None = None

    def xfer2(self, data):
        if self.fail_in is not None:
            self.fail_in -= 1
            if self.fail_in == 0:
                self.fail_in = None
                raise SpiError("SPI transfer failed (test)")
        return super().xfer2(data)


def test_set_cpi_spi_error_is_reported():
    rig = Rig([{"motion": ConstantVelocity(0.1, 0.2)}], bus_class=FailingBus)
    rig.run(10)
    rig.emus[0].fail_in = 1  # the transfer of the drain read and the CPI writes fails
    status, msg = rig.poller.serve_command(("set_cpi", 0, 3200))
    assert status == "error" and DEVICES[0] in msg and "test" in msg
    t = rig.snap(0)
    assert t.spi_errors == 1 and t.cpi_x == t.cpi_y == 1600
    assert (rig.emus[0].cpi_x, rig.emus[0].cpi_y) == (1600, 1600)
    assert rig.channels[0].cpi_wanted == 1600


def test_set_cpi_failing_half_way_keeps_the_scale_right():
    rig = Rig([{"motion": ConstantVelocity(0.1, 0.2)}], bus_class=FailingBus)
    emu, ch = rig.emus[0], rig.channels[0]
    rig.run(10)
    # transfers of set_cpi: the drain read with both CPI writes (1); the read-back of X
    # (2 writes + a read); of Y: its read fails (the chip runs at the new CPI already)
    emu.fail_in = 1 + 3 + 3
    status, _ = rig.poller.serve_command(("set_cpi", 0, 3200))
    assert status == "error"
    before = rig.snap(0)
    base = measured(emu)
    rig.run(100)
    t = rig.snap(0)
    dx = measured(emu)[0] - base[0]
    assert (ch.cpi_x, ch.cpi_y) == (emu.cpi_x, emu.cpi_y)
    assert t.x_total_m - before.x_total_m == pytest.approx(dx * INCH_M / emu.cpi_x, rel=1e-9)


# --- failure and recovery ----------------------------------------------------------------------


def test_fault_window_down_other_channel_keeps_polling_then_reinit():
    fault = (T0 + 1.0 - PERIOD / 2, T0 + 2.0 - PERIOD / 2, "raise")  # fails polls 1000..1999
    rig = Rig(
        [
            {"motion": ConstantVelocity(0.1, 0.2), "fault_windows": [fault]},
            {"motion": ConstantVelocity(-0.1, 0.3)},
        ],
        cpi=1600,
        retry=0.3,
    )
    rig.events()
    rig.run(999)
    assert [rig.snap(i).state for i in (0, 1)] == [ss.STATE_UP, ss.STATE_UP]
    good_seq = rig.snap(0).seq
    for n in range(1, ERRORS_BEFORE_DOWN):
        rig.step()
        t = rig.snap(0)
        assert t.state == ss.STATE_UP and t.spi_errors == n
    assert rig.events() == []
    rig.step()  # the third failed poll
    t = rig.snap(0)
    assert t.state == ss.STATE_DOWN
    assert t.spi_errors == ERRORS_BEFORE_DOWN
    assert t.seq == good_seq + ERRORS_BEFORE_DOWN  # each failed poll is in the ring
    a = rig.ring(0)
    assert a["flags"][-ERRORS_BEFORE_DOWN:].tolist() == [ss.FLAG_SPI_ERROR] * ERRORS_BEFORE_DOWN
    ev = rig.events()
    assert len(ev) == 1 and ev[0][:2] == ("down", DEVICES[0])
    assert "3 polls failed" in ev[0][2] and "emulated fault" in ev[0][2]
    assert "retrying every 0.3 s" in ev[0][2]

    # while down: commands say so; the other channel polls on, counts conserved
    for cmd in [("settings", 0), ("set_cpi", 0, 800), ("set_cpi", 0, 7)]:
        status, msg = rig.poller.serve_command(cmd)
        assert status == "error" and DEVICES[0] in msg and "down" in msg
    seq0 = rig.snap(0).seq
    seq1 = rig.snap(1).seq
    rig.run(500)  # up to t = 1.5 s: one retry (at 1.302 s) failed
    assert rig.snap(0).seq == seq0  # no polls recorded while down
    assert rig.snap(0).state == ss.STATE_DOWN and rig.snap(0).reinits == 1
    assert rig.snap(1).seq == seq1 + 500
    ev = rig.events()
    assert [e[:2] for e in ev] == [("down", DEVICES[0])]  # the failed retry says why, once
    assert "start-up failed" in ev[0][2]

    rig.run(800)  # retries at 1.602 and 1.902 s fail; the window ends; 2.202 s works
    t = rig.snap(0)
    assert (t.state, t.reinits) == (ss.STATE_UP, 2)
    assert (t.cpi_x, t.cpi_y) == (1600, 1600) == (rig.emus[0].cpi_x, rig.emus[0].cpi_y)
    ev = rig.events()
    assert ev == [("up", DEVICES[0], "Philips PLN2033 initialised at 1600 CPI")]
    # counts are conserved again from the re-initialisation on
    base0 = measured(rig.emus[0])
    tot0 = (t.x_total, t.y_total)
    rig.run(300)
    t = rig.snap(0)
    now = measured(rig.emus[0])
    assert (t.x_total - tot0[0], t.y_total - tot0[1]) == (now[0] - base0[0], now[1] - base0[1])
    assert t.y_total - tot0[1] > 0
    # the other channel: every poll counted, nothing lost
    t1 = rig.snap(1)
    assert t1.seq == rig.k and t1.state == ss.STATE_UP and t1.spi_errors == 0
    assert (t1.x_total, t1.y_total) == measured(rig.emus[1]) == (t1.gen_x, t1.gen_y)


def test_reinit_restores_the_cpi_last_commanded():
    fault = (T0 + 0.5, T0 + 0.6, "raise")
    rig = Rig([{"motion": ConstantVelocity(0.1, 0.2), "fault_windows": [fault]}], retry=0.05)
    rig.run(100)
    assert rig.poller.serve_command(("set_cpi", 0, 3200)) == ("ok", 3200)
    rig.run(700)
    t = rig.snap(0)
    assert t.reinits == 2 and t.state == ss.STATE_UP
    assert (t.cpi_x, t.cpi_y) == (3200, 3200) == (rig.emus[0].cpi_x, rig.emus[0].cpi_y)


def test_start_up_failure_retries_after_the_interval():
    fault = (T0 - 1.0, T0 + 0.25, "raise")
    rig = Rig([{"motion": ConstantVelocity(0.1, 0.2), "fault_windows": [fault]}], retry=0.1)
    emu = rig.emus[0]
    t = rig.snap(0)
    assert t.state == ss.STATE_DOWN and t.reinits == 0
    ev = rig.events()
    assert len(ev) == 1 and ev[0][0] == "down" and "start-up failed" in ev[0][2]
    rig.run(99)  # retries wait for the interval: no transfer before it
    assert emu.stats.transfers == emu.stats.faulted_transfers == 1
    rig.step()  # 0.1 s: the retry, still in the window
    assert emu.stats.transfers == emu.stats.faulted_transfers == 2
    assert rig.events() == []  # the same failure again is not news
    rig.run(200)  # 0.2 s fails again, 0.3 s works
    t = rig.snap(0)
    assert t.state == ss.STATE_UP and t.reinits == 1
    assert emu.stats.faulted_transfers == 3
    assert rig.events() == [("up", DEVICES[0], "Philips PLN2033 initialised at 1600 CPI")]
    assert t.seq == rig.k - 300  # polled from 0.3 s on (the poll that re-inits records nothing)


# --- the real loop, briefly ------------------------------------------------------------------


def test_run_loop_polls_serves_commands_and_checks_health(monkeypatch):
    """run() in a thread for a moment, on the sim backend's own real-time emulators."""
    monkeypatch.setattr(poller_mod, "HEALTH_CHECK_S", 0.05)
    n, ring = 2, 4096
    state = ss.SharedState(bytearray(ss.SharedState.size(n, ring)), n, ring)
    cmd, cmd_child = Pipe()
    ev, ev_child = Pipe()
    cfg = PollerConfig(
        devices=DEVICES, backend="sim", cpi=1600, ring_size=ring, sim=SimConfig(speed=0.2)
    )
    p = Poller(cfg, state, cmd_child, ev_child)
    checks = []
    real_check = p.check_health
    p.check_health = lambda ch, now: (checks.append(ch.i), real_check(ch, now))[1]
    th = threading.Thread(target=p.run, daemon=True)
    th.start()
    try:
        wait_until(lambda: state.glob[ss.G_POLLS] >= 100, 30, "100 polls", interval=0.01)
        assert state.glob[ss.G_RUNNING] == 1
        cmd.send(("set_cpi", 1, 800))
        state.glob[ss.G_COMMANDS_SENT] += 1  # as PollerClient.command does
        assert cmd.poll(scaled(30)), "the loop did not serve the command"
        assert cmd.recv() == ("ok", 800)
        polls = int(state.glob[ss.G_POLLS])
        wait_until(lambda: state.glob[ss.G_POLLS] >= polls + 150, 30,
                   "150 polls after the command", interval=0.01)
    finally:
        p.running = False
        th.join(scaled(30))
    assert not th.is_alive()
    assert state.glob[ss.G_RUNNING] == 0
    polls = int(state.glob[ss.G_POLLS])
    assert polls >= 250
    assert int(state.hist.sum()) == polls - 1  # one period between each two polls
    for i in (0, 1):
        t = state.snapshot(i)
        assert t.state == ss.STATE_UP and t.reinits == 1  # nothing to fix: no re-init
        assert t.seq == polls + (i == 1)  # + the drain read of the CPI change
        assert t.y_total > 0 and (t.x_total, t.y_total) == (t.gen_x, t.gen_y)
    assert state.snapshot(1).cpi_x == 800 and state.snapshot(0).cpi_x == 1600
    assert checks.count(0) >= 2 and checks.count(1) >= 2
    assert [e[0] for e in _drain(ev)] == ["up", "up"]


def _drain(conn) -> list:
    out = []
    while conn.poll():
        out.append(conn.recv())
    return out


# --- the health check (a chip that reset itself) -----------------------------------------------


def glitch_rig(**kw) -> Rig:
    # A 1.5 ms power glitch: two polls fail (not enough to go down), then the chip
    # is back at its power-on defaults (1000 CPI).
    glitch = (T0 + 1.0 - PERIOD / 2, T0 + 1.0 + 1.5 * PERIOD, "raise")
    return Rig([{"motion": ConstantVelocity(0.1, 0.2), "fault_windows": [glitch]}], **kw)


def test_health_check_with_the_right_cpi_changes_nothing():
    rig = Rig([{"motion": ConstantVelocity(0.1, 0.2)}])
    rig.run(100)
    rig.events()
    rig.clock.t += PERIOD / 2  # counts are waiting in the sensor
    before = rig.snap(0)
    rig.poller.check_health(rig.channels[0], rig.clock.t)
    assert rig.snap(0) == before
    assert rig.events() == []
    rig.run(10)
    t = rig.snap(0)
    assert t.reinits == 1
    assert (t.x_total, t.y_total) == measured(rig.emus[0])  # the CPI reads ate no counts


def test_health_check_reinitialises_a_chip_that_reset_itself():
    # the glitch is found by the CPI read-back before the first poll after it (Poller.poll),
    # not a periodic check later: the chip is already re-initialised when the polls go on
    rig = glitch_rig()
    rig.run(1005)
    t = rig.snap(0)
    emu = rig.emus[0]
    assert t.state == ss.STATE_UP and t.spi_errors == 2
    assert (t.state, t.reinits, t.cpi_x, t.cpi_y) == (ss.STATE_UP, 2, 1600, 1600)
    assert (emu.cpi_x, emu.cpi_y) == (1600, 1600)
    ev = rig.events()
    assert [e[:2] for e in ev] == [("up", DEVICES[0]), ("down", DEVICES[0]), ("up", DEVICES[0])]
    assert "reset itself" in ev[1][2] and "1000" in ev[1][2]
    # a periodic check now changes nothing
    before = rig.snap(0)
    rig.poller.check_health(rig.channels[0], rig.clock.t)
    assert rig.snap(0) == before and rig.events() == []
    # counts conserved again from here
    base, tot = measured(emu), (t.x_total, t.y_total)
    rig.run(100)
    t = rig.snap(0)
    now = measured(emu)
    assert (t.x_total - tot[0], t.y_total - tot[1]) == (now[0] - base[0], now[1] - base[1])


def test_health_check_keeps_a_commanded_cpi():
    rig = Rig([{"motion": ConstantVelocity(0.1, 0.2)}])
    rig.run(10)
    assert rig.poller.serve_command(("set_cpi", 0, 400)) == ("ok", 400)
    rig.events()
    rig.poller.check_health(rig.channels[0], rig.clock.t)
    assert rig.snap(0).reinits == 1 and rig.events() == []
    # and after a glitch that reset the chip (to 1000 CPI) it comes back at the commanded
    # CPI, not the configured one, at the first poll after the glitch
    rig.emus[0].fault_windows = [(rig.clock.t + 0.0005, rig.clock.t + 0.0015, "raise")]
    rig.run(5)
    t = rig.snap(0)
    assert (t.reinits, t.cpi_x, t.cpi_y) == (2, 400, 400)
    assert (rig.emus[0].cpi_x, rig.emus[0].cpi_y) == (400, 400)
    assert "CPI reads 1000/1000" in next(e for e in rig.events() if e[0] == "down")[2]


def test_health_check_spi_error_leaves_the_decision_to_the_polls():
    rig = Rig([{"motion": ConstantVelocity(0.1, 0.2)}], bus_class=FailingBus)
    rig.run(10)
    rig.events()
    rig.emus[0].fail_in = 1
    before = rig.snap(0)
    rig.poller.check_health(rig.channels[0], rig.clock.t)
    assert rig.snap(0) == before and rig.events() == []


def test_health_check_of_a_down_sensor_does_nothing():
    fault = (T0 - 1.0, T0 + 10.0, "raise")
    rig = Rig([{"motion": ConstantVelocity(0.1, 0.2), "fault_windows": [fault]}])
    rig.events()
    transfers = rig.emus[0].stats.transfers
    rig.poller.check_health(rig.channels[0], rig.clock.t)
    assert rig.emus[0].stats.transfers == transfers and rig.events() == []


def test_power_cycled_chip_counts_only_motion_after_power_on():
    clock = FakeClock(0.0)
    emu = EmulatedPLN2033(
        ConstantVelocity(0.0, 0.1), regmap=MAP, clock=clock, fault_windows=[(1.0, 2.0, "raise")]
    )
    drv = PLN2033(emu, MAP)
    clock.t = 0.9
    drv.read_motion()
    clock.t = 1.5
    with pytest.raises(SpiError):
        drv.read_motion()
    clock.t = 2.1
    m = drv.read_motion()
    assert emu.stats.resets == 1 and emu.cpi_y == 1000
    # powered again at 2.0 s at the latest: at most 0.1 s of motion at 1000 CPI
    assert m.dy <= round(0.1 * 0.1 * 1000 / INCH_M) + 1


def test_poller_module_imports_no_ros():
    import subprocess
    import sys

    code = (
        "import sys, mm_beagle.poller.poller; "
        "print(sorted(m for m in sys.modules if 'rclpy' in m))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]"


def test_simulator_bookkeeping_stays_out_of_the_production_channel():
    """Only the sim backend's channels keep the emulator's ground truth; a spidev poller's
    Channel has no trace of it, and its hot path writes no truth fields."""
    cfg = PollerConfig(devices=DEVICES, backend="spidev", ring_size=16)
    state = ss.SharedState(bytearray(ss.SharedState.size(2, 16)), 2, 16)
    chans = Poller(cfg, state, None, None).channels
    assert [type(ch) for ch in chans] == [poller_mod.Channel] * 2
    assert [truth_of(ch) for ch in chans] == [None, None]
    assert not any(hasattr(ch, name) for ch in chans for name in ("truth", "sim_stats"))
    rig = Rig([{"motion": ConstantVelocity(0.0, TEN_PER_MS)}], cpi=1000)
    assert isinstance(rig.channels[0], SimChannel)
    rig.run(5)
    t = rig.snap(0)
    assert (t.y_total, t.gen_y) == (50, 50) and truth_of(rig.channels[0]).ratio == 1.0


def test_spidev_path_imports_no_numpy():
    """The board's agent has no numpy: the poller, its flags, shared state and the link
    import none, and a spidev poller is built and records a poll without it."""
    import subprocess
    import sys

    code = (
        "import sys\n"
        "from mm_beagle.poller import poller as p, shared_state as ss\n"
        "import mm_beagle.link.link, mm_beagle.link.agent, mm_pc.core.poll_flags\n"
        "from pln2033 import Motion\n"
        "cfg = p.PollerConfig(devices=['/dev/spidev9.0', '/dev/spidev9.1'], ring_size=64)\n"
        "state = ss.SharedState(bytearray(ss.SharedState.size(2, 64)), 2, 64)\n"
        "poller = p.Poller(cfg, state, None, None)\n"
        "poller.channels[0].record(1, Motion(1, 2, 0x80, True, False, False))\n"
        "print(sorted(m for m in sys.modules if m.split('.')[0] == 'numpy'))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]"
