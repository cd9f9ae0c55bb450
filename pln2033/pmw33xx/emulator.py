"""Register-level PMW3360 / PMW3389 emulators behind ``xfer_segments`` (and ``xfer2``).

Built on the shared :class:`~pln2033.emulated.CountingCore` (motion -> 16-bit counts, lifts,
poor-surface windows, noise, faults), they speak the chip's bytes: one frame (chip select
low) holds address/data operations; the delay after each segment is checked against the
datasheet's timing [DS3360 AC table]:

- a read needs tSRAD (160 us) after its address byte, the motion burst tSRAD_MOTBR (35 us):
  shorter, and the data bytes are garbage;
- after a read's data byte tSRR/tSRW (20 us), after a write tSWW/tSWR (180 us) before the
  next command -- also at the end of a frame, since the driver keeps chip select low through
  that gap; shorter, and the rest of the frame is ignored;
- SROM_Load_Burst bytes need 15 us between them; a byte sent sooner is stored garbled;
- 50 ms after Power_Up_Reset, 10 ms between SROM_Enable 0x1D and 0x18, 10 ms between the
  CRC start (0x15) and reading Data_Out -- measured on the emulator's clock.

Every violation counts one ``stats.protocol_errors`` per frame. ``xfer2`` is a frame with no
delays at all (so every read in it is garbage): the driver must use ``xfer_segments``.

Counter semantics [DS3360 Motion, sec. 4]: reading Motion (or a burst) freezes the counters
into the delta registers and clears them (a second freeze before the deltas are read loses
them: ``stats.overwritten_x/y``); reading Delta_X_H / Delta_Y_H clears the frozen value.

SROM model (the emulators' own, not PixArt's): the emulator accepts any blob. An image is
*intact* when it has ``srom_length`` bytes, none garbled by the timing, and (when a reference
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
from collections.abc import Sequence
from typing import Any

from ..emulated import CountingCore
from ..motion import MotionSource
from . import regs as R  # noqa: N812 (the register facts, short)

__all__ = ["EmulatedPMW33xx", "EmulatedPMW3360", "EmulatedPMW3389"]


class EmulatedPMW33xx(CountingCore):
    """One emulated PMW33xx; use it wherever a :class:`~pln2033.bus.SegmentedSpiBus` goes.

    Args as :class:`~pln2033.emulated.CountingCore`, plus ``srom`` (the reference image an
    upload must equal; None: any intact image), ``srom_id``, ``srom_length``,
    ``surface_squal``, ``require_srom`` (count only while an SROM runs; default False, so
    the sim works without PixArt's blob) and ``product_id`` (what Product_ID answers).
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
        super().__init__(
            motion=motion,
            **core,
            cpi=self._decode_cpi(self.regs.cpi.registers),
        )
        self._power_on(now=self.clock(), ready=True)
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
        self._srom_t = 0.0
        self._crc_t: float | None = None

    def _power_on(self, now: float, ready: bool = False) -> None:
        self.srom_image = None
        self.srom_intact = False
        self._defaults()
        self._ready_at = now if ready else now + R.T_RESET_S
        self._update_counting()
        self.stats.resets += 1

    def power_cycle(self) -> None:
        self._power_on(self.clock())

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
            if self._crc_t is None or now - self._crc_t < R.T_CRC_S:
                return 0  # no result yet
            crc = self.srom_crc()
            return crc >> 8 if name == "Data_Out_Upper" else crc & 0xFF
        if name in ("Raw_Data_Sum", "Maximum_Raw_Data", "Minimum_Raw_Data"):
            return self._surface()[name]
        if name in ("Shutter_Upper", "Shutter_Lower"):
            return self._surface()[name]
        return self.r.get(name, 0)

    def _write(self, name: str | None, value: int, now: float) -> None:
        if name is None or name in ("Product_ID", "Inverse_Product_ID", "SROM_ID", "Revision_ID"):
            return
        if name == "Power_Up_Reset":
            if value == R.POWER_UP_RESET_VALUE:
                self._power_on(now)
            return
        if name == "Motion_Burst":
            self.burst_armed = True
            return
        if name == "SROM_Enable":
            if value == R.SROM_INIT:
                self._srom_state, self._srom_t = "init", now
            elif value == R.SROM_START:
                ok = self._srom_state == "init" and now - self._srom_t >= R.T_SROM_INIT_S
                self._srom_state = "armed" if ok else None
                if not ok:
                    self._bad = True
            elif value == R.SROM_CRC:
                keep_image, keep_intact = self.srom_image, self.srom_intact
                self._defaults()  # the self test resets the registers [DS3360 SROM_Enable]
                self.srom_image, self.srom_intact = keep_image, keep_intact
                self._crc_t = now
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

    def _upload(self, data: list[int], gaps: list[float], i: int) -> None:
        """SROM_Load_Burst: bytes data[i+1:], each after a gap >= 15 us."""
        if self._srom_state != "armed":
            self._bad = True  # no download started: the bytes go nowhere
            return
        image = bytearray()
        garbled = False
        for k in range(i + 1, len(data)):
            b = data[k]
            if gaps[k - 1] < R.T_SROM_BYTE_US:
                b ^= 1 << self._rng.randrange(8)  # latched mid-byte: garbled
                garbled = True
            image.append(b)
        if garbled:
            self._bad = True
        self._srom_state = None
        self.srom_image = bytes(image)
        self.srom_intact = (
            not garbled
            and len(image) == self.srom_length
            and (self.srom_reference is None or self.srom_reference == bytes(image))
        )
        self._update_counting()

    # --- SPI ------------------------------------------------------------------------------

    def xfer2(self, data: list[int]) -> list[int]:
        """One frame without delays (reads in it return garbage)."""
        return self.xfer_segments([(list(data), 0)])[0]

    def xfer_segments(self, segments: Sequence[tuple[list[int], int]]) -> list[list[int]]:
        now = self.clock()
        mode = self.spi_fault(now)
        if mode == "no_response":
            return [[0xFF] * len(seg) for seg, _d in segments]
        self.advance(now)
        data: list[int] = []
        gaps: list[float] = []
        for seg, delay in segments:
            if seg:
                data += list(seg)
                gaps += [0.0] * (len(seg) - 1) + [float(delay)]
            elif gaps:
                gaps[-1] += delay  # an empty segment only waits
        out = self._frame(data, gaps, now)
        if mode == "corrupt":
            self.corrupt(out)
        result, k = [], 0
        for seg, _d in segments:
            result.append(out[k : k + len(seg)])
            k += len(seg)
        if self.record:
            self.stats.history.append((tuple(tuple(s) for s, _ in segments), tuple(out)))
        return result

    def _garbage(self, out: list[int], start: int) -> None:
        for k in range(start, len(out)):
            out[k] = self._rng.randrange(256)

    def _frame(self, data: list[int], gaps: list[float], now: float) -> list[int]:
        n = len(data)
        out = [0] * n
        self._bad = False
        names = self._addr_names
        if n and now < self._ready_at:
            self._bad = True  # talking to the chip within 50 ms of the reset
            self._garbage(out, 0)
            n = 0
        i = 0
        while i < n:
            cmd = data[i]
            name = names.get(cmd & R.ADDRESS_MASK)
            if cmd & R.WRITE_FLAG:
                if name == "SROM_Load_Burst":
                    self._upload(data, gaps, i)
                    break
                if i + 1 >= n:
                    self._bad = True  # an address without its data byte
                    break
                self._write(name, data[i + 1], now)
                need = R.T_SWW_US
            else:
                if name == "Motion_Burst":
                    if gaps[i] < R.T_SRAD_MOTBR_US or not self.burst_armed:
                        self._bad = True
                        self._garbage(out, i + 1)
                        break
                    report = self._burst()
                    for k in range(i + 1, min(n, i + 1 + R.BURST_LENGTH)):
                        out[k] = report[k - i - 1]
                    break
                if i + 1 >= n:
                    break  # an address alone: nothing happens
                if gaps[i] < R.T_SRAD_US:
                    self._bad = True
                    out[i + 1] = self._rng.randrange(256)
                else:
                    out[i + 1] = self._read(name, now)
                need = R.T_SRR_US
            if gaps[i + 1] < need:
                self._bad = True  # the next command (or the next frame) comes too soon
                self._garbage(out, i + 2)
                break
            i += 2
        if self._bad:
            self.stats.protocol_errors += 1
        return out

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
