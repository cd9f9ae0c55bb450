"""pimoroni's own PMW3901 / PAA5100 client (``pmw3901`` 1.0.x, PyPI), unmodified, against our
emulators (issue 26).

Faked is only what sits at the kernel boundary: the ``spidev.SpiDev`` object the library
opens (its ``xfer2`` bytes go to the emulator), the chip-select gpio line (handed to the
library as the ``(LineRequest, offset)`` pair that gpiodevice passes through), and the clock
behind the library's ``time.sleep`` / ``time.time`` (the emulator's FakeClock). The library's
classes and methods run as published.

Agreement checked here: the init sequence is recognised (and is byte for byte our
``regs``), the ids, the rotation table, the rejection rule, and ``get_motion`` /
``get_motion_slow`` counts equal the emulator's ground truth (and our driver's reading of a
twin emulator). Not checkable against the library, so pinned as OUR assumptions: the counts
per metre (the library returns raw counts; the scale is :mod:`pln2033.pmw3901.flow_scale`)
and which way the native axes point (the library only swaps and inverts them).
docs/sensors.md, "PMW3901 and PAA5100", "Facts and assumptions".
"""

from __future__ import annotations

import types

import pmw3901 as vendor  # the test extra (pyproject.toml) installs it: a missing one is an error
import pytest
from fakes import FakeClock

from pln2033.pmw3901 import PAA5100, PMW3901, EmulatedPAA5100, EmulatedPMW3901, regs
from pln2033.pmw3901.emulator import expected_init_writes
from pln2033.sensor import INCH_M

#: (pimoroni's class, our emulator, our driver)
CHIPS = [
    pytest.param(vendor.PMW3901, EmulatedPMW3901, PMW3901, id="pmw3901"),
    pytest.param(vendor.PAA5100, EmulatedPAA5100, PAA5100, id="paa5100"),
]


class StartsAt:
    """Still until ``t_on``, then (vx, vy) m/s in the true sensor frame (x right, y forward)."""

    def __init__(self, t_on: float, vx: float, vy: float) -> None:
        self.t_on, self.vx, self.vy = t_on, vx, vy

    def displacement(self, t0: float, t1: float) -> tuple[float, float]:
        dt = max(0.0, t1 - max(t0, self.t_on))
        return self.vx * dt, self.vy * dt


class FakeSpiDev:
    """The ``spidev.SpiDev`` the library opens: transfers go to ``bench.emu``."""

    def __init__(self, bench: Bench) -> None:
        self.bench = bench
        self.opened: tuple[int, int] | None = None
        self.max_speed_hz = 0
        self.mode = 0
        self.no_cs = False
        self.transfers = 0
        self.deselected = 0  # transfers made with a gpio chip select high

    def open(self, bus: int, device: int) -> None:
        self.opened = (bus, device)

    def xfer2(self, data: list[int]) -> list[int]:
        self.transfers += 1
        if self.no_cs and not self.bench.cs_line.selected:
            self.deselected += 1
            return [0xFF] * len(data)  # the chip does not listen: MISO floats high
        return self.bench.emu.xfer2(list(data))

    xfer = xfer2

    def close(self) -> None:
        pass


class FakeCsLine:
    """The gpiod ``LineRequest`` of a chip-select line (chip selected while the line is low)."""

    def __init__(self) -> None:
        self.level = 1
        self.changes: list[tuple[float, int]] = []
        self.clock: FakeClock | None = None

    @property
    def selected(self) -> bool:
        return self.level == 0

    def set_value(self, offset: int, value: object) -> None:
        assert offset == 8
        self.level = 1 if value == vendor.Value.ACTIVE else 0
        self.changes.append((self.clock.t if self.clock else 0.0, self.level))


class Bench:
    """One FakeClock for the library's time module, the emulator and our driver."""

    def __init__(self, monkeypatch: pytest.MonkeyPatch) -> None:
        self.clock = FakeClock()
        self.emu: EmulatedPMW3901 | None = None
        self.spi: FakeSpiDev | None = None
        self.cs_line = FakeCsLine()
        self.cs_line.clock = self.clock
        monkeypatch.setattr(
            vendor, "time", types.SimpleNamespace(time=self.clock, sleep=self.clock.sleep)
        )
        monkeypatch.setattr(vendor.spidev, "SpiDev", self._spidev)

    def _spidev(self) -> FakeSpiDev:
        self.spi = FakeSpiDev(self)
        return self.spi

    def vendor(self, vendor_cls, emu: EmulatedPMW3901, **kw):
        """pimoroni's class on ``emu`` (constructed: reset, init, id check)."""
        self.emu = emu
        return vendor_cls(**kw)

    def ours(self, drv_cls, emu: EmulatedPMW3901, **kw):
        drv = drv_cls(emu, name="/dev/spidev0.1", sleep=self.clock.sleep, **kw)
        drv.initialise(0)
        return drv


