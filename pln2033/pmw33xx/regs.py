"""PMW3360 / PMW3389 register facts as data (addresses, bits, defaults, timing, encodings).

Sources (docs/sensors.md has the full list and where they disagree):

- [DS3360] PixArt PMW3360DM-T2QU datasheet v1.50 (26 Sep 2016), mirrored in
  SunjunKim/PMW3360_Arduino: Datasheet/PMS0058-PMW3360DM-T2QU-DS-R1.50-26092016....pdf
  (register table sec. 10, descriptions sec. 11, burst sec. 4, SROM sec. 5, power up sec. 7,
  AC timing table).
- [QMK] qmk/qmk_firmware drivers/sensors/pmw3360.h, pmw3389.h, pmw3389.c, pmw33xx_common.c/h.
- [TSH] teamspatzenhirn/pmw3389_zephyr_driver drivers/sensor/pmw3389/pmw3389.c.
- [NRF] Nordic's Zephyr PMW3389 header (nRF Desktop style pmw3389.h: PMW3389_PRODUCT_ID 0x47).
- [MJK] mrjohnk/PMW3389DM "proper startup banner.txt": a real PMW3389's printout, Product_ID
  0x47, Inverse_Product_ID 0xB8, SROM_Version 0xE8.
- [ARD] SunjunKim/PMW3360_Arduino sketches (PMW3360DM-Burst/-Mouse.ino): ADNS-9800-era waits
  (tSRAD 35-100 us, writes 20 + 100 us apart), reported to work; not this project's figures.

No register here comes from the PMW3389 datasheet itself (not in the stored sources): the
PMW3389 map is QMK's (addresses as [NRF]'s), its timing is the PMW3360's (identical in [TSH]
and [NRF]).
"""

from __future__ import annotations

from dataclasses import dataclass, field

# --- the serial port [DS3360 sec. 3, AC table] ------------------------------------------------
WRITE_FLAG = 0x80  # address MSB = 1: write; 0: read
ADDRESS_MASK = 0x7F
SPI_MODE = 3  # CPOL=1, CPHA=1 [QMK PMW3389_SPI_MODE 3; TSH SPI_MODE_CPOL|SPI_MODE_CPHA]
MAX_SPI_HZ = 2_000_000  # fSCLK 2.0 MHz [DS3360 AC table]

# --- timing, microseconds [DS3360 Table 4 "AC Electrical Specifications", p. 15-16, re-read
# for issue 26; the same numbers in TSH and NRF for the PMW3389]. Each is a minimum between two
# SCLK edges, wherever chip select is (pln2033/pmw33xx/timing.py measures them so).
T_SRAD_US = 160  # read: last address bit (rising) -> first data bit (falling)
T_SRAD_MOTBR_US = 35  # the same for the motion burst
T_SWW_US = 180  # write: last bit of its data -> last bit of the NEXT write's first data byte
T_SWR_US = 180  # write: last bit of its data -> last bit of the next read's address byte
T_SRW_US = 20  # read: last bit of its data -> first bit of the next command's address
T_SRR_US = 20
T_BEXIT_US = 0.5  # NCS high after a motion burst (500 ns; Figure 22 draws >= 1 us for the SROM)
T_NCS_SCLK_US = 0.12  # NCS falling -> first SCLK (120 ns)
T_SCLK_NCS_WRITE_US = 35  # last SCLK of a write -> NCS rising ("for valid MOSI data transfer")
T_SROM_BYTE_US = 15  # address -> byte 1 and between SROM_Load_Burst bytes [DS3360 fig. 22]
T_SROM_END_US = 200  # last SROM byte -> next command ("soonest to read SROM_ID") [DS3360 fig. 22]
T_RESET_S = 0.050  # Power_Up_Reset -> next command [DS3360 sec. 7 step 4; tMOT-RST 50 ms]
T_SROM_INIT_S = 0.010  # SROM_Enable 0x1D -> 0x18 [DS3360 sec. 5 step 4, fig. 22]
T_CRC_S = 0.010  # SROM_Enable 0x15 -> Data_Out; SPI unused meanwhile [DS3360 SROM_Enable]

