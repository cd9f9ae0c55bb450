"""PixArt PMW3901 and PAA5100JE-Q optical-flow drivers (a :class:`~pln2033.sensor.SensorDriver`).

No ROS here. Register facts: :mod:`.regs` (sources named there and in docs/sensors.md).

Bring-up ([pimoroni], [bitcraze]): power-up reset (0x5A to 0x3A), 20 ms, product id 0x49 and
inverse id 0xB6, one read of the motion registers 0x02..0x06, the init ("performance
optimisation") sequence of the chip, the orientation register, one burst to start from
clean counters. A motion read is one 13-byte transfer: the burst address 0x16 and the 12
burst bytes; the chip's 16-bit delta registers are latched and cleared by it.

Quality: :attr:`Motion.quality` is the burst's SQUAL, with the rejection rule of
[pimoroni] folded in so that ``quality < SQUAL_MIN`` <=> the read carries no valid motion:
a burst with ``SQUAL < 0x19`` *and* the shutter at its longest (upper byte 0x1F) reports its
SQUAL (below 0x19: the poller treats the poll like a lift); a burst with ``SQUAL < 0x19``
but a shorter shutter (a valid read on a dim texture) reports 0x19. The raw bytes of the
last burst stay in :attr:`PMW3901.last_burst` and in the register dump.

Resolution: fixed by the optics and the height above the floor (:mod:`.flow_scale`); the
driver option ``height_m`` sets the effective CPI that :meth:`get_cpi` returns.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence

from ..bus import SpiBus
from ..errors import FirmwareError, InvalidCpiError, ProductIdError, SensorError, SpiError
from ..sensor import ChipInfo, CpiRange, Motion
from . import regs
from .flow_scale import BITCRAZE_PMW3901, OPTICAL_FLOW_ROS_PAA5100, FlowOptics

__all__ = [
    "PAA5100",
    "PAA5100_INFO",
    "PMW3901",
    "PMW3901_INFO",
    "REGISTER_NAMES",
    "InvalidHeightError",
]

INCH_PER_S = 0.0254

#: The register dump's names, in the chip's order (the burst fields in burst order).
REGISTER_NAMES = (
    "product_id",
    "revision_id",
    "motion",
    "observation",
    "delta_x",
    "delta_y",
    "squal",
    "raw_data_sum",
    "maximum_raw_data",
    "minimum_raw_data",
    "shutter_upper",
    "shutter_lower",
    "orientation",
    "inverse_product_id",
)


class InvalidHeightError(SensorError, ValueError):
    """A ``height_m`` outside the chip's working range (the optical-flow scale needs it)."""


def _signed16(lo: int, hi: int) -> int:
    v = (hi << 8) | lo
    return v - 0x10000 if v & 0x8000 else v