@pytest.fixture
def bench(monkeypatch: pytest.MonkeyPatch) -> Bench:
    return Bench(monkeypatch)


def counts_per_metre(emu: EmulatedPMW3901) -> float:
    return emu.cpi_y / INCH_M


# --- bring-up ------------------------------------------------------------------------------------


@pytest.mark.parametrize(("vendor_cls", "emu_cls", "drv_cls"), CHIPS)
def test_the_vendor_init_is_recognised_byte_for_byte_and_the_ids_read(
    bench, vendor_cls, emu_cls, drv_cls
):
    emu = emu_cls(clock=bench.clock, record=True)
    f = bench.vendor(vendor_cls, emu)
    assert bench.spi.opened == (0, 1) and bench.spi.max_speed_hz == 400_000
    # recognised: pimoroni's last block after its c1 rule (factory c1 = 26 -> 26 + 14 + 11 = 51)
    assert emu.init_variant == ("pimoroni", "pimoroni") and emu.tracking
    sent = [(r, v) for _, r, v in emu.writes]
    assert sent == expected_init_writes(emu.CHIP, "pimoroni", c1_rule="pimoroni")
    assert (regs.C1_REG, 51) in sent
    assert f.get_id() == [0x49, 0x00]
    assert emu.orientation == 0xA0  # what the init writes; the library sets no rotation itself
    assert emu.stats.protocol_errors == 0 and emu.stats.resets == 1
    # the library's sleeps: 20 ms after the reset, then its init's waits
    waits = sum(v for r, v in regs.INITS[emu.CHIP]["pimoroni"][1] if r == regs.WAIT)
    assert bench.clock.t == pytest.approx(0.020 + waits / 1000)
    # our driver sends the same init bytes when told pimoroni's c1 rule (then selects bank 0)
    emu2 = emu_cls(clock=bench.clock)
    bench.ours(drv_cls, emu2, c1_rule="pimoroni", rotation_deg=None)
    assert emu2.writes == [*emu.writes, (0, regs.BANK_SELECT, 0)]
    assert emu2.init_variant == emu.init_variant


@pytest.mark.parametrize(("vendor_cls", "emu_cls", "drv_cls"), CHIPS)
def test_the_vendor_accepts_revisions_0_and_1_and_refuses_other_ids(
    bench, vendor_cls, emu_cls, drv_cls
):
    assert bench.vendor(vendor_cls, emu_cls(clock=bench.clock, revision=0x01)).get_id() == [
        0x49,
        0x01,
    ]
    assert list(regs.REVISIONS) == [0x00, 0x01]
    with pytest.raises(RuntimeError, match=r"Invalid Product ID or Revision .*0x49/0x02"):
        bench.vendor(vendor_cls, emu_cls(clock=bench.clock, revision=0x02))
    with pytest.raises(RuntimeError, match=r"Invalid Product ID or Revision .*0x48/0x00"):
        bench.vendor(vendor_cls, emu_cls(clock=bench.clock, product_id=0x48))


def test_a_gpio_chip_select_frames_every_transfer(bench):
    emu = EmulatedPMW3901(clock=bench.clock)
    f = bench.vendor(vendor.PMW3901, emu, spi_port=0, spi_cs_gpio=(bench.cs_line, 8))
    spi = bench.spi
    assert spi.opened == (0, 0) and spi.no_cs is True
    assert spi.transfers > 100 and spi.deselected == 0  # every transfer with the line low
    assert emu.tracking and f.get_id() == [0x49, 0x00]
    # first a 50 ms low pulse, then low/high around each transfer, high between them
    assert bench.cs_line.changes[:2] == [(0.0, 0), (pytest.approx(0.05), 1)]
    assert bench.cs_line.level == 1
    assert len(bench.cs_line.changes) == 2 + 2 * spi.transfers


# --- rotation ------------------------------------------------------------------------------------


