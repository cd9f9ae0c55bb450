"""The PLN2033 register map and command format as data.

The defaults live in ``default_regmap.yaml`` next to this module; every value
in it is an assumption (the datasheet is not public; docs/sensors.md, "PLN2033", lists
each with its source and what a wrong one looks like on a board) and a user overrides any
part with a YAML file of the same layout. Driver and emulator both read the
same :class:`RegisterMap`, so they always speak the same bytes.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

import yaml

from ..errors import RegisterMapError

#: The 13 registers in the order of the seed (and of SensorSettings.msg).
REGISTER_NAMES: tuple[str, ...] = (
    "status",
    "delta_x_disp",
    "delta_y_disp",
    "command_high",
    "command_low",
    "memory_pointer",
    "memory_data",
    "mode_control",
    "power_control",
    "mode_status",
    "system_control",
    "miscellaneous",
    "interrupt_output",
)

_COMMANDS = ("set_x_cpi", "set_y_cpi", "get_x_cpi", "get_y_cpi")
_STATUS_BITS = ("motion", "lift", "overflow_x", "overflow_y", "reserved")


def _default_dict() -> dict[str, Any]:
    text = resources.files(__package__).joinpath("default_regmap.yaml").read_text()
    return yaml.safe_load(text)


def _merge(base: dict[str, Any], override: dict[str, Any], path: str = "") -> dict[str, Any]:
    """Return ``base`` updated by ``override``; unknown keys are an error (typos)."""
    out = copy.deepcopy(base)
    for key, value in override.items():
        where = f"{path}{key}"
        if key not in base:
            raise RegisterMapError(f"unknown key '{where}' in register map; known: {sorted(base)}")
        if isinstance(base[key], dict):
            if not isinstance(value, dict):
                raise RegisterMapError(f"'{where}' must be a mapping, got {value!r}")
            out[key] = _merge(base[key], value, where + ".")
        else:
            out[key] = value
    return out


def _u16(value: Any, where: str, limit: int = 0xFFFF) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= limit:
        raise RegisterMapError(f"'{where}' must be an integer 0..{limit:#x}, got {value!r}")
    return value


@dataclass(frozen=True)
class RegisterMap:
    """Addresses, frame format, status bits, commands and CPI encoding."""

    addresses: dict[str, int]
    write_flag: int
    address_mask: int
    status_motion: int
    status_lift: int
    status_overflow_x: int
    status_overflow_y: int
    status_reserved: int
    commands: dict[str, int]
    cpi_min: int
    cpi_max: int
    cpi_step: int
    cpi_default: int
    power_down_bit: int
    soft_reset_bit: int
    patch_enable_bit: int
    memory_words: int
    patch_start: int
    presence_pattern: int

    @classmethod
    def default(cls) -> RegisterMap:
        return cls.from_dict({})

    @classmethod
    def load(cls, path: str | Path) -> RegisterMap:
        """Defaults overridden by the YAML file at ``path``."""
        try:
            text = Path(path).read_text()
        except OSError as exc:
            raise RegisterMapError(f"cannot read register map {path}: {exc.strerror}") from exc
        try:
            data = yaml.safe_load(text) or {}
        except yaml.YAMLError as exc:  # one line: what and where (the full text spans 5)
            mark = getattr(exc, "problem_mark", None)
            where = f" (line {mark.line + 1}, column {mark.column + 1})" if mark else ""
            what = getattr(exc, "problem", None) or type(exc).__name__
            raise RegisterMapError(f"register map {path} is not valid YAML: {what}{where}") from exc
        except RecursionError:  # the parser recurses per nesting level
            raise RegisterMapError(f"register map {path} is nested too deeply") from None
        if not isinstance(data, dict):
            raise RegisterMapError(f"register map {path} must be a YAML mapping")
        try:
            return cls.from_dict(data)
        except RegisterMapError as exc:
            raise RegisterMapError(f"register map {path}: {exc}") from None

    @classmethod
    def from_dict(cls, override: dict[str, Any]) -> RegisterMap:
        d = _merge(_default_dict(), override)
        regs = d["registers"]
        mask = _u16(d["frame"]["address_mask"], "frame.address_mask", 0xFF)
        addresses = {name: _u16(regs[name], f"registers.{name}", mask) for name in REGISTER_NAMES}
        if len(set(addresses.values())) != len(addresses):
            raise RegisterMapError(f"two registers share an address: {addresses}")
        write_flag = _u16(d["frame"]["write_flag"], "frame.write_flag", 0xFF)
        if not write_flag or write_flag & mask:
            raise RegisterMapError(
                f"'frame.write_flag' ({write_flag:#04x}) must be a non-zero bit outside "
                f"'frame.address_mask' ({mask:#04x}), or reads and writes are confused"
            )
        cpi = d["cpi"]
        cpi_min, cpi_max, step = (_u16(cpi[k], f"cpi.{k}") for k in ("min", "max", "step"))
        if not (0 < cpi_min <= cpi_max and step > 0):
            raise RegisterMapError(f"cpi range is empty: min={cpi_min} max={cpi_max} step={step}")
        if cpi_min % step:
            raise RegisterMapError(
                f"'cpi.min' ({cpi_min}) must be a multiple of 'cpi.step' ({step}): "
                "the sensor's code is cpi / step"
            )
        status = d["status_bits"]
        regmap = cls(
            addresses=addresses,
            write_flag=write_flag,
            address_mask=mask,
            status_motion=_u16(status["motion"], "status_bits.motion"),
            status_lift=_u16(status["lift"], "status_bits.lift"),
            status_overflow_x=_u16(status["overflow_x"], "status_bits.overflow_x"),
            status_overflow_y=_u16(status["overflow_y"], "status_bits.overflow_y"),
            status_reserved=_u16(status["reserved"], "status_bits.reserved"),
            commands={c: _u16(d["commands"][c], f"commands.{c}") for c in _COMMANDS},
            cpi_min=cpi_min,
            cpi_max=cpi_max,
            cpi_step=step,
            cpi_default=_u16(cpi["default"], "cpi.default"),
            power_down_bit=_u16(d["power_control"]["power_down"], "power_control.power_down"),
            soft_reset_bit=_u16(d["system_control"]["soft_reset"], "system_control.soft_reset"),
            patch_enable_bit=_u16(
                d["system_control"]["patch_enable"], "system_control.patch_enable"
            ),
            memory_words=_u16(d["memory"]["words"], "memory.words"),
            patch_start=_u16(d["memory"]["patch_start"], "memory.patch_start"),
            presence_pattern=_u16(d["presence_check"]["pattern"], "presence_check.pattern"),
        )
        problem = regmap.cpi_problem(regmap.cpi_default)
        if problem:
            raise RegisterMapError(f"'cpi.default' is not a valid resolution: {problem}")
        return regmap

    # --- the CPI encoding -------------------------------------------------------

    def cpi_problem(self, cpi: object) -> str | None:
        """Why ``cpi`` cannot be set, or None when it can."""
        allowed = f"allowed: {self.cpi_min}..{self.cpi_max} in steps of {self.cpi_step}"
        if isinstance(cpi, bool) or not isinstance(cpi, int):
            return f"CPI must be an integer, got {cpi!r} ({allowed})"
        if not self.cpi_min <= cpi <= self.cpi_max:
            return f"CPI {cpi} is out of range ({allowed})"
        if cpi % self.cpi_step:
            return f"CPI {cpi} is not supported by the sensor's encoding ({allowed})"
        return None

    def encode_cpi(self, cpi: int) -> int:
        return cpi // self.cpi_step

    def decode_cpi(self, code: int) -> int:
        return code * self.cpi_step

    @property
    def allowed_cpi(self) -> range:
        return range(self.cpi_min, self.cpi_max + 1, self.cpi_step)
