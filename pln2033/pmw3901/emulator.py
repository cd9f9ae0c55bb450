"""Register-level PMW3901 / PAA5100JE-Q emulators behind spidev's ``xfer2`` bytes.

Built on the shared motion model :class:`~pln2033.emulated.CountingCore`: the true
sensor-frame motion becomes counts through the field-of-view model of :mod:`.flow_scale`
at the *emulated* height (``height_m``), so a driver configured for another height sees
the scale error the calibration fit must correct.

What the chip does here (facts: :mod:`.regs`; assumptions marked):

- Banks: register 0x7F selects the bank; every other register is per bank. The ids
  (0x00 = 0x49, 0x01 = revision, 0x5F = 0xB6), the motion registers, the burst 0x16 and
  the power-up reset 0x3A answer in bank 0 only.
- Power-up reset (0x5A to 0x3A): registers back to their factory values, counters cleared,
  the chip not tracking until the init sequence is written. The emulator records every
  write since the reset (``writes``: (bank, register, value)) and starts tracking once they
  begin with one of the chip's known sequences (``regs.INITS``, trim values computed from
  its factory registers; either c1 rule accepted): ``init_variant`` names it. Not tracking
  = no counts and low SQUAL (assumption: the real chip tracks badly without it).
- Reading 0x02 latches the counters into 0x03..0x06 (little-endian, read clears each
  axis after its high byte); the burst latches and clears them, and returns motion,
  observation, delta X/Y, SQUAL, raw sum/max/min, shutter upper/lower.
- Lift and poor-surface edges: the chip has no lift detector that clears its counters; it
  stops counting when the image has no features and keeps what it counted until the next
  read. So a read whose interval straddles an edge holds the counts made before the lift
  (or after the touch-down), with a low SQUAL; ``stats.lift_cleared_x/y`` stay 0. The
  time between reads is split at each window edge (:meth:`advance`).
- SQUAL: around ``squal`` (default 0x60) with the shutter upper byte 0x02 on a good surface;
  below 0x19 with the shutter upper byte at 0x1F after a lift, over a low-quality window,
  or while not tracking -- the [pimoroni] rejection rule then rejects the read.
- Axes (assumption): the native counts are (-y, -x) of the true sensor frame, so that the
  orientation [pimoroni] calls rotation 0 (0xE0) gives +x right, +y forward; the register
  0x5B applies swap, then inversions, as [pimoroni] set_orientation describes.
"""

from __future__ import annotations

from typing import Any

from ..emulated import CountingCore
from ..motion import MotionSource
from . import regs
from .flow_scale import BITCRAZE_PMW3901, OPTICAL_FLOW_ROS_PAA5100, FlowOptics

__all__ = ["EmulatedPAA5100", "EmulatedPMW3901", "expected_init_writes"]

#: Factory values of the trim registers (bank 0x0E) -- assumptions: 0x67 bit 7 set, 0x73 = 0,
#: c1 = 26 (the two c1 rules differ there: 40 vs 51), c2 = 64.
FACTORY_TRIM = {regs.TRIM_PROBE: 0x80, regs.C_FLAG: 0x00, regs.C1_REG: 26, regs.C2_REG: 64}
TRIM_BANK = 0x0E


def expected_init_writes(
    chip: str, variant: str, trim: dict[int, int] | None = None, c1_rule: str = "px4"
) -> list[tuple[int, int]]:
    """The (register, value) writes the init ``variant`` of ``chip`` makes on a chip whose trim
    registers (bank 0x0E) hold ``trim`` (default :data:`FACTORY_TRIM`); WAITs left out."""
    trim = FACTORY_TRIM if trim is None else trim
    preamble, block = regs.INITS[chip][variant]
    out: list[tuple[int, int]] = []
    if preamble:
        out += regs.PREAMBLE
        out.append(
            (
                regs.TRIM_REG,
                regs.TRIM_SET if trim[regs.TRIM_PROBE] & regs.TRIM_PROBE_BIT else regs.TRIM_CLEAR,
            )
        )
        out += regs.MIDDLE
        if trim[regs.C_FLAG] == 0:
            out += regs.C_PREFIX
            out.append((regs.C1_REG, regs.adjust_c1(trim[regs.C1_REG], c1_rule)))
            out.append((regs.C2_REG, regs.adjust_c2(trim[regs.C2_REG])))
    out += [(r, v) for r, v in block if r != regs.WAIT]
    return out