# --- command values ------------------------------------------------------------------------------
POWER_UP_RESET_VALUE = 0x5A  # [DS3360 Power_Up_Reset]
SHUTDOWN_VALUE = 0xB6  # [DS3360 Shutdown]
SROM_INIT = 0x1D  # SROM_Enable: initialise the download [DS3360 sec. 5 step 3]
SROM_START = 0x18  # SROM_Enable: start the download [sec. 5 step 5]
SROM_CRC = 0x15  # SROM_Enable: run the CRC self test [sec. 5, SROM_Enable]
SROM_CRC_PASS = 0xBEEF  # Data_Out_Upper 0xBE, Data_Out_Lower 0xEF [DS3360 Data_Out_Upper]
SROM_LENGTH = 4094  # bytes of a PixArt SROM file [QMK PMW3360_/PMW3389_FIRMWARE_LENGTH 4094]
CONFIG2_WIRED = 0x00  # Rest mode off, one CPI for X and Y [DS3360 sec. 5 step 8, Config2]

# --- Motion register bits [DS3360 Motion 0x02; QMK pmw33xx_report_t] -------------------------
MOT = 0x80  # motion since the last report
LIFT_STAT = 0x08  # 1 = chip lifted
OP_MODE_MASK = 0x06  # 00 run, 01/10/11 rest 1..3
FRAME_RDATA_1ST = 0x01
MOTION_RESET = 0x20  # reset value: bit 5 reads 1
OB_SROM_RUN = 0x40  # Observation bit 6: the SROM runs [DS3360 Observation]
CONFIG2_RPT_MOD = 0x04  # Config2 bit 2: X resolution from Config5 [DS3360 Config2]
CONFIG2_REST_EN = 0x20

BURST_LENGTH = 12  # bytes of the motion burst report [DS3360 sec. 4]
BURST_FIELDS = (
    "Motion",
    "Observation",
    "Delta_X_L",
    "Delta_X_H",
    "Delta_Y_L",
    "Delta_Y_H",
    "SQUAL",
    "Raw_Data_Sum",
    "Maximum_Raw_Data",
    "Minimum_Raw_Data",
    "Shutter_Upper",
    "Shutter_Lower",
)

SQUAL_MAX = 0x80  # [DS3360 SQUAL: "the maximum SQUAL register value is 0x80"]
MIN_SQ_RUN_DEFAULT = 0x10  # below this SQUAL the chip reports zero motion [DS3360 Min_SQ_Run]


@dataclass(frozen=True)
class CpiEncoding:
    """How a resolution register holds CPI: ``cpi = (value + offset) * step``.

    ``registers`` are the Y (or X and Y) resolution registers, high byte first;
    ``x_registers`` the X ones used when Config2's Rpt_Mod bit is set.
    """

    step: int
    offset: int
    min_cpi: int
    max_cpi: int
    registers: tuple[str, ...]
    x_registers: tuple[str, ...]

    def encode(self, cpi: int) -> int:
        return cpi // self.step - self.offset

    def decode(self, value: int) -> int:
        return (value + self.offset) * self.step

    def valid(self, value: int) -> bool:
        cpi = self.decode(value)
        return self.min_cpi <= cpi <= self.max_cpi

    def to_bytes(self, value: int) -> list[int]:
        n = len(self.registers)
        return [(value >> (8 * (n - 1 - i))) & 0xFF for i in range(n)]


@dataclass(frozen=True)
class ChipRegs:
    """One chip's register map: names -> addresses (the dump order), defaults, ids."""

    chip: str
    title: str
    product_id: int
    addresses: dict[str, int]
    defaults: dict[str, int]
    cpi: CpiEncoding
    dump: tuple[str, ...] = field(default=())

    def __getitem__(self, name: str) -> int:
        return self.addresses[name]


