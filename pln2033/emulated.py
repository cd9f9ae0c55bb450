"""The motion -> counts model every chip emulator shares (:class:`CountingCore`).

A motion source gives the true sensor-frame displacement over time; the core
turns it into counts at the current CPI (keeping the fraction, so counts follow
the true position within one count), wraps its counters at ``counter_bits``,
clears them when a lift starts, stops counting on a poor surface, adds count
noise and decides SPI/I2C faults (with a power cycle when a fault window ends).
The chip emulators add their own bytes on top (register latches, bursts,
product ids); they subclass the core or own one. The ground truth in
:class:`EmulatorStats` is what tests and the sim backend compare against.
"""

from __future__ import annotations

import math
import random
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

from .errors import SpiError
from .motion import MotionSource, Stationary
from .sensor import INCH_M

FAULT_MODES = ("raise", "no_response", "corrupt")


@dataclass
class EmulatorStats:
    """Ground truth kept by the emulator, for tests and benchmarks (counts)."""

    counted_x: int = 0  # counts that entered the X counter
    counted_y: int = 0
    lift_cleared_x: int = 0  # counts the lift cleared before anyone read them
    lift_cleared_y: int = 0
    lift_motion_x: float = 0.0  # counts the motion during lifts (and poor surface) would have made
    lift_motion_y: float = 0.0
    overwritten_x: int = 0  # latched counts lost to a second latch before the read
    overwritten_y: int = 0
    overflow_events: int = 0
    lift_events: int = 0  # lifts started
    low_quality_events: int = 0  # poor-surface windows entered
    transfers: int = 0
    faulted_transfers: int = 0
    # Bus traffic the chip would not take as sent, counted once each; what counts is per chip:
    # a frame of the wrong length (PLN2033: not whole 3-byte frames; PMW3901/PAA5100: an odd
    # length outside the burst; PMW33xx: a write without its data byte, a motion burst not
    # armed by a Motion_Burst write) and, on the PMW33xx, every broken timing constraint BETWEEN
    # COMMANDS of the datasheet's Table 4 (tSWW, tSWR, tSRW, tSRR, tSRAD, tSRAD_MOTBR, tBEXIT,
    # tNCS-SCLK, tSCLK-NCS after a write, the power-up, SROM and CRC waits), measured from the
    # end of one command to the start of the next whether or not chip select rose; the model
    # is pln2033/pmw33xx/timing.py, named per constraint in EmulatedPMW33xx.timing_errors
    # (docs/sensors.md "The timing model"). The OTOS's I2C has no such rule: it stays 0.
    protocol_errors: int = 0
    resets: int = 0
    history: list[tuple] = field(default_factory=list)


def wrap(value: int, bits: int = 16) -> tuple[int, bool]:
    """``value`` wrapped into a signed ``bits``-bit counter, and whether it wrapped."""
    half = 1 << (bits - 1)
    if -half <= value < half:
        return value, False
    return ((value + half) & ((half << 1) - 1)) - half, True


class _Windows:
    """Sorted (start, end) windows looked up with a time that only moves forward."""

    def __init__(self, windows: Sequence[tuple[float, float]]) -> None:
        self.w = sorted((float(a), float(b)) for a, b, *_ in windows)
        self.i = 0

    def __bool__(self) -> bool:
        return bool(self.w)

    def overlaps(self, t0: float, t1: float) -> bool:
        """A window overlaps (t0, t1]; windows that ended by t0 are skipped for good."""
        w, i = self.w, self.i
        while i < len(w) and w[i][1] <= t0:
            i += 1
        self.i = i
        return i < len(w) and w[i][0] < t1

    def covers_end(self, t: float) -> bool:
        """The current window (after :meth:`overlaps`) still runs at ``t``."""
        return self.i < len(self.w) and t < self.w[self.i][1]