class EmulatedPMW3901(CountingCore):
    """One emulated PMW3901; use it wherever a :class:`~pln2033.bus.SpiBus` goes.

    Args as :class:`~pln2033.emulated.CountingCore` (motion, clock, lift_windows,
    noise_counts, fault_windows, reset_after_fault, seed, record, low_quality_windows), plus:
        height_m: the emulated lens-to-floor distance (m; default the driver's default).
        optics: the emulated field-of-view model (default the driver's).
        product_id, revision: what the id registers answer.
        squal: SQUAL on a good surface.
        trim: factory values of the trim registers (bank 0x0E), see :data:`FACTORY_TRIM`.
    """

    CHIP = "pmw3901"
    OPTICS: FlowOptics = BITCRAZE_PMW3901
    HEIGHT_DEFAULT_M = 0.10

    def __init__(
        self,
        motion: MotionSource | None = None,
        *,
        height_m: float | None = None,
        optics: FlowOptics | None = None,
        product_id: int = regs.PRODUCT_ID_VALUE,
        revision: int = 0x00,
        squal: int = 0x60,
        trim: dict[int, int] | None = None,
        **core: Any,
    ) -> None:
        self.optics = optics or self.OPTICS
        self.height_m = self.HEIGHT_DEFAULT_M if height_m is None else float(height_m)
        if not self.height_m > 0:
            raise ValueError(f"emulated height must be > 0 m, got {height_m}")
        self.product_id = product_id
        self.revision = revision
        self.squal_level = squal
        self.trim = dict(FACTORY_TRIM if trim is None else trim)
        self._expected = {
            (variant, rule): expected_init_writes(self.CHIP, variant, self.trim, rule)
            for variant in regs.INITS[self.CHIP]
            for rule in ("px4", "pimoroni")
        }
        self._expected_lengths = {len(v) for v in self._expected.values()}
        self._lq = sorted((float(a), float(b)) for a, b in core.get("low_quality_windows", ()))
        self._lq_i = 0
        # every start and end of a lift or low-quality window, in time order
        self._edges = sorted(
            {float(t) for w in (*core.get("lift_windows", ()), *self._lq) for t in w[:2]}
        )
        self._edge_i = 0
        self.latch_x = self.latch_y = 0
        super().__init__(
            motion=motion,
            **core,
            cpi=self.optics.cpi(self.height_m),
            counter_bits=16,
        )
        self._power_on()
        self.stats.resets = 0

    # --- chip state -------------------------------------------------------------------------

    def _power_on(self) -> None:
        self.regs: dict[tuple[int, int], int] = {
            (TRIM_BANK, reg): value for reg, value in self.trim.items()
        }
        self.regs[(0, regs.PRODUCT_ID)] = self.product_id
        self.regs[(0, regs.REVISION_ID)] = self.revision
        self.regs[(0, regs.INVERSE_PRODUCT_ID)] = self.product_id ^ 0xFF
        self.bank = 0
        self.writes: list[tuple[int, int, int]] = []
        self.init_variant: tuple[str, str] | None = None
        self.reset_counts()
        self.latch_x = self.latch_y = 0
        self._latch_out = [0, 0, 0, 0]
        self._poor_seen = False
        self.counting = False  # not tracking until the init sequence is in
        self.stats.resets += 1

    def power_cycle(self) -> None:
        self._power_on()

    def clear_latches(self) -> tuple[int, int]:
        x, y = self.latch_x, self.latch_y
        self.latch_x = self.latch_y = 0
        self._latch_out = [0, 0, 0, 0]
        return x, y

    @property
    def tracking(self) -> bool:
        return self.init_variant is not None

    @property
    def orientation(self) -> int:
        return self.regs.get((0, regs.ORIENTATION), 0)

    def output_counts(self, x: int, y: int) -> tuple[int, int]:
        """True-frame counts (x right, y forward) as the chip reports them (see module doc)."""
        return regs.orient(-y, -x, self.orientation)

    # --- time -------------------------------------------------------------------------------

    def advance(self, now: float | None = None) -> None:
        """Count up to ``now``, stopping at every window edge on the way (module doc)."""
        if now is None:
            now = self.clock()
        edges, i = self._edges, self._edge_i
        while i < len(edges) and edges[i] <= self._t:
            i += 1
        while i < len(edges) and edges[i] < now:
            self._advance_to(edges[i])
            i += 1
        self._edge_i = i
        self._advance_to(now)

    def _start_lift(self) -> None:
        # the core clears the counters when a lift starts; this chip keeps them (module doc)
        self._lifted = True
        self._lift_flag = True
        self.stats.lift_events += 1

    def _advance_to(self, now: float) -> None:
        t0 = self._t
        super().advance(now)
        t1 = self._t
        if self._lq and t1 > t0:
            w, i = self._lq, self._lq_i
            while i < len(w) and w[i][1] <= t0:
                i += 1
            self._lq_i = i
            if i < len(w) and w[i][0] < t1:
                self._poor_seen = True

    # --- SPI --------------------------------------------------------------------------------

    def xfer2(self, data: list[int]) -> list[int]:
        now = self.clock()
        mode = self.spi_fault(now)
        if mode == "no_response":
            return [0xFF] * len(data)
        self.advance(now)
        out = [0] * len(data)
        if data and data[0] == regs.MOTION_BURST and self.bank == 0:
            burst = self._burst()
            n = min(len(data) - 1, regs.BURST_LEN)
            out[1 : 1 + n] = burst[:n]
        else:
            if len(data) % 2:
                self.stats.protocol_errors += 1
            for i in range(0, len(data) - 1, 2):
                cmd = data[i]
                if cmd & regs.WRITE_FLAG:
                    self._write(cmd & regs.ADDRESS_MASK, data[i + 1])
                else:
                    out[i + 1] = self._read(cmd & regs.ADDRESS_MASK)
        if mode == "corrupt":
            self.corrupt(out)
        if self.record:
            self.stats.history.append((tuple(data), tuple(out)))
        return out

    def close(self) -> None:
        pass

    # --- register semantics -----------------------------------------------------------------

    def _write(self, reg: int, value: int) -> None:
        if reg == regs.BANK_SELECT:
            self.writes.append((self.bank, reg, value))
            self.bank = value
        elif self.bank == 0 and reg == regs.POWER_UP_RESET:
            if value == regs.POWER_UP_RESET_VALUE:
                self._power_on()
            return
        else:
            self.writes.append((self.bank, reg, value))
            if self.bank == 0 and reg in (
                regs.PRODUCT_ID,
                regs.REVISION_ID,
                regs.INVERSE_PRODUCT_ID,
            ):
                return  # read-only
            self.regs[(self.bank, reg)] = value
        if self.init_variant is None and len(self.writes) in self._expected_lengths:
            sent = [(r, v) for _, r, v in self.writes]
            for key, want in self._expected.items():
                if sent == want:
                    self.init_variant = key
                    self.counting = True
                    break

    def _read(self, reg: int) -> int:
        if self.bank == 0:
            if reg == regs.MOTION:
                return self._latch()
            if regs.DELTA_X_L <= reg <= regs.DELTA_Y_H:
                k = reg - regs.DELTA_X_L
                value = self._latch_out[k]
                if k == 1:
                    self.latch_x = self._latch_out[0] = self._latch_out[1] = 0
                elif k == 3:
                    self.latch_y = self._latch_out[2] = self._latch_out[3] = 0
                return value
        return self.regs.get((self.bank, reg), 0)

    def _take(self) -> tuple[bool, bool, int, int]:
        """(moved, poor, x, y): flags and counts since the last latch, cleared."""
        s = self.stats
        moved, lift_seen, _ox, _oy = self.take_flags()
        s.overwritten_x += self.latch_x
        s.overwritten_y += self.latch_y
        x, y = self.take_counts()
        poor = lift_seen or self.lifted or self._poor_seen or self.poor_surface or not self.tracking
        self._poor_seen = False
        return moved, poor, x, y

    def _latch(self) -> int:
        moved, _poor, x, y = self._take()
        self.latch_x, self.latch_y = x, y
        ox, oy = self.output_counts(x, y)
        ox &= 0xFFFF
        oy &= 0xFFFF
        self._latch_out = [ox & 0xFF, ox >> 8, oy & 0xFF, oy >> 8]
        return regs.MOTION_BIT if moved else 0

    def _burst(self) -> list[int]:
        moved, poor, x, y = self._take()
        self.latch_x = self.latch_y = 0
        self._latch_out = [0, 0, 0, 0]
        ox, oy = self.output_counts(x, y)
        ox &= 0xFFFF
        oy &= 0xFFFF
        rng = self._rng
        if poor:
            squal = rng.randrange(0, regs.SQUAL_MIN)
            shutter_upper, shutter_lower = regs.SHUTTER_UPPER_MAX, 0xFF
            raw = (0x08, 0x10, 0x00)
        else:
            squal = max(0x20, min(0xFF, self.squal_level + rng.randint(-8, 8)))
            shutter_upper, shutter_lower = 0x02, rng.randrange(0x40, 0xC0)
            raw = (0x30, 0x70, 0x10)
        return [
            regs.MOTION_BIT if moved else 0,
            0x00,  # observation: its meaning is not published
            ox & 0xFF,
            ox >> 8,
            oy & 0xFF,
            oy >> 8,
            squal,
            *raw,
            shutter_upper,
            shutter_lower,
        ]


class EmulatedPAA5100(EmulatedPMW3901):
    """One emulated PAA5100JE-Q: the PMW3901's bytes, its own init sequence and optics."""

    CHIP = "paa5100"
    OPTICS = OPTICAL_FLOW_ROS_PAA5100
    HEIGHT_DEFAULT_M = 0.025