@pytest.mark.parametrize(("vendor_cls", "emu_cls", "drv_cls"), CHIPS)
def test_rotations_match_our_table_and_turn_the_reading_by_quarter_turns(
    bench, vendor_cls, emu_cls, drv_cls
):
    emu = emu_cls(clock=bench.clock)
    f = bench.vendor(vendor_cls, emu)
    ours = {}
    for rot in (0, 90, 180, 270):
        ours[rot] = drv = bench.ours(drv_cls, emu_cls(clock=bench.clock), rotation_deg=rot)
        f.set_rotation(rot)
        assert emu.orientation == regs.ROTATIONS[rot]  # pimoroni's table is ours
        assert drv.bus.orientation == regs.ROTATIONS[rot]
    with pytest.raises(TypeError, match="0, 90, 180 or 270"):
        f.set_rotation(45)
    # 1 s at (0.05, 0.10) m/s under each rotation; the rotation-0 reading is (a, b)
    readings = {}
    for rot in (0, 90, 180, 270):
        f.set_rotation(rot)
        emu.motion = StartsAt(bench.clock.t, 0.05, 0.10)
        ours[rot].bus.motion = StartsAt(bench.clock.t, 0.05, 0.10)
        f.get_motion_slow()  # clear what the previous rotation left (nothing: still)
        ours[rot].read_motion()
        bench.clock.t += 1.0
        readings[rot] = f.get_motion()
        m = ours[rot].read_motion()
        # our driver reads what pimoroni's reads (each emulator carries its own fraction)
        assert abs(m.dx - readings[rot][0]) <= 1 and abs(m.dy - readings[rot][1]) <= 1
        emu.motion = ours[rot].bus.motion = StartsAt(1e9, 0.0, 0.0)
    a, b = readings[0]
    want = {0: (a, b), 90: (-b, a), 180: (-a, -b), 270: (b, -a)}
    for rot, (x, y) in readings.items():
        assert abs(x - want[rot][0]) <= 1 and abs(y - want[rot][1]) <= 1, (rot, readings)


# --- counts against the ground truth -------------------------------------------------------------


def run_both(bench, vendor_cls, emu_cls, drv_cls, read: str, vx: float, vy: float, polls: int):
    """pimoroni's ``read`` ("get_motion"/"get_motion_slow") and our driver on twin emulators,
    both at rotation 0, a 10 ms poll grid from the start of the motion: sums and emulators."""
    emu = emu_cls(clock=bench.clock)
    f = bench.vendor(vendor_cls, emu)
    f.set_rotation(0)
    twin = emu_cls(clock=bench.clock)
    drv = bench.ours(drv_cls, twin, rotation_deg=0)
    t_on = bench.clock.t
    emu.motion = twin.motion = StartsAt(t_on, vx, vy)
    vendor_sum = [0, 0]
    ours_sum = [0, 0]
    for k in range(1, polls + 1):
        bench.clock.t = t_on + 0.01 * k
        x, y = getattr(f, read)()
        m = drv.read_motion()
        vendor_sum = [vendor_sum[0] + x, vendor_sum[1] + y]
        ours_sum = [ours_sum[0] + m.dx, ours_sum[1] + m.dy]
    return vendor_sum, ours_sum, emu, bench.clock.t - t_on


@pytest.mark.parametrize("read", ["get_motion", "get_motion_slow"])
@pytest.mark.parametrize(("vendor_cls", "emu_cls", "drv_cls"), CHIPS)
def test_vendor_counts_equal_the_emulators_truth_and_our_drivers(
    bench, vendor_cls, emu_cls, drv_cls, read
):
    # 2 s at (0.12, 0.25) m/s (below both chips' tracking limits), 200 polls
    vendor_sum, ours_sum, emu, dt = run_both(
        bench, vendor_cls, emu_cls, drv_cls, read, 0.12, 0.25, 200
    )
    s = emu.stats
    assert vendor_sum == [s.counted_x, s.counted_y]  # every counted count read, none twice
    assert vendor_sum == ours_sum  # the same numbers as our driver
    cpm = counts_per_metre(emu)
    assert abs(vendor_sum[0] - 0.12 * dt * cpm) <= 1
    assert abs(vendor_sum[1] - 0.25 * dt * cpm) <= 1
    assert s.protocol_errors == 0 and s.overwritten_x == s.overwritten_y == 0


