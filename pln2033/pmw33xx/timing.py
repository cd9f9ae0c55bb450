"""The PMW33xx serial-port timing as constraints between commands [DS3360 Table 4, sec. 3-5, 7].

Times are microseconds on the chip's own timeline (an edge of SCLK or NCS), so a gap is
measured from the end of one command to the start of the next whether or not chip select
rose between them: QMK's 35 us low + 145 us high after a write meets tSWW = 180 us as well
as 180 us kept low. :class:`Command` is one command's edges, :func:`gap_violation` names the
constraint a command breaks with respect to the one before it (None: none).

The reference points are the datasheet's: a byte starts with its first falling SCLK and
ends with its last rising SCLK; tSWW runs to the END of the next write's first data byte,
tSWR to the end of the next read's address byte, tSRW/tSRR to the START of the next address.
"""

from __future__ import annotations

from dataclasses import dataclass

from . import regs as R  # noqa: N812 (the register facts, short)

# names of the constraints, as counted in EmulatedPMW33xx.timing_errors
TSWW = "tSWW"
TSWR = "tSWR"
TSRW = "tSRW"
TSRR = "tSRR"
TSRAD = "tSRAD"
TSRAD_MOTBR = "tSRAD_MOTBR"
TBEXIT = "tBEXIT"
TNCS_SCLK = "tNCS-SCLK"
TSCLK_NCS_WRITE = "tSCLK-NCS(write)"
POWER_UP_WAIT = "power-up wait (50 ms)"
SROM_INIT_WAIT = "SROM_Enable 0x1D wait (10 ms)"
CRC_WAIT = "CRC self-test wait (10 ms)"
SROM_BYTE = "SROM byte gap (15 us)"
SROM_END_WAIT = "SROM end wait (200 us)"

#: float rounding on the timeline: a gap equal to its minimum keeps it
EPS_US = 1e-6

#: waits during which the chip ignores the bus: a write sent then is lost, not only counted
#: (NCS is ignored during reset, DS3360 sec. 7; "the SPI port should not be used" during the
#: CRC test, SROM_Enable)
BUS_IGNORED = frozenset({POWER_UP_WAIT, CRC_WAIT})


@dataclass(frozen=True)
class Command:
    """One command's SCLK edges (us): ``kind`` is "write", "read", "motion_burst" or
    "srom_burst"; ``wait_us``/``wait`` the extra wait it imposes on the next command."""

    kind: str
    start: float  # first falling SCLK of the address byte
    addr_end: float  # last rising SCLK of the address byte
    data1_end: float  # last rising SCLK of the first data byte (tSWW's far end)
    end: float  # last rising SCLK of the last byte
    wait_us: float = 0.0
    wait: str = ""

    @property
    def writes(self) -> bool:
        return self.kind in ("write", "srom_burst")


def short(gap_us: float, need_us: float) -> bool:
    """The gap is shorter than its minimum."""
    return gap_us < need_us - EPS_US


def wait_after(name: str | None, value: int) -> tuple[float, str]:
    """The wait a write of ``value`` to register ``name`` imposes on the next command."""
    if name == "Power_Up_Reset" and value == R.POWER_UP_RESET_VALUE:
        return R.T_RESET_S * 1e6, POWER_UP_WAIT
    if name == "SROM_Enable" and value == R.SROM_INIT:
        return R.T_SROM_INIT_S * 1e6, SROM_INIT_WAIT
    if name == "SROM_Enable" and value == R.SROM_CRC:
        return R.T_CRC_S * 1e6, CRC_WAIT
    return 0.0, ""


def gap_violation(prev: Command | None, nxt: Command, cs_high_us: float | None) -> str | None:
    """The constraint ``nxt`` breaks after ``prev``; ``cs_high_us`` is how long chip select
    was high between them (None: it stayed low)."""
    if prev is None:
        return None
    if prev.wait_us and short(nxt.start - prev.end, prev.wait_us):
        return prev.wait
    if prev.kind == "motion_burst":
        # the burst ends only with NCS high for tBEXIT [DS3360 sec. 4]; then no tSRR
        if cs_high_us is None or short(cs_high_us, R.T_BEXIT_US):
            return TBEXIT
        return None
    if prev.kind == "read":
        need, name = (R.T_SRW_US, TSRW) if nxt.writes else (R.T_SRR_US, TSRR)
        return name if short(nxt.start - prev.end, need) else None
    if prev.kind == "write":
        if nxt.writes:
            return TSWW if short(nxt.data1_end - prev.end, R.T_SWW_US) else None
        return TSWR if short(nxt.addr_end - prev.end, R.T_SWR_US) else None
    return None  # srom_burst: its own wait (200 us) above