class PMW3901:
    """One PMW3901 on one chip select.

    Args:
        bus: the SPI device (mode 3 per the datasheet; mode 0 works too, [pimoroni] uses it).
        name: the device path, for messages.
        height_m: lens-to-floor distance (m), in :attr:`HEIGHT_RANGE_M`; default
            :attr:`HEIGHT_DEFAULT_M`. Sets the effective CPI (:mod:`.flow_scale`).
        optics: the field-of-view model (default :attr:`OPTICS`, docs/sensors.md says why).
        init: the init variant, a key of ``regs.INITS[chip]`` ("pimoroni"; PMW3901 also
            "bitcraze"), or a sequence of (register, value) pairs (``(regs.WAIT, ms)`` to
            pause) that replaces the last block, after the preamble and the c1/c2 trim.
        c1_rule: "px4" (vendor demo kit, default) or "pimoroni" (see ``regs.adjust_c1``).
        rotation_deg: 0/90/180/270 -> the orientation register ([pimoroni] set_rotation),
            None leaves the value the init sequence wrote (0xA0).
        product_id: the product id to expect (inverse: its complement), for a relabelled part.
        sleep: the pause function (tests pass one that advances a fake clock).
    """

    CHIP = "pmw3901"
    TITLE = "PixArt PMW3901"
    OPTICS: FlowOptics = BITCRAZE_PMW3901
    HEIGHT_DEFAULT_M = 0.10
    HEIGHT_RANGE_M = (0.08, 1.0)
    HEIGHT_HINT = (
        "its lens focuses from 80 mm (datasheet figure quoted by PX4's driver); for a sensor "
        "closer to the floor use a PAA5100 (15..35 mm)"
    )
    MAX_FLOW_RAD_S = 7.4  # datasheet, quoted by PX4's driver; a speed limit of 7.4 * height

    def __init__(
        self,
        bus: SpiBus,
        name: str = "pmw3901",
        *,
        height_m: float | None = None,
        optics: FlowOptics | None = None,
        init: str | Sequence[tuple[int, int]] = "pimoroni",
        c1_rule: str = "px4",
        rotation_deg: int | None = 0,
        product_id: int = regs.PRODUCT_ID_VALUE,
        sleep: Callable[[float], None] = time.sleep,
    ) -> None:
        self.bus = bus
        self.name = name
        self.optics = optics or self.OPTICS
        self.height_m = self._check_height(self.HEIGHT_DEFAULT_M if height_m is None else height_m)
        variants = regs.INITS[self.CHIP]
        if isinstance(init, str):
            if init not in variants:
                raise ValueError(
                    f"{name}: init sequence {init!r} unknown for the {self.TITLE}; "
                    f"allowed: {', '.join(variants)} or a list of (register, value) pairs"
                )
            self._preamble, self._init = variants[init]
        else:
            self._preamble, self._init = True, tuple((int(r), int(v)) for r, v in init)
        regs.adjust_c1(0, c1_rule)  # ValueError naming the rules
        self.c1_rule = c1_rule
        if rotation_deg is not None and rotation_deg not in regs.ROTATIONS:
            raise ValueError(
                f"{name}: rotation_deg must be one of 0, 90, 180, 270 or None, got {rotation_deg!r}"
            )
        self.rotation_deg = rotation_deg
        if not 0 <= product_id <= 0xFF:
            raise ValueError(f"{name}: product_id must be a byte, got {product_id!r}")
        self.product_id = product_id
        self._sleep = sleep
        self.metres_per_count = self.optics.metres_per_count(self.height_m)
        self.effective_cpi = self.optics.cpi(self.height_m)
        self.cpi = max(1, round(self.effective_cpi))
        self.info = self.chip_info(self.height_m, self.optics)
        # The burst is built once: it runs up to 1000 times a second.
        self._burst_tx = [regs.MOTION_BURST] + [0] * regs.BURST_LEN
        self.last_burst: list[int] = [0] * (regs.BURST_LEN + 1)
        self.revision = -1

    # --- the chip's description -------------------------------------------------------------

    @classmethod
    def max_speed_mps(cls, height_m: float) -> float:
        return cls.MAX_FLOW_RAD_S * height_m

    @classmethod
    def chip_info(cls, height_m: float | None = None, optics: FlowOptics | None = None) -> ChipInfo:
        """The :class:`ChipInfo` at ``height_m`` (default: the default height), CPI fixed there."""
        h = cls.HEIGHT_DEFAULT_M if height_m is None else height_m
        cpi = max(1, round((optics or cls.OPTICS).cpi(h)))
        return ChipInfo(
            chip=cls.CHIP,
            title=cls.TITLE,
            bus="spi",
            cpi=CpiRange(cpi, cpi, 1),
            cpi_default=cpi,
            spi_mode=3,
            max_spi_hz=2_000_000,
            counter_bits=16,
            quality_name="SQUAL",
            quality_threshold=regs.SQUAL_MIN,
            max_speed_mps=round(cls.max_speed_mps(h), 3),
            firmware="",
            source="pimoroni/pmw3901-python (init, burst, rejection rule), crazyflie-firmware "
            "and PX4 (ids, FOV model): docs/sensors.md",
        )

    def _check_height(self, h: object) -> float:
        lo, hi = self.HEIGHT_RANGE_M
        if isinstance(h, bool) or not isinstance(h, int | float) or not math.isfinite(h):
            raise InvalidHeightError(f"{self.name}: height_m must be a number of metres, got {h!r}")
        if not lo <= h <= hi:
            raise InvalidHeightError(
                f"{self.name}: height_m {h:g} m is outside the {self.TITLE}'s working range "
                f"{lo:g}..{hi:g} m: {self.HEIGHT_HINT}. Measure the lens-to-floor distance "
                "and set the driver option height_m"
            )
        return float(h)

    # --- raw register access ------------------------------------------------------------------

    def _xfer(self, tx: list[int]) -> list[int]:
        rx = self.bus.xfer2(tx)
        if len(rx) != len(tx):
            raise SpiError(f"{self.name}: sent {len(tx)} bytes, received {len(rx)}")
        return rx

    def read_register(self, reg: int) -> int:
        """One byte from ``reg`` of the current bank."""
        return self._xfer([reg & regs.ADDRESS_MASK, 0])[1]

    def write_register(self, reg: int, value: int) -> None:
        if not 0 <= value <= 0xFF:
            raise ValueError(f"register value {value} does not fit 8 bits")
        self._xfer([(reg & regs.ADDRESS_MASK) | regs.WRITE_FLAG, value])

    def _write_all(self, pairs: Sequence[tuple[int, int]]) -> None:
        for reg, value in pairs:
            if reg == regs.WAIT:
                self._sleep(value / 1000.0)
            else:
                self.write_register(reg, value)

    # --- bring-up -------------------------------------------------------------------------------

    def power_up_reset(self) -> None:
        self.write_register(regs.POWER_UP_RESET, regs.POWER_UP_RESET_VALUE)
        self._sleep(regs.POWER_UP_WAIT_S)

    def check_product_id(self) -> None:
        """ProductIdError unless the ids read (product, inverse) = (expected, its complement)."""
        got = self.read_register(regs.PRODUCT_ID)
        self.revision = self.read_register(regs.REVISION_ID)
        inv = self.read_register(regs.INVERSE_PRODUCT_ID)
        want, want_inv = self.product_id, self.product_id ^ 0xFF
        if got == want and inv == want_inv:
            return
        if got == inv and got in (0x00, 0xFF):
            what = f"every byte reads {got:#04x}: nothing answers"
        else:
            what = f"product id reads {got:#04x}, inverse id {inv:#04x}"
        raise ProductIdError(
            f"{self.name}: no {self.TITLE} found ({what}; expected {want:#04x} and inverse "
            f"{want_inv:#04x}). Check the wiring (MISO, MOSI, SCLK, CS), the 3.3 V supply, "
            "that this chip select is the sensor's, and SPI mode 3 (or 0) at <= 2 MHz; a part "
            "that answers with another id can be accepted with the driver option product_id"
        )

    def _run_init(self) -> None:
        if self._preamble:
            self._write_all(regs.PREAMBLE)
            probe = self.read_register(regs.TRIM_PROBE)
            self.write_register(
                regs.TRIM_REG, regs.TRIM_SET if probe & regs.TRIM_PROBE_BIT else regs.TRIM_CLEAR
            )
            self._write_all(regs.MIDDLE)
            if self.read_register(regs.C_FLAG) == 0:
                c1 = regs.adjust_c1(self.read_register(regs.C1_REG), self.c1_rule)
                c2 = regs.adjust_c2(self.read_register(regs.C2_REG))
                self._write_all(regs.C_PREFIX)
                self.write_register(regs.C1_REG, c1)
                self.write_register(regs.C2_REG, c2)
        self._write_all(self._init)
        self.write_register(regs.BANK_SELECT, 0x00)
        if self.rotation_deg is not None:
            self.write_register(regs.ORIENTATION, regs.ROTATIONS[self.rotation_deg])

    def initialise(self, cpi: int | None = None, firmware: Sequence[int] | None = None) -> None:
        """Reset, identify, init sequence, orientation, one burst (clean counters).

        ``cpi`` is ignored: the resolution is fixed by the height (``height_m``); the node
        logs that. ``firmware`` must be None: the chip takes none (FirmwareError).
        """
        if firmware is not None:
            self.check_firmware(firmware)
        self.power_up_reset()
        self.check_product_id()
        for reg in (regs.MOTION, regs.DELTA_X_L, regs.DELTA_X_H, regs.DELTA_Y_L, regs.DELTA_Y_H):
            self.read_register(reg)
        self._run_init()
        self.read_motion()

    # --- motion ---------------------------------------------------------------------------------

    @property
    def motion_tx(self) -> list[int]:
        """The 13 bytes of a motion burst (address + 12), built once."""
        return self._burst_tx

    def read_motion(self) -> Motion:
        """One burst: delta X/Y since the previous read (cleared by the chip), SQUAL."""
        return self.decode_motion(self.bus.xfer2(self._burst_tx))

    def decode_motion(self, rx: list[int]) -> Motion:
        """The :class:`Motion` in the 13 bytes a burst clocked in (rx[0]: during the address)."""
        if len(rx) != regs.BURST_LEN + 1:
            raise SpiError(f"{self.name}: sent {regs.BURST_LEN + 1} bytes, received {len(rx)}")
        self.last_burst = rx
        b = rx[1:]
        squal = b[regs.B_SQUAL]
        if squal < regs.SQUAL_MIN and b[regs.B_SHUTTER_UPPER] != regs.SHUTTER_UPPER_MAX:
            squal = regs.SQUAL_MIN  # [pimoroni] accepts it: keep it at/above the threshold
        status = b[regs.B_MOTION]
        return Motion(
            dx=_signed16(b[regs.B_DX_L], b[regs.B_DX_H]),
            dy=_signed16(b[regs.B_DY_L], b[regs.B_DY_H]),
            status=status,
            lifted=False,  # no lift bit: a lifted chip shows as low quality
            moved=bool(status & regs.MOTION_BIT),
            overflow=False,  # no overflow bit; 16 bits hold 8 m per read at 0.10 m
            quality=squal,
        )

    def read_all_registers(self) -> tuple[Motion, dict[str, int]]:
        """The register dump (:data:`REGISTER_NAMES`) and the Motion its burst cleared."""
        ids = [self.read_register(regs.PRODUCT_ID), self.read_register(regs.REVISION_ID)]
        motion = self.read_motion()
        b = self.last_burst[1:]
        values = dict(zip(REGISTER_NAMES[:2], ids, strict=True))
        values.update(
            motion=b[regs.B_MOTION],
            observation=b[regs.B_OBSERVATION],
            delta_x=(b[regs.B_DX_H] << 8) | b[regs.B_DX_L],
            delta_y=(b[regs.B_DY_H] << 8) | b[regs.B_DY_L],
            squal=b[regs.B_SQUAL],
            raw_data_sum=b[regs.B_RAW_SUM],
            maximum_raw_data=b[regs.B_RAW_MAX],
            minimum_raw_data=b[regs.B_RAW_MIN],
            shutter_upper=b[regs.B_SHUTTER_UPPER],
            shutter_lower=b[regs.B_SHUTTER_LOWER],
            orientation=self.read_register(regs.ORIENTATION),
            inverse_product_id=self.read_register(regs.INVERSE_PRODUCT_ID),
        )
        return motion, values

    # --- resolution (fixed) ---------------------------------------------------------------------

    def cpi_problem(self, cpi: object) -> str | None:
        problem = self.info.cpi.problem(cpi, self.TITLE)
        if problem is None:
            return None
        return (
            f"{self.name}: the {self.TITLE}'s resolution is fixed at {self.cpi} CPI, set by its "
            f"height above the floor ({self.height_m:g} m, driver option height_m), not by a "
            f"register; cannot set {cpi!r}. Change height_m to the measured height, and let the "
            "calibration fit's scale correct the rest"
        )

    def get_cpi(self) -> tuple[int, int]:
        """The effective CPI at the configured height, both axes (no register holds it)."""
        return self.cpi, self.cpi

    def set_cpi(self, cpi: int, on_drain: Callable[[Motion], None] | None = None) -> None:
        """Accepts only the effective CPI (no write); anything else: InvalidCpiError.
        ``on_drain`` is never called: the resolution does not change, so no count changes scale."""
        problem = self.cpi_problem(cpi)
        if problem:
            raise InvalidCpiError(problem)

    # --- firmware (none) ------------------------------------------------------------------------

    def check_firmware(self, words: Sequence[int]) -> None:
        raise FirmwareError(
            f"the {self.TITLE} takes no firmware (it has no SROM or patch RAM); "
            "leave the firmware option empty for this device"
        )

    def load_firmware(self, words: Sequence[int]) -> None:
        self.check_firmware(words)


class PAA5100(PMW3901):
    """One PAA5100JE-Q (Pimoroni's "near optical flow" breakout): the PMW3901's protocol with
    its own init sequence, optics and a 15..35 mm working range."""

    CHIP = "paa5100"
    TITLE = "PixArt PAA5100JE-Q"
    OPTICS = OPTICAL_FLOW_ROS_PAA5100
    HEIGHT_DEFAULT_M = 0.025
    HEIGHT_RANGE_M = (0.015, 0.035)
    HEIGHT_HINT = (
        "its working range is 15..35 mm (datasheet general description); for a sensor "
        "higher above the floor use a PMW3901 (80 mm and up)"
    )
    MAX_SPEED_MPS = 45 * INCH_PER_S  # 45 ips (datasheet figure quoted on the DPRG list)

    @classmethod
    def max_speed_mps(cls, height_m: float) -> float:
        return cls.MAX_SPEED_MPS


PMW3901_INFO = PMW3901.chip_info()
"""The PMW3901 at its default height (0.10 m): 104 CPI."""
PAA5100_INFO = PAA5100.chip_info()
"""The PAA5100 at its default height (25 mm): 232 CPI."""