# Readable registers in address order; write-only and side-effect registers (SROM_Enable,
# Power_Up_Reset, Shutdown, Motion_Burst, SROM_Load_Burst, Raw_Data_Burst, Frame_Capture,
# Raw_Data_Grab) are not in the dump.
_COMMON = {
    "Product_ID": 0x00,
    "Revision_ID": 0x01,
    "Motion": 0x02,
    "Delta_X_L": 0x03,
    "Delta_X_H": 0x04,
    "Delta_Y_L": 0x05,
    "Delta_Y_H": 0x06,
    "SQUAL": 0x07,
    "Raw_Data_Sum": 0x08,
    "Maximum_Raw_Data": 0x09,
    "Minimum_Raw_Data": 0x0A,
    "Shutter_Lower": 0x0B,
    "Shutter_Upper": 0x0C,
    "Control": 0x0D,
}
_WRITE_ONLY = {
    "Frame_Capture": 0x12,
    "SROM_Enable": 0x13,
    "Raw_Data_Grab": 0x29,
    "Power_Up_Reset": 0x3A,
    "Shutdown": 0x3B,
    "Motion_Burst": 0x50,
    "SROM_Load_Burst": 0x62,
    "Raw_Data_Burst": 0x64,
}
_REST = {
    "Config2": 0x10,
    "Angle_Tune": 0x11,
    "Run_Downshift": 0x14,
    "Rest1_Rate_Lower": 0x15,
    "Rest1_Rate_Upper": 0x16,
    "Rest1_Downshift": 0x17,
    "Rest2_Rate_Lower": 0x18,
    "Rest2_Rate_Upper": 0x19,
    "Rest2_Downshift": 0x1A,
    "Rest3_Rate_Lower": 0x1B,
    "Rest3_Rate_Upper": 0x1C,
    "Observation": 0x24,
    "Data_Out_Lower": 0x25,
    "Data_Out_Upper": 0x26,
    "SROM_ID": 0x2A,
    "Min_SQ_Run": 0x2B,
    "Raw_Data_Threshold": 0x2C,
}

# Defaults from the PMW3360 register table [DS3360 sec. 10]; the emulators start there.
_DEFAULTS_3360 = {
    "Product_ID": 0x42,
    "Revision_ID": 0x01,
    "Motion": MOTION_RESET,
    "Shutter_Lower": 0x12,
    "Control": 0x02,
    "Config1": 0x31,  # 5000 cpi
    "Config2": 0x20,
    "Run_Downshift": 0x32,
    "Rest1_Downshift": 0x1F,
    "Rest2_Rate_Lower": 0x63,
    "Rest2_Downshift": 0xBC,
    "Rest3_Rate_Lower": 0xF3,
    "Rest3_Rate_Upper": 0x01,
    "Min_SQ_Run": MIN_SQ_RUN_DEFAULT,
    "Raw_Data_Threshold": 0x0A,
    "Config5": 0x31,
    "Inverse_Product_ID": 0xBD,
    "LiftCutoff_Tune_Timeout": 0x27,
    "LiftCutoff_Tune_Min_Length": 0x09,
    "Lift_Config": 0x02,
}

PMW3360 = ChipRegs(
    chip="pmw3360",
    title="PixArt PMW3360",
    product_id=0x42,  # [DS3360 Product_ID; QMK; SunjunKim]
    addresses={
        **_COMMON,
        "Config1": 0x0F,
        **_REST,
        "Config5": 0x2F,
        "Inverse_Product_ID": 0x3F,
        "LiftCutoff_Tune3": 0x41,
        "Angle_Snap": 0x42,
        "LiftCutoff_Tune1": 0x4A,
        "LiftCutoff_Tune_Timeout": 0x58,
        "LiftCutoff_Tune_Min_Length": 0x5A,
        "Lift_Config": 0x63,
        "LiftCutoff_Tune2": 0x65,
        **_WRITE_ONLY,
    },
    defaults=_DEFAULTS_3360,
    # Config1: 0x00 = 100 cpi .. 0x77 = 12000 cpi in steps of 100 [DS3360 Config1, Config5]
    cpi=CpiEncoding(100, 1, 100, 12000, ("Config1",), ("Config5",)),
)

