"""A register-level PLN2033 emulator behind spidev's ``xfer2`` bytes.

It implements the frame format and register semantics of a
:class:`~pln2033.regmap.RegisterMap` (the same data the driver reads), so the
real driver code runs unchanged against it. A motion source gives the true
sensor-frame displacement over time; the emulator turns it into counts at the
current CPI (keeping the fraction, so counts follow the true position within
one count), wraps its 16-bit counters, clears them on lifts, and injects SPI
faults on demand.

Counter model (an assumption, see docs/pln2033.md): a status read latches the
counters into the delta registers and clears the counters; a delta read
returns the latch and clears it. A second status read before the deltas are
read overwrites the latch, and those counts are gone -- as on the original
robot, whose settings read ate the counters.
"""

from __future__ import annotations

import math
import random
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

from .driver import INCH_M
from .errors import SpiError
from .motion import MotionSource, Stationary
from .regmap import RegisterMap

FAULT_MODES = ("raise", "no_response", "corrupt")


@dataclass
class EmulatorStats:
    """Ground truth kept by the emulator, for tests and benchmarks (counts)."""

    counted_x: int = 0  # counts that entered the X counter
    counted_y: int = 0
    lift_cleared_x: int = 0  # counts the lift cleared before anyone read them
    lift_cleared_y: int = 0
    lift_motion_x: float = 0.0  # counts the motion during lifts would have made
    lift_motion_y: float = 0.0
    overwritten_x: int = 0  # latched counts lost to a second status read
    overwritten_y: int = 0
    overflow_events: int = 0
    lift_events: int = 0  # lifts started
    transfers: int = 0
    faulted_transfers: int = 0
    protocol_errors: int = 0  # transfers whose length was not a whole frame
    resets: int = 0
    history: list[tuple[int, ...]] = field(default_factory=list)


def _wrap16(value: int) -> tuple[int, bool]:
    if -0x8000 <= value <= 0x7FFF:
        return value, False
    return ((value + 0x8000) & 0xFFFF) - 0x8000, True


