"""The PLN2033 driver: registers, displacement, CPI, power, reset, patch code.

No ROS here. The driver talks to any :class:`~pln2033.bus.SpiBus`; it speaks
the frame format of a :class:`~pln2033.pln2033.regmap.RegisterMap`.

Counter semantics (what the emulator implements and the node relies on):
reading the status register latches the sensor's X/Y counters into the
delta registers and clears the counters; reading a delta register returns
the latched value and clears it. So a displacement read is always status,
delta X, delta Y in one transfer (:meth:`PLN2033.read_motion`), and any
other status read (a settings read) must hand its displacement on to the
caller -- :meth:`PLN2033.read_all_registers` does, so no count is lost.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path

from ..bus import SpiBus
from ..errors import (
    InvalidCpiError,
    PatchError,
    SensorError,
    SensorNotRespondingError,
    SpiError,
)
from ..firmware import read_firmware_bytes
from ..sensor import INCH_M, ChipInfo, CpiRange, Motion
from .regmap import REGISTER_NAMES, RegisterMap

__all__ = [
    "INCH_M",
    "INFO",
    "PLN2033",
    "Motion",
    "pln2033_info",
    "read_patch_file",
]


def pln2033_info(regmap: RegisterMap) -> ChipInfo:
    """The PLN2033's :class:`ChipInfo` under ``regmap`` (its CPI range is part of the map)."""
    return ChipInfo(
        chip="pln2033",
        title="Philips PLN2033",
        bus="spi",
        cpi=CpiRange(regmap.cpi_min, regmap.cpi_max, regmap.cpi_step),
        cpi_default=regmap.cpi_default,
        spi_mode=1,
        max_spi_hz=8_000_000,
        max_speed_mps=0.0,  # not published
        firmware="patch",
        source="assumed register map (no public datasheet): docs/pln2033.md",
        registers=REGISTER_NAMES,
        status_bits=(
            ("motion", regmap.status_motion),
            ("lift", regmap.status_lift),
            ("overflow X", regmap.status_overflow_x),
            ("overflow Y", regmap.status_overflow_y),
            # a chip select with no sensor reads all ones
            ("reserved (no sensor answering?)", regmap.status_reserved),
        ),
    )


def _signed16(value: int) -> int:
    return value - 0x10000 if value & 0x8000 else value


