"""Register-level PMW3360 / PMW3389 emulators behind ``xfer_segments`` (and ``xfer2``).

Built on the shared :class:`~pln2033.emulated.CountingCore` (motion -> 16-bit counts, lifts,
poor-surface windows, noise, faults), they speak the chip's bytes. One call is one frame
(chip select low); each segment's delay follows its bytes, a leading empty segment waits
after chip select falls. Timing [DS3360 Table 4] is checked as constraints BETWEEN COMMANDS
(:mod:`~pln2033.pmw33xx.timing`), from the end of one command to the start of the next,
whether chip select rose between them or not: the emulator lays every byte on the chip's
timeline (``sclk_hz`` per bit, ``cs_setup_us`` after chip select falls, the delays, and
between two calls the host clock's time with chip select high, at least ``min_cs_high_us``).

Each violated constraint counts one ``stats.protocol_errors`` (and one in
``timing_errors[name]``). Its effect: a read (or burst) that comes too soon, or whose
tSRAD is short, returns garbage; a write is still applied (the datasheet says it "may not
complete", but the Arduino sketches' 120 us writes are reported to work), except while the
chip ignores the bus (the 50 ms after a reset, the 10 ms CRC test), where it is lost; an
SROM byte sent sooner than 15 us after the previous one is stored garbled.

Counter semantics [DS3360 Motion, sec. 4]: reading Motion (or a burst) freezes the counters
into the delta registers and clears them (a second freeze before the deltas are read loses
them: ``stats.overwritten_x/y``); reading Delta_X_H / Delta_Y_H clears the frozen value.

SROM model (the emulators' own, not PixArt's): SROM_Load_Burst takes ``srom_length`` bytes
(the chip knows its image's length: bytes after it in the same frame are commands again, so
reading SROM_ID before chip select rises works, as users report of the Arduino sketch). An
image is *intact* when it has ``srom_length`` bytes, none garbled, and (when a reference
``srom`` is given) equals it; then SROM_ID reads ``srom_id`` (0x04, the version QMK and the
nRF drivers expect of PixArt's current SROM) and the CRC self test answers 0xBEEF, the pass
value the PMW3360 datasheet lists. Otherwise SROM_ID reads the low byte of the image's
CRC-16/CCITT (or 0x00 when the length is wrong: the SROM never starts) and the self test
answers that CRC. A real chip's CRC answer for its blob is the one its datasheet lists.

SQUAL [DS3360 SQUAL, Min_SQ_Run]: ``surface_squal`` (+-8) on a surface, 0..3 while lifted,
4..10 over a poor surface (below Min_SQ_Run 0x10, where the chip reports zero motion).
"""

from __future__ import annotations

import random
from collections import Counter
from collections.abc import Sequence
from typing import Any

from ..emulated import CountingCore
from ..motion import MotionSource
from . import regs as R  # noqa: N812 (the register facts, short)
from . import timing as T  # noqa: N812 (the timing constraints, short)

__all__ = ["EmulatedPMW33xx", "EmulatedPMW3360", "EmulatedPMW3389"]