class CountingCore:
    """Motion to counts for one emulated sensor (see the module docstring).

    Args:
        motion: true sensor-frame displacement over time (metres).
        clock: seconds, monotonic; inject a fake clock for deterministic tests.
        lift_windows: (start, end) times during which the sensor is lifted.
        noise_counts: standard deviation of count noise per sqrt(second) of time.
        fault_windows: (start, end, mode) times during which transfers fail;
            mode is one of FAULT_MODES. Leaving a window power-cycles the chip
            when ``reset_after_fault`` is true.
        record: keep every transfer in ``stats.history``.
        low_quality_windows: (start, end) times over a poor surface: the chip
            counts nothing and reports a low quality figure.
        cpi: the resolution counts start at (float: optical flow's effective CPI).
        counter_bits: width of the signed counters.
    """

    def __init__(
        self,
        motion: MotionSource | None = None,
        clock: Callable[[], float] = time.monotonic,
        lift_windows: Sequence[tuple[float, float]] = (),
        noise_counts: float = 0.0,
        fault_windows: Sequence[tuple[float, float, str]] = (),
        reset_after_fault: bool = True,
        seed: int = 0,
        record: bool = False,
        low_quality_windows: Sequence[tuple[float, float]] = (),
        cpi: float = 1000.0,
        counter_bits: int = 16,
    ) -> None:
        self.motion: MotionSource = motion or Stationary()
        self.clock = clock
        self.lift_windows = sorted(lift_windows)
        self._lifts = _Windows(self.lift_windows)
        self._poor = _Windows(low_quality_windows)
        self.noise_counts = noise_counts
        for w in fault_windows:
            if w[2] not in FAULT_MODES:
                raise ValueError(f"fault mode {w[2]!r} unknown; allowed: {FAULT_MODES}")
        self.fault_windows = sorted(fault_windows)
        self.reset_after_fault = reset_after_fault
        self.fault: str | None = None  # fault on demand, for tests
        self.record = record
        self.counter_bits = counter_bits
        self.stats = EmulatorStats()
        self._rng = random.Random(seed)
        self._t = clock()
        self._in_fault_window = False
        self._fault_end = 0.0
        self._lifted = False
        self.poor_surface = False
        self.counting = True  # False while powered down or not tracking
        self.cpi_default = cpi
        self.reset_counts()

    # --- state ----------------------------------------------------------------------------

    def reset_counts(self) -> None:
        """Power-up state of the counters: nothing counted, default CPI, no flags."""
        self.cpi_x = self.cpi_y = self.cpi_default
        self.acc_x = self.acc_y = 0
        self._frac_x = self._frac_y = 0.0
        self._moved = False
        self._lift_flag = self._lifted
        self._ovf_x = self._ovf_y = False

    def power_cycle(self) -> None:
        """The chip lost power (end of a fault window): chips override to reset registers too."""
        self.reset_counts()
        self.stats.resets += 1

    def clear_latches(self) -> tuple[int, int]:
        """A lift starts: clear any chip latches, return the counts they held (override)."""
        return 0, 0

    def set_cpi_x(self, cpi: float) -> None:
        self._frac_x *= cpi / self.cpi_x
        self.cpi_x = cpi

    def set_cpi_y(self, cpi: float) -> None:
        self._frac_y *= cpi / self.cpi_y
        self.cpi_y = cpi

    def take_counts(self) -> tuple[int, int]:
        """The counters' values, cleared (the chip's latch-and-clear)."""
        x, y = self.acc_x, self.acc_y
        self.acc_x = self.acc_y = 0
        return x, y

    def take_flags(self) -> tuple[bool, bool, bool, bool]:
        """(moved, lift seen, overflow x, overflow y) since the last take, then cleared."""
        out = (
            self._moved or bool(self.acc_x or self.acc_y),
            self._lift_flag,
            self._ovf_x,
            self._ovf_y,
        )
        self._moved = False
        self._lift_flag = self._lifted
        self._ovf_x = self._ovf_y = False
        return out

    @property
    def lifted(self) -> bool:
        return self._lifted

    # --- time -----------------------------------------------------------------------------

    def advance(self, now: float | None = None) -> None:
        """Count the motion up to ``now`` (default: the clock)."""
        if now is None:
            now = self.clock()
        t0 = self._t
        if now <= t0:
            return
        self._t = now
        dxm, dym = self.motion.displacement(t0, now)
        if self._lifts and self._lifts.overlaps(t0, now):
            if not self._lifted:
                self._start_lift()
            self.stats.lift_motion_x += dxm * self.cpi_x / INCH_M
            self.stats.lift_motion_y += dym * self.cpi_y / INCH_M
            # A window that ends inside this interval leaves the sensor down again:
            # the lift is reported by the next read, not by every read after.
            self._lifted = self._lifts.covers_end(now)
            return
        self._lifted = False
        if self._poor and self._poor.overlaps(t0, now):
            if not self.poor_surface:
                self.stats.low_quality_events += 1
            self.stats.lift_motion_x += dxm * self.cpi_x / INCH_M
            self.stats.lift_motion_y += dym * self.cpi_y / INCH_M
            self.poor_surface = self._poor.covers_end(now)
            return
        self.poor_surface = False
        if not self.counting:
            return
        self._count(dxm, dym, now - t0)

    def _count(self, dxm: float, dym: float, dt: float) -> None:
        s = self.stats
        fx = self._frac_x + dxm * self.cpi_x / INCH_M
        fy = self._frac_y + dym * self.cpi_y / INCH_M
        if self.noise_counts:
            sigma = self.noise_counts * math.sqrt(dt)
            fx += self._rng.gauss(0.0, sigma)
            fy += self._rng.gauss(0.0, sigma)
        nx = math.floor(fx)
        ny = math.floor(fy)
        self._frac_x = fx - nx
        self._frac_y = fy - ny
        if nx or ny:
            self._moved = True
            s.counted_x += nx
            s.counted_y += ny
            self.acc_x, ox = wrap(self.acc_x + nx, self.counter_bits)
            self.acc_y, oy = wrap(self.acc_y + ny, self.counter_bits)
            if ox or oy:
                self._ovf_x |= ox
                self._ovf_y |= oy
                s.overflow_events += 1

    def _start_lift(self) -> None:
        s = self.stats
        self._lifted = True
        self._lift_flag = True
        s.lift_events += 1
        lx, ly = self.clear_latches()
        s.lift_cleared_x += self.acc_x + lx
        s.lift_cleared_y += self.acc_y + ly
        self.acc_x = self.acc_y = 0

    # --- faults ---------------------------------------------------------------------------

    def fault_now(self, now: float) -> str | None:
        """The fault mode of a transfer at ``now`` (None: it works); counts it in stats."""
        self.stats.transfers += 1
        mode = self.fault or (self._fault_mode(now) if self.fault_windows else None)
        if mode is not None and mode != "corrupt":
            self.stats.faulted_transfers += 1
        return mode

    def spi_fault(self, now: float) -> str | None:
        """:meth:`fault_now` for an SPI transfer: a "raise" fault raises the kernel's SpiError;
        otherwise the mode ("no_response": the caller answers all ones; "corrupt"; None)."""
        mode = self.fault_now(now)
        if mode == "raise":
            raise SpiError("SPI transfer failed: Remote I/O error (emulated fault)")
        return mode

    def corrupt(self, out: list[int]) -> None:
        """Flip one random bit of ``out`` (a "corrupt" fault)."""
        self.stats.faulted_transfers += 1
        if out:
            j = self._rng.randrange(len(out))
            out[j] ^= 1 << self._rng.randrange(8)

    def _fault_mode(self, now: float) -> str | None:
        for start, end, mode in self.fault_windows:
            if start <= now < end:
                self._in_fault_window = True
                self._fault_end = end
                return mode
        if self._in_fault_window:
            self._in_fault_window = False
            if self.reset_after_fault:
                self.power_cycle()  # the chip lost power: registers, RAM, counters gone
                # and it counted nothing before power came back at the window's end
                self._t = max(self._t, self._fault_end)
        return None