class EmulatedPLN2033:
    """One emulated PLN2033; use it wherever a :class:`~pln2033.bus.SpiBus` goes.

    Args:
        motion: true sensor-frame displacement over time (metres).
        regmap: register map (default: the package's default map).
        clock: seconds, monotonic; inject a fake clock for deterministic tests.
        lift_windows: (start, end) times during which the sensor is lifted.
        noise_counts: standard deviation of count noise per sqrt(second) of time.
        fault_windows: (start, end, mode) times during which transfers fail;
            mode is one of FAULT_MODES. Leaving a window power-cycles the chip
            when ``reset_after_fault`` is true.
        record: keep every transfer's (tx, rx) bytes in ``stats.history``.
    """

    def __init__(
        self,
        motion: MotionSource | None = None,
        regmap: RegisterMap | None = None,
        clock: Callable[[], float] = time.monotonic,
        lift_windows: Sequence[tuple[float, float]] = (),
        noise_counts: float = 0.0,
        fault_windows: Sequence[tuple[float, float, str]] = (),
        reset_after_fault: bool = True,
        seed: int = 0,
        record: bool = False,
    ) -> None:
        self.map = regmap or RegisterMap.default()
        self.motion: MotionSource = motion or Stationary()
        self.clock = clock
        self.lift_windows = sorted(lift_windows)
        self.noise_counts = noise_counts
        for w in fault_windows:
            if w[2] not in FAULT_MODES:
                raise ValueError(f"fault mode {w[2]!r} unknown; allowed: {FAULT_MODES}")
        self.fault_windows = sorted(fault_windows)
        self.reset_after_fault = reset_after_fault
        self.fault: str | None = None  # fault on demand, for tests
        self.record = record
        self.stats = EmulatorStats()
        self._rng = random.Random(seed)
        self._t = clock()
        self._in_fault_window = False
        self._fault_end = 0.0
        self._lifted = False
        self._lift_idx = 0
        a = self.map.addresses
        self._power_addr = a["power_control"]
        self._readers = {
            a["status"]: self._read_status,
            a["delta_x_disp"]: self._read_dx,
            a["delta_y_disp"]: self._read_dy,
            a["memory_data"]: self._read_memory,
            a["memory_pointer"]: lambda: self._mem_ptr,
        }
        self._writers = {
            a["command_high"]: self._write_command,
            a["memory_pointer"]: self._write_pointer,
            a["memory_data"]: self._write_memory,
            a["system_control"]: self._write_system_control,
            a["status"]: lambda v: None,  # read-only
            a["delta_x_disp"]: lambda v: None,
            a["delta_y_disp"]: lambda v: None,
        }
        self._power_on()
        self.stats.resets = 0

    # --- chip state -------------------------------------------------------------------

    def _power_on(self) -> None:
        m = self.map
        self.regs = {addr: 0 for addr in m.addresses.values()}
        self.regs[m.addresses["mode_status"]] = 0x0001  # "tracking"
        self.cpi_x = self.cpi_y = m.cpi_default
        self.acc_x = self.acc_y = 0
        self.latch_x = self.latch_y = 0
        self._frac_x = self._frac_y = 0.0
        self._moved = False
        self._lift_flag = self._lifted
        self._ovf_x = self._ovf_y = False
        self.ram = [0] * m.memory_words
        self._mem_ptr = 0
        self.stats.resets += 1

    @property
    def powered(self) -> bool:
        return not self.regs[self.map.addresses["power_control"]] & self.map.power_down_bit

    @property
    def patch_enabled(self) -> bool:
        return bool(self.regs[self.map.addresses["system_control"]] & self.map.patch_enable_bit)

    # --- time -----------------------------------------------------------------------------

    def _lifted_between(self, t0: float, t1: float) -> bool:
        # Time only moves forward, so windows that ended are skipped for good.
        windows = self.lift_windows
        i = self._lift_idx
        while i < len(windows) and windows[i][1] <= t0:
            i += 1
        self._lift_idx = i
        return i < len(windows) and windows[i][0] < t1

    def advance(self, now: float | None = None) -> None:
        """Count the motion up to ``now`` (default: the clock)."""
        if now is None:
            now = self.clock()
        t0 = self._t
        if now <= t0:
            return
        self._t = now
        dxm, dym = self.motion.displacement(t0, now)
        if self.lift_windows and self._lifted_between(t0, now):
            if not self._lifted:
                self._start_lift()
            self.stats.lift_motion_x += dxm * self.cpi_x / INCH_M
            self.stats.lift_motion_y += dym * self.cpi_y / INCH_M
            # A window that ends inside this interval leaves the sensor down again:
            # the lift is reported by the next status read, not by every read after.
            self._lifted = now < self.lift_windows[self._lift_idx][1]
            return
        self._lifted = False
        if self.regs[self._power_addr] & self.map.power_down_bit:
            return
        s = self.stats
        fx = self._frac_x + dxm * self.cpi_x / INCH_M
        fy = self._frac_y + dym * self.cpi_y / INCH_M
        if self.noise_counts:
            sigma = self.noise_counts * math.sqrt(now - t0)
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
            self.acc_x, ox = _wrap16(self.acc_x + nx)
            self.acc_y, oy = _wrap16(self.acc_y + ny)
            if ox or oy:
                self._ovf_x |= ox
                self._ovf_y |= oy
                s.overflow_events += 1

    def _start_lift(self) -> None:
        s = self.stats
        self._lifted = True
        self._lift_flag = True
        s.lift_events += 1
        s.lift_cleared_x += self.acc_x + self.latch_x
        s.lift_cleared_y += self.acc_y + self.latch_y
        self.acc_x = self.acc_y = self.latch_x = self.latch_y = 0

    # --- SPI ------------------------------------------------------------------------------

    def xfer2(self, data: list[int]) -> list[int]:
        now = self.clock()
        self.stats.transfers += 1
        mode = self.fault or (self._fault_mode(now) if self.fault_windows else None)
        if mode == "raise":
            self.stats.faulted_transfers += 1
            raise SpiError("SPI transfer failed: Remote I/O error (emulated fault)")
        if mode == "no_response":
            self.stats.faulted_transfers += 1
            return [0xFF] * len(data)
        self.advance(now)
        out = [0] * len(data)
        whole = len(data) - len(data) % 3
        if whole != len(data):
            self.stats.protocol_errors += 1
        mask, wflag = self.map.address_mask, self.map.write_flag
        readers, regs = self._readers, self.regs
        for i in range(0, whole, 3):
            cmd = data[i]
            addr = cmd & mask
            if cmd & wflag:
                self._write(addr, (data[i + 1] << 8) | data[i + 2])
            else:
                reader = readers.get(addr)  # inlined _read: this loop runs 2000 times a second
                value = reader() if reader is not None else regs.get(addr, 0)
                out[i + 1] = value >> 8
                out[i + 2] = value & 0xFF
        if mode == "corrupt":
            self.stats.faulted_transfers += 1
            j = self._rng.randrange(len(out)) if out else 0
            if out:
                out[j] ^= 1 << self._rng.randrange(8)
        if self.record:
            self.stats.history.append((tuple(data), tuple(out)))
        return out

    def close(self) -> None:
        pass

    def _fault_mode(self, now: float) -> str | None:
        for start, end, mode in self.fault_windows:
            if start <= now < end:
                self._in_fault_window = True
                self._fault_end = end
                return mode
        if self._in_fault_window:
            self._in_fault_window = False
            if self.reset_after_fault:
                self._power_on()  # the chip lost power: registers, RAM, counters gone
                # and it counted nothing before power came back at the window's end
                self._t = max(self._t, self._fault_end)
        return None

    def _read(self, addr: int) -> int:
        reader = self._readers.get(addr)
        if reader is not None:
            return reader()
        return self.regs.get(addr, 0)

    def _write(self, addr: int, value: int) -> None:
        writer = self._writers.get(addr)
        if writer is not None:
            writer(value)
        elif addr in self.regs:
            self.regs[addr] = value

    # --- register semantics -----------------------------------------------------------------

    def _read_status(self) -> int:
        m = self.map
        s = self.stats
        value = 0
        if self._moved or self.acc_x or self.acc_y:
            value |= m.status_motion
        if self._lift_flag:
            value |= m.status_lift
        if self._ovf_x:
            value |= m.status_overflow_x
        if self._ovf_y:
            value |= m.status_overflow_y
        s.overwritten_x += self.latch_x
        s.overwritten_y += self.latch_y
        self.latch_x, self.latch_y = self.acc_x, self.acc_y
        self.acc_x = self.acc_y = 0
        self._moved = False
        self._lift_flag = self._lifted
        self._ovf_x = self._ovf_y = False
        return value

    def _read_dx(self) -> int:
        value, self.latch_x = self.latch_x, 0
        return value & 0xFFFF

    def _read_dy(self) -> int:
        value, self.latch_y = self.latch_y, 0
        return value & 0xFFFF

    def _write_command(self, opcode: int) -> None:
        m = self.map
        a = m.addresses
        arg = self.regs[a["command_low"]]
        self.regs[a["command_high"]] = opcode
        c = m.commands
        if opcode in (c["set_x_cpi"], c["set_y_cpi"]):
            cpi = m.decode_cpi(arg)
            if m.cpi_problem(cpi) is not None:
                return  # the chip ignores codes it does not support
            if opcode == c["set_x_cpi"]:
                self._frac_x *= cpi / self.cpi_x
                self.cpi_x = cpi
            else:
                self._frac_y *= cpi / self.cpi_y
                self.cpi_y = cpi
        elif opcode == c["get_x_cpi"]:
            self.regs[a["command_low"]] = m.encode_cpi(self.cpi_x)
        elif opcode == c["get_y_cpi"]:
            self.regs[a["command_low"]] = m.encode_cpi(self.cpi_y)

    def _write_pointer(self, value: int) -> None:
        self._mem_ptr = value % self.map.memory_words

    def _write_memory(self, value: int) -> None:
        self.ram[self._mem_ptr] = value
        self._mem_ptr = (self._mem_ptr + 1) % self.map.memory_words

    def _read_memory(self) -> int:
        value = self.ram[self._mem_ptr]
        self._mem_ptr = (self._mem_ptr + 1) % self.map.memory_words
        return value

    def _write_system_control(self, value: int) -> None:
        if value & self.map.soft_reset_bit:
            self._power_on()
            return
        self.regs[self.map.addresses["system_control"]] = value