class EmulatedPMW33xx(CountingCore):
    """One emulated PMW33xx; use it wherever a :class:`~pln2033.bus.SegmentedSpiBus` goes.

    Args as :class:`~pln2033.emulated.CountingCore`, plus ``srom`` (the reference image an
    upload must equal; None: any intact image), ``srom_id``, ``srom_length``,
    ``surface_squal``, ``require_srom`` (count only while an SROM runs; default False, so
    the sim works without PixArt's blob) and ``product_id`` (what Product_ID answers).

    The bus as the chip sees it: ``sclk_hz`` (bit rate; default the 2 MHz maximum, the
    shortest bytes), ``cs_setup_us`` (chip select falling -> first SCLK that the host's
    controller gives by itself; assumed half a clock period) and ``min_cs_high_us`` (chip
    select high between two calls at least this long even when the clock did not move, as a
    test's fake clock does; a real ioctl round trip is longer than 1 us).
    """

    regs: R.ChipRegs

    def __init__(
        self,
        motion: MotionSource | None = None,
        *,
        srom: Sequence[int] | None = None,
        srom_id: int = 0x04,
        srom_length: int = R.SROM_LENGTH,
        surface_squal: int = 0x40,
        require_srom: bool = False,
        product_id: int | None = None,
        sclk_hz: float = R.MAX_SPI_HZ,
        cs_setup_us: float | None = None,
        min_cs_high_us: float = 1.0,
        **core: Any,
    ) -> None:
        self.srom_reference = None if srom is None else bytes(srom)
        self.srom_id_intact = srom_id
        self.srom_length = srom_length
        self.surface_squal = surface_squal
        self.require_srom = require_srom
        self.product_id = self.regs.product_id if product_id is None else product_id
        self._addr_names = {v: k for k, v in self.regs.addresses.items()}
        self.latch_x = self.latch_y = 0
        self.srom_image: bytes | None = None
        self.srom_intact = False
        self._squal_rng = random.Random(core.get("seed", 0) + 1)
        self.byte_us = 8e6 / sclk_hz
        self.cs_setup_us = 0.5e6 / sclk_hz if cs_setup_us is None else cs_setup_us
        self.min_cs_high_us = min_cs_high_us
        self.timing_errors: Counter[str] = Counter()
        self._prev: T.Command | None = None  # the last command, on the chip's timeline (us)
        self._cs_rise_us: float | None = None  # when chip select last rose (chip time, us)
        self._host_at_rise = 0.0  # the host clock (s) of that frame
        super().__init__(
            motion=motion,
            **core,
            cpi=self._decode_cpi(self.regs.cpi.registers),
        )
        self._power_on(None)
        self.stats.resets = 0

    # --- chip state -----------------------------------------------------------------------

    def _decode_cpi(self, names: Sequence[str], regs: dict[str, int] | None = None) -> int:
        src = regs if regs is not None else self.regs.defaults
        v = 0
        for n in names:
            v = (v << 8) | src.get(n, 0)
        return self.regs.cpi.decode(v)

    def _defaults(self) -> None:
        """Registers to their defaults (power up, reset, after the CRC test); SROM kept."""
        self.r = {n: 0 for n in self.regs.addresses}
        self.r.update(self.regs.defaults)
        self.r["Product_ID"] = self.product_id
        self.r["Inverse_Product_ID"] = self.product_id ^ 0xFF
        self.reset_counts()
        self.latch_x = self.latch_y = 0
        self.burst_armed = False
        self._srom_state: str | None = None
        self._srom_t = 0.0  # us, chip time
        self._crc_t: float | None = None  # us, chip time

    def _power_on(self, at_us: float | None) -> None:
        """Power comes back (or a reset) at chip time ``at_us``: the chip answers 50 ms later,
        as after a Power_Up_Reset (None: no wait here, the emulator's first power-up is long
        past, or the Power_Up_Reset command itself carries the wait)."""
        self.srom_image = None
        self.srom_intact = False
        self._defaults()
        if at_us is not None:
            wait, name = T.wait_after("Power_Up_Reset", R.POWER_UP_RESET_VALUE)
            self._prev = T.Command("write", at_us, at_us, at_us, at_us, wait, name)
        self._update_counting()
        self.stats.resets += 1

    def _chip_time_us(self, host_now: float) -> float:
        """Chip time (us) at host time ``host_now``, chip select high since the last frame."""
        if self._cs_rise_us is None:
            return host_now * 1e6
        return self._cs_rise_us + max(0.0, host_now - self._host_at_rise) * 1e6

    def power_cycle(self) -> None:
        self._power_on(self._chip_time_us(self.clock()))

    def clear_latches(self) -> tuple[int, int]:
        x, y = self.latch_x, self.latch_y
        self.latch_x = self.latch_y = 0
        return x, y

    def _update_counting(self) -> None:
        self.counting = self.srom_running or not self.require_srom

    @property
    def srom_running(self) -> bool:
        return self.srom_image is not None and len(self.srom_image) == self.srom_length

    @property
    def srom_id(self) -> int:
        image = self.srom_image
        if image is None or not self.srom_running:
            return 0
        if self.srom_intact:
            return self.srom_id_intact
        return R.crc16_ccitt(image) & 0xFF or 0x01

    def srom_crc(self) -> int:
        """What the CRC self test answers for the image in the chip."""
        if self.srom_running and self.srom_intact:
            return R.SROM_CRC_PASS
        crc = R.crc16_ccitt(self.srom_image or b"")
        return crc ^ 1 if crc == R.SROM_CRC_PASS else crc

    # --- register semantics ---------------------------------------------------------------

    def _freeze(self) -> int:
        """A Motion read or a burst: the counters into the delta registers; the Motion byte."""
        s = self.stats
        moved, lift_seen, _ox, _oy = self.take_flags()
        s.overwritten_x += self.latch_x
        s.overwritten_y += self.latch_y
        self.latch_x, self.latch_y = self.take_counts()
        value = R.MOTION_RESET
        if moved or self.latch_x or self.latch_y:
            value |= R.MOT
        if lift_seen or self.lifted:
            value |= R.LIFT_STAT
        self._frame_squal = self._squal()
        return value

    def _squal(self) -> int:
        g = self._squal_rng
        if self.lifted:
            return g.randint(0, 3)
        if self.poor_surface:
            return g.randint(4, 10)
        return max(0, min(R.SQUAL_MAX, self.surface_squal + g.randint(-8, 8)))

    def _surface(self) -> dict[str, int]:
        """The frame statistics a burst and the registers report."""
        dark = self.lifted
        shutter = 0x4000 if dark else 0x0012 + self._squal_rng.randint(0, 3)
        return {
            "Raw_Data_Sum": 0x05 if dark else 0x30,
            "Maximum_Raw_Data": 0x10 if dark else 0x60,
            "Minimum_Raw_Data": 0x00 if dark else 0x10,
            "Shutter_Upper": shutter >> 8,
            "Shutter_Lower": shutter & 0xFF,
        }

    def _observation(self) -> int:
        return 0x3F | (R.OB_SROM_RUN if self.srom_running else 0)

    def _burst(self) -> list[int]:
        motion = self._freeze()
        x, y = self.latch_x & 0xFFFF, self.latch_y & 0xFFFF
        self.latch_x = self.latch_y = 0
        s = self._surface()
        return [
            motion,
            self._observation(),
            x & 0xFF,
            x >> 8,
            y & 0xFF,
            y >> 8,
            self._frame_squal,
            s["Raw_Data_Sum"],
            s["Maximum_Raw_Data"],
            s["Minimum_Raw_Data"],
            s["Shutter_Upper"],
            s["Shutter_Lower"],
        ]

    def _read(self, name: str | None, now: float) -> int:
        """Register ``name``'s value, read at chip time ``now`` (us)."""
        if name is None:
            return 0
        self.burst_armed = False  # a non-burst read [DS3360 sec. 4 step 7]
        if name == "Motion":
            return self._freeze()
        if name == "Delta_X_L":
            return self.latch_x & 0xFF
        if name == "Delta_X_H":
            v, self.latch_x = (self.latch_x & 0xFFFF) >> 8, 0
            return v
        if name == "Delta_Y_L":
            return self.latch_y & 0xFF
        if name == "Delta_Y_H":
            v, self.latch_y = (self.latch_y & 0xFFFF) >> 8, 0
            return v
        if name == "SQUAL":
            return getattr(self, "_frame_squal", 0)
        if name == "SROM_ID":
            return self.srom_id
        if name == "Observation":
            return self._observation()
        if name in ("Data_Out_Upper", "Data_Out_Lower"):
            if self._crc_t is None or now - self._crc_t < R.T_CRC_S * 1e6:
                return 0  # no result yet
            crc = self.srom_crc()
            return crc >> 8 if name == "Data_Out_Upper" else crc & 0xFF
        if name in ("Raw_Data_Sum", "Maximum_Raw_Data", "Minimum_Raw_Data"):
            return self._surface()[name]
        if name in ("Shutter_Upper", "Shutter_Lower"):
            return self._surface()[name]
        return self.r.get(name, 0)

    def _write(self, name: str | None, value: int, now: float, end: float | None = None) -> None:
        """Register ``name`` <- ``value``: the command starts at chip time ``now`` and ends at
        ``end`` (us; the waits it starts run from its end)."""
        end = now if end is None else end
        if name is None or name in ("Product_ID", "Inverse_Product_ID", "SROM_ID", "Revision_ID"):
            return
        if name == "Power_Up_Reset":
            if value == R.POWER_UP_RESET_VALUE:
                self._power_on(None)
            return
        if name == "Motion_Burst":
            self.burst_armed = True
            return
        if name == "SROM_Enable":
            if value == R.SROM_INIT:
                self._srom_state, self._srom_t = "init", end
            elif value == R.SROM_START:
                ok = self._srom_state == "init" and now - self._srom_t >= R.T_SROM_INIT_S * 1e6
                self._srom_state = "armed" if ok else None  # (too soon: counted as a gap)
            elif value == R.SROM_CRC:
                keep_image, keep_intact = self.srom_image, self.srom_intact
                self._defaults()  # the self test resets the registers [DS3360 SROM_Enable]
                self.srom_image, self.srom_intact = keep_image, keep_intact
                self._crc_t = end
            return
        self.r[name] = value
        enc = self.regs.cpi
        if name in enc.registers or name in enc.x_registers or name == "Config2":
            self._apply_cpi()

    def _apply_cpi(self) -> None:
        enc = self.regs.cpi

        def value(names: Sequence[str]) -> int:
            v = 0
            for n in names:
                v = (v << 8) | self.r.get(n, 0)
            return v

        vy = value(enc.registers)
        vx = value(enc.x_registers) if self.r.get("Config2", 0) & R.CONFIG2_RPT_MOD else vy
        if enc.valid(vy) and enc.decode(vy) != self.cpi_y:
            self.set_cpi_y(enc.decode(vy))
        if enc.valid(vx) and enc.decode(vx) != self.cpi_x:
            self.set_cpi_x(enc.decode(vx))

    def _upload(self, data: list[int], garbled: list[bool]) -> None:
        """SROM_Load_Burst's bytes; ``garbled[k]``: byte k came sooner than 15 us after the
        one before it (latched mid-byte)."""
        if self._srom_state != "armed":
            return  # no download started: the bytes go nowhere (the SROM does not run)
        image = bytearray()
        for b, bad in zip(data, garbled, strict=True):
            image.append(b ^ (1 << self._rng.randrange(8)) if bad else b)
        self._srom_state = None
        self.srom_image = bytes(image)
        self.srom_intact = (
            not any(garbled)
            and len(image) == self.srom_length
            and (self.srom_reference is None or self.srom_reference == bytes(image))
        )
        self._update_counting()

    # --- SPI ------------------------------------------------------------------------------

    def xfer2(self, data: list[int]) -> list[int]:
        """One frame without delays (reads in it return garbage)."""
        return self.xfer_segments([(list(data), 0)])[0]

    def xfer_segments(self, segments: Sequence[tuple[list[int], float]]) -> list[list[int]]:
        now = self.clock()
        mode = self.spi_fault(now)
        if mode == "no_response":
            return [[0xFF] * len(seg) for seg, _d in segments]
        self.advance(now)
        out = self._frame(segments, now)
        if mode == "corrupt":
            self.corrupt(out)
        result, k = [], 0
        for seg, _d in segments:
            result.append(out[k : k + len(seg)])
            k += len(seg)
        if self.record:
            self.stats.history.append((tuple(tuple(s) for s, _ in segments), tuple(out)))
        return result

    def _garbage(self, out: list[int], start: int, stop: int | None = None) -> None:
        for k in range(start, len(out) if stop is None else stop):
            out[k] = self._rng.randrange(256)

    def _violation(self, name: str) -> None:
        self.timing_errors[name] += 1
        self.stats.protocol_errors += 1

    def _layout(
        self, segments: Sequence[tuple[list[int], float]], host_now: float
    ) -> tuple[list[int], list[float], float | None, float, float]:
        """The frame's bytes, each byte's start (us, chip time; it ends byte_us later), how
        long chip select was high before it (None: first frame), when it fell and rose."""
        if self._cs_rise_us is None:
            cs_high, fall = None, host_now * 1e6
        else:
            cs_high = max((host_now - self._host_at_rise) * 1e6, self.min_cs_high_us)
            fall = self._cs_rise_us + cs_high
        t = fall + self.cs_setup_us
        data: list[int] = []
        starts: list[float] = []
        for seg, delay in segments:
            for b in seg:
                data.append(int(b))
                starts.append(t)
                t += self.byte_us
            t += float(delay)
        return data, starts, cs_high, fall, t

    def _frame(self, segments: Sequence[tuple[list[int], float]], host_now: float) -> list[int]:
        data, s, cs_high, fall, rise = self._layout(segments, host_now)
        n, bu = len(data), self.byte_us
        out = [0] * n
        names = self._addr_names
        first_gap = cs_high  # chip select rose before the frame's first command only
        prev_frame = self._prev
        if n and T.short(s[0] - fall, R.T_NCS_SCLK_US):
            early: str | None = T.TNCS_SCLK
        else:
            early = None
        i = 0
        while i < n:
            cmd = data[i]
            name = names.get(cmd & R.ADDRESS_MASK)
            write = bool(cmd & R.WRITE_FLAG)
            if write and name == "SROM_Load_Burst":
                stop = min(n, i + 1 + self.srom_length)
                last = max(stop - 1, i)
                c = T.Command(
                    "srom_burst", s[i], s[i] + bu, s[min(i + 1, last)] + bu, s[last] + bu,
                    R.T_SROM_END_US, T.SROM_END_WAIT,
                )  # fmt: skip
                self._check_gap(c, first_gap, early)
                garbled = [
                    T.short(s[k] - s[k - 1] - bu, R.T_SROM_BYTE_US) for k in range(i + 1, stop)
                ]
                for _ in range(sum(garbled)):
                    self._violation(T.SROM_BYTE)
                self._upload(data[i + 1 : stop], garbled)
                i = stop
            elif write:
                if i + 1 >= n:
                    self._violation("write without its data byte")
                    break
                wait, wait_name = T.wait_after(name, data[i + 1])
                c = T.Command(
                    "write", s[i], s[i] + bu, s[i + 1] + bu, s[i + 1] + bu, wait, wait_name
                )
                broken = self._check_gap(c, first_gap, early)
                if broken not in T.BUS_IGNORED:
                    self._write(name, data[i + 1], c.start, c.end)
                i += 2
            elif name == "Motion_Burst":
                last = min(n - 1, i + R.BURST_LENGTH)
                c = T.Command(
                    "motion_burst", s[i], s[i] + bu, s[min(i + 1, last)] + bu, s[last] + bu
                )
                bad = self._check_gap(c, first_gap, early) is not None
                if i + 1 < n and T.short(s[i + 1] - c.addr_end, R.T_SRAD_MOTBR_US):
                    self._violation(T.TSRAD_MOTBR)
                    bad = True
                if not self.burst_armed:
                    self._violation("motion burst not armed")
                    bad = True
                if bad:
                    self._garbage(out, i + 1)  # the counters stay for the next burst
                else:
                    report = self._burst()
                    for k in range(i + 1, last + 1):
                        out[k] = report[k - i - 1]
                i = n  # the burst holds the port until chip select rises [DS3360 sec. 4]
            else:
                if i + 1 >= n:
                    break  # an address alone: nothing happens
                c = T.Command("read", s[i], s[i] + bu, s[i + 1] + bu, s[i + 1] + bu)
                bad = self._check_gap(c, first_gap, early) is not None
                if T.short(s[i + 1] - c.addr_end, R.T_SRAD_US):
                    self._violation(T.TSRAD)
                    bad = True
                out[i + 1] = self._rng.randrange(256) if bad else self._read(name, c.start)
                i += 2
            first_gap, early = None, None
        last_cmd = self._prev if self._prev is not prev_frame else None
        if (
            last_cmd
            and last_cmd.kind == "write"
            and T.short(rise - last_cmd.end, R.T_SCLK_NCS_WRITE_US)
        ):
            self._violation(T.TSCLK_NCS_WRITE)  # chip select rose too soon after a write
        if n:
            self._cs_rise_us, self._host_at_rise = rise, host_now
        return out

    def _check_gap(self, c: T.Command, cs_high: float | None, early: str | None) -> str | None:
        """Count what ``c`` breaks after the previous command (and a short tNCS-SCLK before
        it); ``c`` becomes the previous command. Returns the first constraint broken."""
        broken = T.gap_violation(self._prev, c, cs_high)
        self._prev = c
        for name in (early, broken):
            if name:
                self._violation(name)
        return broken or early

    def close(self) -> None:
        pass


class EmulatedPMW3360(EmulatedPMW33xx):
    """An emulated PixArt PMW3360 (product id 0x42, Config1 resolution)."""

    regs = R.PMW3360


class EmulatedPMW3389(EmulatedPMW33xx):
    """An emulated PixArt PMW3389 (product id 0x47, Resolution_H/L); ``resolution_offset``
    as the driver's (1: QMK's encoding, 0: teamspatzenhirn's)."""

    def __init__(self, *args, resolution_offset: int = 1, **kwargs) -> None:
        self.regs = R.pmw3389_regs(resolution_offset)
        super().__init__(*args, **kwargs)