@pytest.mark.parametrize(("vendor_cls", "emu_cls", "drv_cls"), CHIPS)
def test_the_vendor_rejects_the_reads_of_a_lift_our_driver_keeps_their_counts(
    bench, vendor_cls, emu_cls, drv_cls
):
    """Both apply the same rule (SQUAL < 0x19 and shutter upper 0x1F); pimoroni's get_motion
    then discards the burst and retries every 10 ms, so the counts made before the lift and
    after the touch-down that those bursts carried are lost to it; our driver returns them
    with the low quality (the poller keeps them, flagged)."""
    t0 = 10.0  # after both bring-ups
    vy = 1250 * INCH_M / emu_cls.OPTICS.cpi(emu_cls.HEIGHT_DEFAULT_M)  # 1.25 counts per ms
    # the schedule of test_pmw3901_driver's straddle test: motion from 0.2 ms, a lift from
    # 23.2 to 116.8 ms (edges inside the polls at 30 and 120 ms), 10 ms polls
    kw = {"clock": bench.clock, "lift_windows": [(t0 + 0.0232, t0 + 0.1168)]}
    emu = emu_cls(motion=StartsAt(t0 + 0.0002, 0.0, vy), **kw)
    twin = emu_cls(motion=StartsAt(t0 + 0.0002, 0.0, vy), **kw)
    f = bench.vendor(vendor_cls, emu)
    f.set_rotation(0)
    drv = bench.ours(drv_cls, twin, rotation_deg=0)
    assert bench.clock.t < t0
    ours, low = [], []
    for k in range(1, 21):
        bench.clock.t = t0 + 0.01 * k
        m = drv.read_motion()
        ours.append(m.dy)
        if drv.info.low_quality(m.quality):
            low.append(k * 10)
    assert ours[:4] == [12, 12, 4, 0] and ours[11:13] == [4, 13]
    assert low == list(range(30, 121, 10))
    assert sum(ours) == twin.stats.counted_y == 132
    got = []  # (ms the call started, ms it returned, dy)
    bench.clock.t = t0  # the vendor's emulator has seen nothing since its bring-up: replay
    while bench.clock.t < t0 + 0.1999:
        start = round((bench.clock.t - t0) * 1000) + 10
        bench.clock.t = t0 + start / 1000
        dy = f.get_motion()[1]
        got.append((start, round((bench.clock.t - t0) * 1000), dy))
    # the call at 30 ms: its burst (4 counts) and the retries up to 120 ms (4 more) rejected
    assert got[:4] == [(10, 10, 12), (20, 20, 12), (30, 130, 13), (140, 140, 12)]
    assert sum(dy for _, _, dy in got) == emu.stats.counted_y - 8 == 124
    assert emu.stats.counted_y == twin.stats.counted_y


def test_the_vendor_times_out_under_a_long_lift(bench):
    emu = EmulatedPMW3901(clock=bench.clock, lift_windows=[(0.0, 100.0)])
    f = bench.vendor(vendor.PMW3901, emu)
    t = bench.clock.t
    with pytest.raises(RuntimeError, match="Timed out waiting for motion data"):
        f.get_motion(timeout=1)
    assert bench.clock.t - t == pytest.approx(1.0, abs=0.011)


# --- our assumptions, pinned (the library cannot check them) -------------------------------------


@pytest.mark.parametrize(
    ("vendor_cls", "emu_cls", "height_m", "counts"),
    [(vendor.PMW3901, EmulatedPMW3901, 0.10, 4090), (vendor.PAA5100, EmulatedPAA5100, 0.025, 9117)],
)
def test_our_assumption_counts_per_metre_at_the_default_height(
    bench, vendor_cls, emu_cls, height_m, counts
):
    """OUR ASSUMPTION, not pimoroni's (its library returns raw counts, no scale): a 1 m push
    reads 4090 counts on a PMW3901 at 0.10 m ([bitcraze] 30 px over 4.2 deg) and 9117 on a
    PAA5100 at 25 mm ([ofr] 42 deg, 35 px, 5 counts per px). A real board: docs/sensors.md."""
    emu = emu_cls(clock=bench.clock, height_m=height_m)
    assert emu.height_m == emu.HEIGHT_DEFAULT_M == height_m
    f = bench.vendor(vendor_cls, emu)
    f.set_rotation(0)
    emu.motion = StartsAt(bench.clock.t, 0.0, 0.25)
    total = 0
    for _ in range(400):  # 4 s at 0.25 m/s = 1 m
        bench.clock.t += 0.01
        total += f.get_motion()[1]
    assert abs(total - counts) <= 1
    assert counts == int(1 / (height_m * emu.optics.rad_per_count))


def test_our_assumption_axis_directions(bench):
    """OUR ASSUMPTION: at pimoroni's rotation 0 (0xE0) a push to the sensor's right reads
    +x and a push forward +y (native counts = (-y, -x) of that frame). pimoroni's library and
    README name no direction; neither does any source we have. Under the init's own 0xA0
    (no set_rotation) forward then reads -y. A real board: docs/sensors.md."""
    emu = EmulatedPMW3901(clock=bench.clock)
    f = bench.vendor(vendor.PMW3901, emu)
    for rot, push, want in (
        (None, (0.1, 0.0), (1, 0)),
        (None, (0.0, 0.1), (0, -1)),
        (0, (0.1, 0.0), (1, 0)),
        (0, (0.0, 0.1), (0, 1)),
    ):
        if rot is not None:
            f.set_rotation(rot)
        emu.motion = StartsAt(bench.clock.t, *push)
        bench.clock.t += 1.0
        x, y = f.get_motion()
        n = 0.1 * counts_per_metre(emu)
        assert (round(x / n), round(y / n)) == want, (rot, push, x, y)
        emu.motion = StartsAt(1e9, 0.0, 0.0)