class PLN2033:
    """One PLN2033 sensor on one chip select (a :class:`~pln2033.sensor.SensorDriver`)."""

    def __init__(self, bus: SpiBus, regmap: RegisterMap | None = None, name: str = "pln2033"):
        self.bus = bus
        self.map = regmap or RegisterMap.default()
        self.name = name
        self.info = pln2033_info(self.map)
        m = self.map
        a = m.addresses
        # The motion burst is built once: it runs 1000 times a second.
        self._motion_tx = [a["status"], 0, 0, a["delta_x_disp"], 0, 0, a["delta_y_disp"], 0, 0]
        self._all_tx: list[int] = []
        for reg in REGISTER_NAMES:
            self._all_tx += [a[reg], 0, 0]
        self._overflow_mask = m.status_overflow_x | m.status_overflow_y

    # --- raw register access ------------------------------------------------------

    def _xfer(self, tx: list[int]) -> list[int]:
        rx = self.bus.xfer2(tx)
        if len(rx) != len(tx):
            raise SpiError(f"{self.name}: sent {len(tx)} bytes, received {len(rx)}")
        return rx

    def read_register(self, name: str) -> int:
        """Read one 16-bit register by name (see REGISTER_NAMES).

        Reading ``status`` or a delta register clears counters: use
        :meth:`read_motion` or :meth:`read_all_registers` for those.
        """
        rx = self._xfer([self.map.addresses[name], 0, 0])
        return (rx[1] << 8) | rx[2]

    def write_register(self, name: str, value: int) -> None:
        if not 0 <= value <= 0xFFFF:
            raise ValueError(f"register value {value} does not fit 16 bits")
        self._xfer([self.map.addresses[name] | self.map.write_flag, value >> 8, value & 0xFF])

    # --- displacement ---------------------------------------------------------------

    def _decode_status(self, status: int) -> None:
        if status & self.map.status_reserved:
            raise SensorNotRespondingError(
                f"{self.name}: status register reads {status:#06x} (reserved bits set): "
                "no PLN2033 is answering; check wiring, chip select and 3.3 V supply"
            )

    @property
    def motion_tx(self) -> list[int]:
        """The 9 bytes of the motion burst (status, delta X, delta Y), built once."""
        return self._motion_tx

    def read_motion(self) -> Motion:
        """Status, delta X and delta Y in one transfer; clears the counters."""
        return self.decode_motion(self.bus.xfer2(self._motion_tx))

    def decode_motion(self, rx: list[int]) -> Motion:
        """The :class:`Motion` in the bytes a motion burst clocked in."""
        if len(rx) != 9:
            raise SpiError(f"{self.name}: sent 9 bytes, received {len(rx)}")
        status = (rx[1] << 8) | rx[2]
        if status & self.map.status_reserved:
            self._decode_status(status)
        m = self.map
        return Motion(
            dx=_signed16((rx[4] << 8) | rx[5]),
            dy=_signed16((rx[7] << 8) | rx[8]),
            status=status,
            lifted=bool(status & m.status_lift),
            moved=bool(status & m.status_motion),
            overflow=bool(status & self._overflow_mask),
        )

    @property
    def unusual_status_bits(self) -> int:
        """Status bits a poll must look at closely: reserved, lift, overflow."""
        m = self.map
        return m.status_reserved | m.status_lift | self._overflow_mask

    def read_all_registers(self) -> tuple[Motion, dict[str, int]]:
        """All 13 registers in one transfer, plus the displacement that read cleared.

        The caller must add the returned :class:`Motion` to its sums: the
        status read cleared the sensor's counters.
        """
        rx = self._xfer(self._all_tx)
        values = {reg: (rx[3 * i + 1] << 8) | rx[3 * i + 2] for i, reg in enumerate(REGISTER_NAMES)}
        status = values["status"]
        self._decode_status(status)
        m = self.map
        motion = Motion(
            dx=_signed16(values["delta_x_disp"]),
            dy=_signed16(values["delta_y_disp"]),
            status=status,
            lifted=bool(status & m.status_lift),
            moved=bool(status & m.status_motion),
            overflow=bool(status & self._overflow_mask),
        )
        return motion, values

    # --- resolution -------------------------------------------------------------------

    def _command(self, opcode: str, argument: int = 0) -> int:
        self.write_register("command_low", argument)
        self.write_register("command_high", self.map.commands[opcode])
        return self.read_register("command_low")

    def _check_cpi(self, cpi: int) -> None:
        problem = self.map.cpi_problem(cpi)
        if problem:
            raise InvalidCpiError(problem)

    def cpi_problem(self, cpi: object) -> str | None:
        return self.map.cpi_problem(cpi)

    def get_cpi(self) -> tuple[int, int]:
        return self.get_x_cpi(), self.get_y_cpi()

    def get_x_cpi(self) -> int:
        return self.map.decode_cpi(self._command("get_x_cpi"))

    def get_y_cpi(self) -> int:
        return self.map.decode_cpi(self._command("get_y_cpi"))

    def set_x_cpi(self, cpi: int) -> None:
        self._check_cpi(cpi)
        self._command("set_x_cpi", self.map.encode_cpi(cpi))
        self._verify_cpi("X", cpi, self.get_x_cpi())

    def set_y_cpi(self, cpi: int) -> None:
        self._check_cpi(cpi)
        self._command("set_y_cpi", self.map.encode_cpi(cpi))
        self._verify_cpi("Y", cpi, self.get_y_cpi())

    def set_cpi(self, cpi: int, on_drain: Callable[[Motion], None] | None = None) -> None:
        """Set X and Y to the same resolution (as the original did), verified by reading back.

        With ``on_drain`` the counters are drained in the same transfer as the two CPI
        writes (status, deltas, then the commands): no count can fall between the drain
        and the write, so every count the chip made at the old CPI goes to ``on_drain``
        (called before the read-back, so a failed verify loses none) and the next read
        holds only counts at the new one. Without it the counters are left alone.
        """
        self._check_cpi(cpi)
        if on_drain is None:
            self.set_x_cpi(cpi)
            self.set_y_cpi(cpi)
            return
        code = self.map.encode_cpi(cpi)
        rx = self._xfer(self._motion_tx + self._cpi_write_tx(code))
        on_drain(self.decode_motion(rx[:9]))
        self._verify_cpi("X", cpi, self.get_x_cpi())
        self._verify_cpi("Y", cpi, self.get_y_cpi())

    def _cpi_write_tx(self, code: int) -> list[int]:
        """The frames of set X then set Y to the encoded resolution ``code``."""
        a, w, c = self.map.addresses, self.map.write_flag, self.map.commands
        low = [a["command_low"] | w, code >> 8, code & 0xFF]
        tx: list[int] = []
        for op in ("set_x_cpi", "set_y_cpi"):
            tx += [*low, a["command_high"] | w, c[op] >> 8, c[op] & 0xFF]
        return tx

    def _verify_cpi(self, axis: str, wanted: int, got: int) -> None:
        if got != wanted:
            raise SensorError(f"{self.name}: {axis} resolution reads back {got} CPI, set {wanted}")

    # --- power, reset, presence ------------------------------------------------------

    def soft_reset(self) -> None:
        """Reset registers, DSP RAM and counters to their power-up state."""
        self.write_register("system_control", self.map.soft_reset_bit)

    def power_down(self) -> None:
        value = self.read_register("power_control")
        self.write_register("power_control", value | self.map.power_down_bit)

    def power_up(self) -> None:
        value = self.read_register("power_control")
        self.write_register("power_control", value & ~self.map.power_down_bit & 0xFFFF)

    def check_presence(self) -> None:
        """Write a pattern to the memory pointer and read it back.

        A missing, unpowered or miswired sensor reads back 0x0000 or 0xFFFF.
        """
        pattern = self.map.presence_pattern
        self.write_register("memory_pointer", pattern)
        got = self.read_register("memory_pointer")
        self.write_register("memory_pointer", 0)
        if got != pattern:
            raise SensorNotRespondingError(
                f"{self.name}: no PLN2033 answers (wrote {pattern:#06x} to the memory pointer, "
                f"read back {got:#06x}); check wiring (MISO/MOSI/SCLK/CS), the 3.3 V supply "
                "and that SPI runs in mode 1"
            )

    # --- vendor patch code -------------------------------------------------------------

    def load_patch(self, words: Sequence[int]) -> None:
        """Write the patch code into the DSP RAM, verify it, then enable it."""
        self.check_patch(words)
        self.write_register("memory_pointer", self.map.patch_start)
        for word in words:
            self.write_register("memory_data", word)
        self.verify_patch(words)
        value = self.read_register("system_control")
        self.write_register("system_control", value | self.map.patch_enable_bit)

    def check_firmware(self, words: Sequence[int]) -> None:
        """The PLN2033's firmware is its vendor patch code: :meth:`check_patch`."""
        self.check_patch(words)

    def load_firmware(self, words: Sequence[int]) -> None:
        self.load_patch(words)

    def verify_patch(self, words: Sequence[int]) -> None:
        """Read the DSP RAM back and compare it with ``words``."""
        self.check_patch(words)
        self.write_register("memory_pointer", self.map.patch_start)
        for i, word in enumerate(words):
            got = self.read_register("memory_data")
            if got != word:
                raise PatchError(
                    f"{self.name}: patch code verify failed at word {i} "
                    f"(address {self.map.patch_start + i:#06x}): wrote {word:#06x}, "
                    f"read {got:#06x}"
                )

    def check_patch(self, words: Sequence[int]) -> None:
        """PatchError unless ``words`` are 1..room 16-bit words."""
        room = self.map.memory_words - self.map.patch_start
        if not words:
            raise PatchError("the patch code is empty")
        if len(words) > room:
            raise PatchError(f"the patch code has {len(words)} words; the DSP RAM holds {room}")
        bad = [
            w
            for w in words
            if isinstance(w, bool) or not isinstance(w, int) or not 0 <= w <= 0xFFFF
        ]
        if bad:
            raise PatchError(f"patch words must be 16-bit, got {bad[0]!r}")

    # --- bring-up ---------------------------------------------------------------------------

    def initialise(self, cpi: int, firmware: Sequence[int] | None = None) -> None:
        """The initial configuration: reset, presence check, patch code (``firmware``), power up,
        CPI."""
        self._check_cpi(cpi)
        self.soft_reset()
        self.check_presence()
        if firmware is not None:
            self.load_patch(firmware)
        self.power_up()
        self.set_cpi(cpi)
        self.read_motion()  # start from clean counters


def read_patch_file(path: str | Path) -> list[int]:
    """Read the vendor patch code the user supplies (:func:`read_firmware_bytes`; the output
    of the original's arrayConverter). Bytes pair up big-endian into 16-bit RAM words.
    """
    data = read_firmware_bytes(path, "patch file", PatchError)
    if len(data) % 2:
        raise PatchError(
            f"patch file {Path(path)} has {len(data)} bytes; 16-bit words need an even count"
        )
    return [(data[i] << 8) | data[i + 1] for i in range(0, len(data), 2)]


INFO = pln2033_info(RegisterMap.default())
"""The PLN2033 under the default register map (a user's map may change its CPI range)."""