# PMW3389: the PMW3360 layout with a 16-bit resolution (Resolution_L/H at 0x0E/0x0F, Config5
# split into L/H) and a few more registers [QMK pmw3389.h; NRF].
_DEFAULTS_3389 = {
    **{k: v for k, v in _DEFAULTS_3360.items() if k not in ("Config1", "Config5")},
    "Product_ID": 0x47,
    "Inverse_Product_ID": 0xB8,
    # Resolution reset value: assumed 5000 cpi like the PMW3360 (no source at hand).
    "Resolution_H": 0x00,
    "Resolution_L": 0x63,
    "Config5_H": 0x00,
    "Config5_L": 0x63,
}
_DEFAULTS_3389.pop("LiftCutoff_Tune_Timeout")
_DEFAULTS_3389.pop("LiftCutoff_Tune_Min_Length")

# [TSH Expected_Product_ID 0x47, inverse 0xB8; NRF; MJK a real chip's banner]. QMK's pmw3389.c
# signature {0x42, 0xBD, 0x04} is the PMW3360's (its own PMW3389 SROM starts 0x01, 0xE8, and
# MJK's chip reports SROM_Version 0xE8): driver option product_id=0x42 follows QMK anyway.
PMW3389_PRODUCT_ID = 0x47


def pmw3389_regs(resolution_offset: int = 1) -> ChipRegs:
    """The PMW3389 map with its resolution encoding ``cpi = (value + offset) * 50``.

    offset 1 (the default) is QMK's (pmw3389.c: ``(cpival + 1) * 50``, and the nRF/ZMK
    drivers'); offset 0 is teamspatzenhirn's (``resolution = cpi / 50``).
    """
    if resolution_offset not in (0, 1):
        raise ValueError(
            f"resolution_offset {resolution_offset!r}: 1 = QMK's (cpi/50 - 1), "
            "0 = teamspatzenhirn's (cpi/50)"
        )
    return ChipRegs(
        chip="pmw3389",
        title="PixArt PMW3389",
        product_id=PMW3389_PRODUCT_ID,
        addresses={
            **_COMMON,
            "Resolution_L": 0x0E,
            "Resolution_H": 0x0F,
            **_REST,
            "Control2": 0x2D,
            "Config5_L": 0x2E,
            "Config5_H": 0x2F,
            "Inverse_Product_ID": 0x3F,
            "LiftCutoff_Cal3": 0x41,
            "Angle_Snap": 0x42,
            "LiftCutoff_Cal1": 0x4A,
            "Lift_Config": 0x63,
            "LiftCutoff_Cal2": 0x65,
            "LiftCutoff_Cal_Timeout": 0x71,
            "LiftCutoff_Cal_Min_Length": 0x72,
            "PWM_Period_Cnt": 0x73,
            "PWM_Width_Cnt": 0x74,
            **_WRITE_ONLY,
        },
        defaults=_DEFAULTS_3389,
        cpi=CpiEncoding(
            50,
            resolution_offset,
            50,
            16000,
            ("Resolution_H", "Resolution_L"),
            ("Config5_H", "Config5_L"),
        ),
    )


PMW3389 = pmw3389_regs()


def dump_names(regs: ChipRegs) -> tuple[str, ...]:
    """The registers a dump reads, in address order (no write-only ones)."""
    names = [n for n in regs.addresses if n not in _WRITE_ONLY]
    return tuple(sorted(names, key=regs.addresses.__getitem__))


def crc16_ccitt(data: bytes | list[int], crc: int = 0xFFFF) -> int:
    """CRC-16/CCITT-FALSE: the EMULATORS' stand-in for the chip's SROM self test (not PixArt's).

    A real chip's self test answers :data:`SROM_CRC_PASS` for the SROM its datasheet lists;
    the emulators answer that for an intact image and this CRC otherwise.
    """
    for b in data:
        crc ^= b << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1021) & 0xFFFF if crc & 0x8000 else (crc << 1) & 0xFFFF
    return crc
