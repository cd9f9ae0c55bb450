"""PMW3360 and PMW3389 drivers (PixArt gaming-mouse sensors, SPI mode 3).

No ROS here. Both chips speak the same serial protocol [DS3360 sec. 3]: one address byte
(MSB 1 = write) and one data byte; a read waits tSRAD (160 us) between the address and the
data, the motion burst tSRAD_MOTBR (35 us). Those waits lie inside one chip-select frame, so
every transfer goes through :meth:`~pln2033.bus.SegmentedSpiBus.xfer_segments`: each
segment carries the delay after it (on Linux the kernel's ``delay_usecs``), and each frame
ends with the gap the next command needs (tSWW 180 us after a write, tSRR 20 us after a
read), chip select still low, so consecutive frames are timed without a sleep.

Counter semantics [DS3360 Motion, sec. 4]: reading Motion (or a motion burst) freezes the
delta registers and clears the counters; reading the deltas clears them. The burst reports
Motion, Observation, Delta_X_L/H, Delta_Y_L/H, SQUAL, Raw_Data_Sum, Max/Min raw data and
Shutter_Upper/Lower. The burst mode is armed by writing Motion_Burst and must be armed again
after any other register read (step 7), which this driver tracks.

The SROM (PixArt's firmware, 4094 bytes) cannot ship with this project: the user supplies it
(:func:`read_srom_file`), like the PLN2033's patch code.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

from ..errors import (
    FirmwareError,
    InvalidCpiError,
    ProductIdError,
    SensorError,
    SensorNotRespondingError,
    SpiError,
)
from ..firmware import read_firmware_bytes
from ..sensor import INCH_M, ChipInfo, CpiRange, Motion
from . import regs as R  # noqa: N812 (the register facts, short: R.T_SRAD_US)

__all__ = [
    "PMW3360",
    "PMW3360_INFO",
    "PMW3389",
    "PMW3389_INFO",
    "PMW33xx",
    "PollBudget",
    "poll_budget",
    "read_srom_file",
]

IPS_M = INCH_M  # one inch per second in m/s

PMW3360_INFO = ChipInfo(
    chip="pmw3360",
    title="PixArt PMW3360",
    bus="spi",
    cpi=CpiRange(100, 12000, 100),  # [DS3360 Config1]
    cpi_default=1600,  # QMK's PMW3360_CPI default
    spi_mode=R.SPI_MODE,
    max_spi_hz=R.MAX_SPI_HZ,
    counter_bits=16,
    quality_name="SQUAL",
    # Min_SQ_Run's default 0x10: below that SQUAL the chip reports zero motion [DS3360 0x2B],
    # so such a poll lost counts: treated like a lift.
    quality_threshold=R.MIN_SQ_RUN_DEFAULT,
    max_speed_mps=250 * IPS_M,  # 250 ips typical [DS3360 key parameters]
    firmware="srom",
    source="PMW3360 datasheet v1.50 (SunjunKim/PMW3360_Arduino) + QMK drivers/sensors/pmw3360*",
)

PMW3389_INFO = ChipInfo(
    chip="pmw3389",
    title="PixArt PMW3389",
    bus="spi",
    cpi=CpiRange(50, 16000, 50),  # [QMK pmw3389.h; TSH]
    cpi_default=2000,  # QMK's PMW3389_CPI default
    spi_mode=R.SPI_MODE,
    max_spi_hz=R.MAX_SPI_HZ,
    counter_bits=16,
    quality_name="SQUAL",
    quality_threshold=R.MIN_SQ_RUN_DEFAULT,  # assumed as the PMW3360's (same Min_SQ_Run register)
    max_speed_mps=400 * IPS_M,  # 400 ips (PixArt's figure, as issue 15 quotes it)
    firmware="srom",
    source="QMK drivers/sensors/pmw3389* (map, CPI), teamspatzenhirn + nRF (product id 0x47)",
)


def _signed16(value: int) -> int:
    return value - 0x10000 if value & 0x8000 else value


def read_srom_file(path: str | Path) -> list[int]:
    """The SROM file the user supplies: bytes in hex text (``0x01, 0x04, ...``; PixArt ships an
    ASCII text file [DS3360 sec. 5]; ``//`` and ``#`` comments allowed) or raw binary."""
    return list(read_firmware_bytes(path, "SROM file", FirmwareError))


class PMW33xx:
    """One PMW3360 or PMW3389 on one chip select (a :class:`~pln2033.sensor.SensorDriver`).

    Options (per device, through the registry's ``make_driver(..., **options)``):
        product_id: the Product_ID to expect (default the chip's; the inverse is its
            complement). Override it for a chip that answers another id (QMK's PMW3389
            code expects 0x42).
        srom_id: the SROM_ID to expect after an upload (None: any non-zero version).
        srom_length: the bytes an SROM file must have (None: any length).
        check_crc: run the SROM CRC self test after an upload (10 ms; default on).
        burst_length: bytes of the motion burst to read (7 reaches SQUAL; 12 all).
        tsrad_us, tsrad_motbr_us: the read delays (default the datasheet's 160 / 35 us).
        sleep: how to wait between frames (time.sleep; tests pass a fake clock's).
    """

    regs: R.ChipRegs
    info: ChipInfo

    def __init__(
        self,
        bus,
        name: str = "pmw33xx",
        *,
        product_id: int | None = None,
        srom_id: int | None = None,
        srom_length: int | None = R.SROM_LENGTH,
        check_crc: bool = True,
        burst_length: int = R.BURST_LENGTH,
        tsrad_us: int = R.T_SRAD_US,
        tsrad_motbr_us: int = R.T_SRAD_MOTBR_US,
        sleep: Callable[[float], None] = time.sleep,
    ) -> None:
        if not hasattr(bus, "xfer_segments"):
            raise TypeError(
                f"{name}: the {self.info.title} needs a bus with xfer_segments (delays inside "
                "one chip-select frame): SpidevBus or the chip's emulator"
            )
        for label, v in (("product_id", product_id), ("srom_id", srom_id)):
            if v is not None and (
                isinstance(v, bool) or not isinstance(v, int) or not 0 <= v <= 0xFF
            ):
                raise ValueError(f"{name}: option {label} must be a byte 0..255, got {v!r}")
        if not 7 <= burst_length <= R.BURST_LENGTH:
            raise ValueError(f"{name}: burst_length {burst_length} must be 7..12 (SQUAL is byte 6)")
        for label, us in (("tsrad_us", tsrad_us), ("tsrad_motbr_us", tsrad_motbr_us)):
            if not 0 <= us <= 0xFFFF:
                raise ValueError(f"{name}: {label} {us} must be 0..65535 us")
        self.bus = bus
        self.name = name
        self.product_id = self.regs.product_id if product_id is None else product_id
        self.srom_id = srom_id
        self.srom_length = srom_length
        self.check_crc = check_crc
        self.tsrad_us = tsrad_us
        self._sleep = sleep
        self.srom_version = 0  # SROM_ID after the last upload (0: none)
        a = self.regs.addresses
        # The hot path, built once: arm the burst (a write to Motion_Burst), then the burst.
        self._arm_tx = [([a["Motion_Burst"] | R.WRITE_FLAG, 0x00], R.T_SWW_US)]
        self._burst_tx = [([a["Motion_Burst"]], tsrad_motbr_us), ([0] * burst_length, 0)]
        self._in_burst = False
        self._dump_names = R.dump_names(self.regs)
        self._dump_tx, self._dump_idx = self._frame([("r", n) for n in self._dump_names])

    # --- frames ---------------------------------------------------------------------------

    def _frame(self, ops: Sequence[tuple]) -> tuple[list[tuple[list[int], int]], list[int]]:
        """Segments for ("r", name) / ("w", name, value) ops and the segment index of each
        read's data byte."""
        a = self.regs.addresses
        segs: list[tuple[list[int], int]] = []
        idx: list[int] = []
        for op in ops:
            if op[0] == "r":
                segs.append(([a[op[1]]], self.tsrad_us))
                segs.append(([0], R.T_SRR_US))
                idx.append(len(segs) - 1)
            else:
                segs.append(([a[op[1]] | R.WRITE_FLAG, op[2] & 0xFF], R.T_SWW_US))
        return segs, idx

    def _xfer(self, segments: list[tuple[list[int], int]]) -> list[list[int]]:
        rx = self.bus.xfer_segments(segments)
        if len(rx) != len(segments) or any(
            len(r) != len(s[0]) for r, s in zip(rx, segments, strict=False)
        ):
            raise SpiError(f"{self.name}: the bus returned another number of bytes than sent")
        return rx

    def read_registers(self, names: Sequence[str]) -> list[int]:
        """Read registers by name in one frame. Reading Motion or a delta register clears
        counters (use :meth:`read_motion` / :meth:`read_all_registers` for those)."""
        segs, idx = self._frame([("r", n) for n in names])
        rx = self._xfer(segs)
        self._in_burst = False  # [DS3360 sec. 4 step 7]
        return [rx[i][0] for i in idx]

    def read_register(self, name: str) -> int:
        return self.read_registers([name])[0]

    def write_registers(self, pairs: Sequence[tuple[str, int]]) -> None:
        for reg, value in pairs:
            if not 0 <= value <= 0xFF:
                raise ValueError(f"register value {value} of {reg} does not fit 8 bits")
        self._xfer(self._frame([("w", n, v) for n, v in pairs])[0])

    def write_register(self, name: str, value: int) -> None:
        self.write_registers([(name, value)])

    # --- motion ---------------------------------------------------------------------------

    @property
    def transfers_per_poll(self) -> int:
        """SPI frames one :meth:`read_motion` costs: 1 (2 after a non-burst access)."""
        return 1 if self._in_burst else 2

    @property
    def burst_delay_us(self) -> int:
        """The wait inside each burst frame (tSRAD_MOTBR)."""
        return self._burst_tx[0][1]

    def read_motion(self) -> Motion:
        """One motion burst: counts since the previous read, SQUAL, lift; clears the counters."""
        if not self._in_burst:
            self._xfer(self._arm_tx)
            self._in_burst = True
        rx = self.bus.xfer_segments(self._burst_tx)
        return self.decode_burst(rx[1])

    def decode_burst(self, b: list[int]) -> Motion:
        """The :class:`Motion` in the bytes a burst clocked in (after the address byte)."""
        if len(b) != len(self._burst_tx[1][0]):
            raise SpiError(f"{self.name}: burst returned {len(b)} bytes")
        m = b[0]
        if m == 0xFF and b[1] == 0xFF:
            raise SensorNotRespondingError(
                f"{self.name}: the motion burst reads all ones: no {self.info.title} answers; "
                "check wiring (MISO), the supply and SPI mode 3"
            )
        if m & (R.OP_MODE_MASK | R.FRAME_RDATA_1ST):
            self._in_burst = False  # rest mode or frame data: arm the burst again [QMK]
        return Motion(
            dx=_signed16(b[2] | (b[3] << 8)),
            dy=_signed16(b[4] | (b[5] << 8)),
            status=m,
            lifted=bool(m & R.LIFT_STAT),
            moved=bool(m & R.MOT),
            overflow=False,  # the chip has no overflow flag: poll before 32767 counts
            quality=b[6],
        )

    def read_all_registers(self) -> tuple[Motion, dict[str, int]]:
        """Every readable register in one frame (address order) and the Motion it cleared."""
        rx = self._xfer(self._dump_tx)
        self._in_burst = False
        values = {n: rx[i][0] for n, i in zip(self._dump_names, self._dump_idx, strict=True)}
        m = values["Motion"]
        motion = Motion(
            dx=_signed16(values["Delta_X_L"] | (values["Delta_X_H"] << 8)),
            dy=_signed16(values["Delta_Y_L"] | (values["Delta_Y_H"] << 8)),
            status=m,
            lifted=bool(m & R.LIFT_STAT),
            moved=bool(m & R.MOT),
            overflow=False,
            quality=values["SQUAL"],
        )
        return motion, values

    # --- resolution -----------------------------------------------------------------------

    def cpi_problem(self, cpi: object) -> str | None:
        return self.info.cpi.problem(cpi, self.info.title)

    def _check_cpi(self, cpi: int) -> None:
        problem = self.cpi_problem(cpi)
        if problem:
            raise InvalidCpiError(problem)

    def get_cpi(self) -> tuple[int, int]:
        enc = self.regs.cpi
        names = ["Config2", *enc.registers, *enc.x_registers]
        vals = self.read_registers(names)
        n = len(enc.registers)

        def value(bs: list[int]) -> int:
            v = 0
            for byte in bs:
                v = (v << 8) | byte
            return v

        y = enc.decode(value(vals[1 : 1 + n]))
        x = enc.decode(value(vals[1 + n :])) if vals[0] & R.CONFIG2_RPT_MOD else y
        return x, y

    def set_cpi(self, cpi: int, on_drain: Callable[[Motion], None] | None = None) -> None:
        """Both axes (Config2's Rpt_Mod off), high byte first [QMK], verified by reading back.

        With ``on_drain``: one chip-select frame (the burst cannot share one with a write)
        reads Motion, which freezes the counts into the delta registers and clears the
        counters [DS3360 Motion], writes the resolution right after it (tSRW), then reads
        the frozen deltas and SQUAL: the counts made at the old CPI are the deltas, and only
        the Motion read's data byte and tSRW (~25 us) lie between the freeze and the write
        (reading the deltas before the write would leave their 4 x 180 us). Assumed, as no
        datasheet says otherwise: a write between the Motion read and the delta reads
        leaves the frozen deltas alone (only a second Motion read loses them). The drained
        :class:`Motion` (old CPI) goes to ``on_drain`` before the read-back.
        """
        self._check_cpi(cpi)
        enc = self.regs.cpi
        data = enc.to_bytes(enc.encode(cpi))
        writes = [("w", n, v) for n, v in zip(enc.registers, data, strict=True)]
        if on_drain is None:
            self._xfer(self._frame(writes)[0])
        else:
            names = ["Motion", "Delta_X_L", "Delta_X_H", "Delta_Y_L", "Delta_Y_H", "SQUAL"]
            segs, idx = self._frame([("r", "Motion"), *writes, *(("r", n) for n in names[1:])])
            rx = self._xfer(segs)
            self._in_burst = False  # [DS3360 sec. 4 step 7]
            v = dict(zip(names, (rx[i][0] for i in idx), strict=True))
            m = v["Motion"]
            on_drain(
                Motion(
                    dx=_signed16(v["Delta_X_L"] | (v["Delta_X_H"] << 8)),
                    dy=_signed16(v["Delta_Y_L"] | (v["Delta_Y_H"] << 8)),
                    status=m,
                    lifted=bool(m & R.LIFT_STAT),
                    moved=bool(m & R.MOT),
                    overflow=False,
                    quality=v["SQUAL"],
                )
            )
        got = self.get_cpi()
        if got != (cpi, cpi):
            raise SensorError(
                f"{self.name}: the resolution reads back {got[0]}/{got[1]} CPI (x/y) after "
                f"setting {cpi}: the {self.info.title} did not take it; check the wiring, and "
                "for a PMW3389 the resolution encoding (driver option resolution_offset)"
            )

    # --- identity -------------------------------------------------------------------------

    def check_product_id(self) -> None:
        """ProductIdError unless Product_ID and Inverse_Product_ID are the expected pair."""
        pid, inv = self.read_registers(["Product_ID", "Inverse_Product_ID"])
        want = self.product_id
        if pid == want and inv == want ^ 0xFF:
            return
        what = (
            f"{self.name}: Product_ID reads {pid:#04x} and Inverse_Product_ID {inv:#04x}; "
            f"a {self.info.title} answers {want:#04x} and {want ^ 0xFF:#04x}. "
        )
        if pid in (0x00, 0xFF) and inv in (0x00, 0xFF):
            why = (
                "MISO reads all zeros or ones: nothing answers. Check the wiring (MISO, MOSI, "
                "SCLK, NCS on this chip select), the supply (breakouts take 3.3-5 V, the chip "
                "runs at 1.8-2.1 V) and that SPI runs in mode 3 (CPOL=1, CPHA=1) at <= 2 MHz. "
            )
        elif pid ^ inv == 0xFF:
            why = (
                f"A chip answers consistently with id {pid:#04x} (PMW3360: 0x42, PMW3389: "
                "0x47 per teamspatzenhirn/nRF, 0x42 per QMK): check the 'chips' entry of this "
                "device. "
            )
        else:
            why = (
                "The two ids disagree: bits are corrupted on the bus. Check SPI mode 3, a "
                "clock <= 2 MHz, the wiring and the ground. "
            )
        raise ProductIdError(
            what + why + f"If your chip really reports {pid:#04x}, set the driver option "
            f"product_id={pid:#04x} for this device."
        )

    # --- firmware (SROM) ------------------------------------------------------------------

    def check_firmware(self, words: Sequence[int]) -> None:
        """FirmwareError unless ``words`` are SROM bytes of the expected length."""
        if words is None or len(words) == 0:
            raise FirmwareError(f"the {self.info.title} SROM is empty")
        bad = [
            w for w in words if isinstance(w, bool) or not isinstance(w, int) or not 0 <= w <= 255
        ]
        if bad:
            raise FirmwareError(f"SROM bytes must be 0..255, got {bad[0]!r}")
        if self.srom_length is not None and len(words) != self.srom_length:
            raise FirmwareError(
                f"the SROM has {len(words)} bytes; a PixArt {self.info.title} SROM has "
                f"{self.srom_length} (QMK's PMW33XX_FIRMWARE_LENGTH): is it the right file? "
                "(driver option srom_length overrides the check)"
            )

    def load_firmware(self, words: Sequence[int]) -> None:
        """SROM download [DS3360 sec. 5] and its checks: SROM_ID, then the CRC self test.

        The self test resets the registers to their defaults [DS3360 SROM_Enable]: set the
        resolution after this.
        """
        self.check_firmware(words)
        a = self.regs.addresses
        self.write_registers([("Config2", R.CONFIG2_WIRED), ("SROM_Enable", R.SROM_INIT)])
        self._sleep(R.T_SROM_INIT_S)
        self.write_register("SROM_Enable", R.SROM_START)
        segs = [([a["SROM_Load_Burst"] | R.WRITE_FLAG], R.T_SROM_BYTE_US)]
        segs += [([int(b)], R.T_SROM_BYTE_US) for b in words[:-1]]
        segs.append(([int(words[-1])], R.T_SROM_END_US))
        self._xfer(segs)
        self._in_burst = False
        version = self.read_register("SROM_ID")  # the first access after the upload [step 7]
        if version == 0:
            raise FirmwareError(
                f"{self.name}: SROM_ID reads 0x00 after the upload: the SROM does not run. "
                f"Is it the {self.info.title}'s SROM? Check the wiring and a clock <= 2 MHz, "
                "then initialise again"
            )
        if self.srom_id is not None and version != self.srom_id:
            raise FirmwareError(
                f"{self.name}: SROM_ID reads {version:#04x}, expected {self.srom_id:#04x} "
                "(driver option srom_id): another SROM version was uploaded"
            )
        self.write_register("Config2", R.CONFIG2_WIRED)
        if self.check_crc:
            self.write_register("SROM_Enable", R.SROM_CRC)
            self._sleep(R.T_CRC_S)
            hi, lo = self.read_registers(["Data_Out_Upper", "Data_Out_Lower"])
            crc = (hi << 8) | lo
            if crc != R.SROM_CRC_PASS:
                raise FirmwareError(
                    f"{self.name}: the SROM CRC self test answers {crc:#06x}, not "
                    f"{R.SROM_CRC_PASS:#06x}: the SROM in the chip is damaged or not the one "
                    f"for the {self.info.title}. Check the file, the wiring and the SPI clock, "
                    "then initialise again"
                )
            self.write_register("Config2", R.CONFIG2_WIRED)  # the self test reset it
        self.srom_version = version

    # --- bring-up -------------------------------------------------------------------------

    def initialise(self, cpi: int, firmware: Sequence[int] | None = None) -> None:
        """Power-up sequence [DS3360 sec. 7]: reset, wait 50 ms, read Motion and the deltas
        once, product id, SROM download + checks (when given), Config2 (wired, no rest
        mode), resolution, one motion read (clean counters)."""
        self._check_cpi(cpi)
        if firmware is not None:
            self.check_firmware(firmware)
        self._in_burst = False
        self.write_register("Power_Up_Reset", R.POWER_UP_RESET_VALUE)
        self._sleep(R.T_RESET_S)
        self.read_registers(["Motion", "Delta_X_L", "Delta_X_H", "Delta_Y_L", "Delta_Y_H"])
        self.check_product_id()
        if firmware is not None:
            self.load_firmware(firmware)
        self.write_register("Config2", R.CONFIG2_WIRED)
        self.set_cpi(cpi)
        self.read_motion()


class PMW3360(PMW33xx):
    """PixArt PMW3360: 100..12000 CPI in steps of 100 (Config1), 250 ips."""

    regs = R.PMW3360
    info = PMW3360_INFO


class PMW3389(PMW33xx):
    """PixArt PMW3389: 50..16000 CPI in steps of 50 (Resolution_H/L), 400 ips.

    Extra option ``resolution_offset``: 1 (default, QMK: register = cpi/50 - 1) or 0
    (teamspatzenhirn: register = cpi/50). Product id 0x47 by default (teamspatzenhirn, nRF;
    QMK's table says 0x42: option ``product_id=0x42``).
    """

    info = PMW3389_INFO

    def __init__(self, bus, name: str = "pmw3389", *, resolution_offset: int = 1, **options):
        self.regs = R.pmw3389_regs(resolution_offset)
        super().__init__(bus, name, **options)


@dataclass(frozen=True)
class PollBudget:
    """What one sensor's motion burst costs at ``rate_hz`` (see docs/sensors.md)."""

    chip: str
    rate_hz: float
    cpi: int
    counts_per_poll: float  # at the chip's top speed
    headroom: float  # 32767 / counts_per_poll: > 1 = the 16-bit counters do not wrap
    min_rate_hz: float  # the slowest poll that keeps counts_per_poll <= 32767
    hold_us: float  # chip select held per burst: tSRAD_MOTBR + the bytes at spi_hz
    delay_share: float  # tSRAD_MOTBR / period
    hold_share: float  # hold_us / period


def poll_budget(
    info: ChipInfo,
    rate_hz: float,
    cpi: int | None = None,
    spi_hz: int | None = None,
    burst_length: int = R.BURST_LENGTH,
) -> PollBudget:
    """Counts per poll at the chip's top speed and CPI, and the bus time of one burst."""
    cpi = info.cpi.max if cpi is None else cpi
    spi_hz = info.max_spi_hz if spi_hz is None else spi_hz
    rate = info.max_speed_mps / INCH_M * cpi
    limit = (1 << (info.counter_bits - 1)) - 1
    counts = rate / rate_hz
    hold = R.T_SRAD_MOTBR_US + (1 + burst_length) * 8 / spi_hz * 1e6
    period_us = 1e6 / rate_hz
    return PollBudget(
        chip=info.chip,
        rate_hz=rate_hz,
        cpi=cpi,
        counts_per_poll=counts,
        headroom=limit / counts,
        min_rate_hz=rate / limit,
        hold_us=hold,
        delay_share=R.T_SRAD_MOTBR_US / period_us,
        hold_share=hold / period_us,
    )
