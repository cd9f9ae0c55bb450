"""The interface every sensor driver offers: what the poller, the agent and the node call.

No ROS here. Each chip family lives in a subpackage (``pln2033``, ``pmw33xx``, ``pmw3901``,
``otos``) and registers itself in :mod:`pln2033.chips`.
docs/sensors.md says which source each chip's register facts come from.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import NamedTuple, Protocol, runtime_checkable

INCH_M = 0.0254
"""One inch in metres: counts / cpi * INCH_M = metres."""

QUALITY_NONE = -1
"""``Motion.quality`` of a chip that has no surface-quality figure."""


class Motion(NamedTuple):
    """One displacement read: counts since the previous read, sensor frame.

    (A NamedTuple: it is built once per 1 kHz poll, and that is cheap.)

    ``dx`` is along the sensor's X axis (robot's right), ``dy`` along its Y
    axis (robot's forward), both signed counts. ``quality`` is the chip's
    surface-quality figure of this read (SQUAL 0..255 on the PixArt chips),
    :data:`QUALITY_NONE` where the chip has none.
    """

    dx: int
    dy: int
    status: int
    lifted: bool
    moved: bool
    overflow: bool
    quality: int = QUALITY_NONE


NO_MOTION = Motion(0, 0, 0, False, False, False)
"""What a register dump that leaves the counters alone hands back."""


@dataclass(frozen=True)
class CpiRange:
    """The resolutions a chip can be set to: ``min..max`` in steps of ``step`` (counts per inch)."""

    min: int
    max: int
    step: int

    def __post_init__(self) -> None:
        if not (0 < self.min <= self.max and self.step > 0):
            raise ValueError(f"empty CPI range {self.min}..{self.max} step {self.step}")

    @property
    def fixed(self) -> bool:
        """The chip's resolution cannot be set (optical flow: it follows the height)."""
        return self.min == self.max

    @property
    def values(self) -> range:
        return range(self.min, self.max + 1, self.step)

    def describe(self) -> str:
        if self.fixed:
            return f"fixed at {self.min}"
        return f"{self.min}..{self.max} in steps of {self.step}"

    def problem(self, cpi: object, chip: str = "the sensor") -> str | None:
        """Why ``cpi`` cannot be set on ``chip``, or None when it can."""
        allowed = f"{chip} allows {self.describe()}"
        if isinstance(cpi, bool) or not isinstance(cpi, int):
            return f"CPI must be an integer, got {cpi!r} ({allowed})"
        if not self.min <= cpi <= self.max:
            return f"CPI {cpi} is out of range ({allowed})"
        if (cpi - self.min) % self.step:
            return f"CPI {cpi} is not supported by the sensor's encoding ({allowed})"
        return None


@dataclass(frozen=True)
class ChipInfo:
    """What the rest of the project needs to know about one chip type."""

    chip: str  # registry key, e.g. "pmw3360"
    title: str  # e.g. "PixArt PMW3360"
    bus: str  # "spi" | "i2c"
    cpi: CpiRange
    cpi_default: int
    spi_mode: int = 0  # 0..3 (SPI chips)
    max_spi_hz: int = 2_000_000
    counter_bits: int = 16
    quality_name: str = ""  # e.g. "SQUAL"; "" = the chip has no quality figure
    quality_threshold: int = 0  # a read with 0 <= quality < this is treated like a lift
    #: a read below the quality threshold still carries real motion (the chip's own fusion
    #: keeps counting through it): flagged low quality, but no gap for the lift estimate
    poor_polls_carry_motion: bool = False
    max_speed_mps: float = 0.0  # the chip's tracking limit (m/s)
    firmware: str = ""  # "patch" | "srom" | "" = takes none
    source: str = ""  # where the register facts come from (one line; details in docs/sensors.md)
    #: the fixed register dump of a chip whose dump has its own message fields (the PLN2033's
    #: 13 in SensorSettings); () = the dump names its registers (register_names)
    registers: tuple[str, ...] = ()
    #: (what it means, mask) of each known bit of the chip's status register, for display
    status_bits: tuple[tuple[str, int], ...] = ()

    def low_quality(self, quality: int) -> bool:
        """True for a read whose surface quality is below the chip's threshold."""
        return 0 <= quality < self.quality_threshold


@runtime_checkable
class SensorDriver(Protocol):
    """One sensor on one bus address. Every method raises a :class:`~pln2033.errors.SensorError`
    subclass whose message says what to do."""

    info: ChipInfo
    name: str  # the device path, used in messages

    def initialise(self, cpi: int, firmware: Sequence[int] | None = None) -> None:
        """Reset, identify, upload and verify ``firmware`` when given, power up, set ``cpi``,
        and read the counters once so the next read starts clean."""
        ...

    def read_motion(self) -> Motion:
        """One motion read (the chip's burst where it has one); clears the chip's counters."""
        ...

    def get_cpi(self) -> tuple[int, int]:
        """(x, y) counts per inch read back from the chip (fixed chips: the effective value)."""
        ...

    def set_cpi(self, cpi: int, on_drain: Callable[[Motion], None] | None = None) -> None:
        """Set both axes; InvalidCpiError outside :attr:`ChipInfo.cpi`; verified by reading back.
        ``on_drain`` gets the counts made at the old CPI, drained with the write (a chip whose
        CPI cannot change calls it never: its counts keep their scale)."""
        ...

    def cpi_problem(self, cpi: object) -> str | None:
        """Why ``cpi`` cannot be set on this chip, or None."""
        ...

    def read_all_registers(self) -> tuple[Motion, dict[str, int]]:
        """The register dump (name -> value, the chip's order) and the Motion that reading
        cleared: the caller adds it to its sums, so a dump loses no count."""
        ...

    def check_firmware(self, words: Sequence[int]) -> None:
        """FirmwareError unless ``words`` could be uploaded to this chip."""
        ...

    def load_firmware(self, words: Sequence[int]) -> None:
        """Upload ``words`` (patch code, SROM) and verify it."""
        ...
