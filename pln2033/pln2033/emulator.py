"""A register-level PLN2033 emulator behind spidev's ``xfer2`` bytes.

It implements the frame format and register semantics of a
:class:`~pln2033.pln2033.regmap.RegisterMap` (the same data the driver reads), so the
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

import time
from collections.abc import Callable, Sequence

from ..emulated import FAULT_MODES, CountingCore, EmulatorStats
from ..motion import MotionSource
from .regmap import RegisterMap

__all__ = ["FAULT_MODES", "EmulatedPLN2033", "EmulatorStats"]


class EmulatedPLN2033(CountingCore):
    """One emulated PLN2033; use it wherever a :class:`~pln2033.bus.SpiBus` goes.

    Args as :class:`~pln2033.emulated.CountingCore`, plus ``regmap`` (default:
    the package's default map).
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
        low_quality_windows: Sequence[tuple[float, float]] = (),
    ) -> None:
        self.map = regmap or RegisterMap.default()
        self.latch_x = self.latch_y = 0
        super().__init__(
            motion=motion,
            clock=clock,
            lift_windows=lift_windows,
            noise_counts=noise_counts,
            fault_windows=fault_windows,
            reset_after_fault=reset_after_fault,
            seed=seed,
            record=record,
            low_quality_windows=low_quality_windows,
            cpi=self.map.cpi_default,
        )
        a = self.map.addresses
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
            a["power_control"]: self._write_power_control,
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
        self.reset_counts()
        self.latch_x = self.latch_y = 0
        self.counting = True
        self.ram = [0] * m.memory_words
        self._mem_ptr = 0
        self.stats.resets += 1

    def power_cycle(self) -> None:
        self._power_on()

    def clear_latches(self) -> tuple[int, int]:
        x, y = self.latch_x, self.latch_y
        self.latch_x = self.latch_y = 0
        return x, y

    @property
    def powered(self) -> bool:
        return not self.regs[self.map.addresses["power_control"]] & self.map.power_down_bit

    @property
    def patch_enabled(self) -> bool:
        return bool(self.regs[self.map.addresses["system_control"]] & self.map.patch_enable_bit)

    # --- SPI ------------------------------------------------------------------------------

    def xfer2(self, data: list[int]) -> list[int]:
        now = self.clock()
        mode = self.spi_fault(now)
        if mode == "no_response":
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
            self.corrupt(out)
        if self.record:
            self.stats.history.append((tuple(data), tuple(out)))
        return out

    def close(self) -> None:
        pass

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
        moved, lift, ovf_x, ovf_y = self.take_flags()
        value = 0
        if moved:
            value |= m.status_motion
        if lift:
            value |= m.status_lift
        if ovf_x:
            value |= m.status_overflow_x
        if ovf_y:
            value |= m.status_overflow_y
        s.overwritten_x += self.latch_x
        s.overwritten_y += self.latch_y
        self.latch_x, self.latch_y = self.take_counts()
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
                self.set_cpi_x(cpi)
            else:
                self.set_cpi_y(cpi)
        elif opcode == c["get_x_cpi"]:
            self.regs[a["command_low"]] = m.encode_cpi(round(self.cpi_x))  # whole CPI here
        elif opcode == c["get_y_cpi"]:
            self.regs[a["command_low"]] = m.encode_cpi(round(self.cpi_y))

    def _write_pointer(self, value: int) -> None:
        self._mem_ptr = value % self.map.memory_words

    def _write_memory(self, value: int) -> None:
        self.ram[self._mem_ptr] = value
        self._mem_ptr = (self._mem_ptr + 1) % self.map.memory_words

    def _read_memory(self) -> int:
        value = self.ram[self._mem_ptr]
        self._mem_ptr = (self._mem_ptr + 1) % self.map.memory_words
        return value

    def _write_power_control(self, value: int) -> None:
        self.regs[self.map.addresses["power_control"]] = value
        self.counting = not value & self.map.power_down_bit

    def _write_system_control(self, value: int) -> None:
        if value & self.map.soft_reset_bit:
            self._power_on()
            return
        self.regs[self.map.addresses["system_control"]] = value
