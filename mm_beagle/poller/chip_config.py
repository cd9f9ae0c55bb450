"""Which chip each device is, its driver options and its bus: the board side of issue 15.

The node's ``chips`` / ``chip_options`` parameters and the agent's ``--chips`` /
``--chip-options`` end here. No ROS, no numpy (the board's agent imports it).

``chip_options`` are ``key=value`` strings; each goes to every configured chip whose
driver takes that keyword (``height_m=0.08`` reaches the PMW3901/PAA5100 drivers,
``product_id=0x42`` every driver that checks a product id); ``CHIP.key=value``
(``pmw3389.product_id=0x42``) reaches only that chip's driver and wins over a plain
``key``. A key no configured chip's driver takes is a configuration error (exit 2), as
is a value the driver refuses.
Values: ``true``/``false``, integers (``0x47`` too), floats, comma-separated tuples
(``offset=0.05,0,0``), else the string.
"""

from __future__ import annotations

import inspect
from collections.abc import Sequence
from functools import cache

from pln2033 import chips as registry
from pln2033.sensor import ChipInfo

# constructor keywords that are not user options: the poller passes them, or they are objects
_NOT_OPTIONS = frozenset(("self", "bus", "name", "regmap", "sleep", "clock", "optics"))


def chips_help() -> str:
    """The allowed chip names, for parameter descriptions and errors."""
    return ", ".join(registry.chip_names())


def split_names(items: Sequence[str]) -> list[str]:
    """``["pmw3360,pln2033"]`` or ``["pmw3360", "pln2033"]`` -> ["pmw3360", "pln2033"]
    (a launch argument arrives as one string); empty entries dropped."""
    return [n.strip() for item in items for n in str(item).split(",") if n.strip()]


def parse_value(text: str) -> object:
    """``true``/``false``, an int (``0x47``), a float, ``a,b,c`` -> a tuple of those (the
    OTOS's ``offset=0.05,0,0``), else the string."""
    if "," in text:
        return tuple(parse_value(part) for part in text.split(","))
    low = text.strip().lower()
    if low in ("true", "false"):
        return low == "true"
    for conv in (lambda v: int(v, 0), float):
        try:
            return conv(text.strip())
        except ValueError:
            pass
    return text.strip()


def parse_chip_options(items: Sequence[str]) -> dict[str, object]:
    """``["height_m=0.08", "product_id=0x42"]`` -> {"height_m": 0.08, "product_id": 66}."""
    out: dict[str, object] = {}
    for item in items:
        if not item:
            continue
        key, sep, value = str(item).partition("=")
        key = key.strip()
        chip, dot, bare = key.rpartition(".")
        if not sep or not bare.isidentifier() or (dot and not chip):
            raise ValueError(
                f"chip option {item!r} is not key=value or CHIP.key=value "
                "(e.g. height_m=0.08, pmw3389.product_id=0x42)"
            )
        if dot and chip not in registry.chip_names():
            raise ValueError(f"chip option {item!r} names chip {chip!r}; allowed: {chips_help()}")
        if key in out:
            raise ValueError(f"chip option {key!r} is given twice")
        out[key] = parse_value(value)
    return out


def _driver_class(chip: str) -> type:
    return registry._load(registry._spec(chip).driver)


@cache
def option_names(chip: str) -> frozenset[str]:
    """The keywords ``chip``'s driver takes as options (its and its bases' ``__init__``)."""
    names: set[str] = set()
    for cls in _driver_class(chip).__mro__:
        init = cls.__dict__.get("__init__")
        if init is None:
            continue
        for p in inspect.signature(init).parameters.values():
            if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY) and p.name not in _NOT_OPTIONS:
                names.add(p.name)
    return frozenset(names)


@cache
def keyword_names(chip: str) -> frozenset[str]:
    """Every keyword ``chip``'s driver takes, the non-option ones (``sleep``) too."""
    names: set[str] = set()
    for cls in _driver_class(chip).__mro__:
        init = cls.__dict__.get("__init__")
        if init is not None:
            names.update(inspect.signature(init).parameters)
    return frozenset(names - {"self", "bus", "name"})


def options_for(chip: str, options: dict[str, object]) -> dict[str, object]:
    """The part of ``options`` the driver of ``chip`` takes (tests may add ``sleep``);
    ``CHIP.key`` entries for this chip win over plain ``key`` ones."""
    names = keyword_names(chip)
    out = {k: v for k, v in options.items() if k in names}
    prefix = f"{chip}."
    out.update({k[len(prefix) :]: v for k, v in options.items() if k.startswith(prefix)})
    return out


class _NoBus:
    """Stands in for a bus while a driver's options are checked (constructors do no I/O)."""

    def xfer2(self, data: list[int]) -> list[int]:
        raise RuntimeError("no bus: option check only")

    xfer_segments = xfer2

    def write_read(self, *args: object) -> bytes:
        raise RuntimeError("no bus: option check only")

    write = write_read


def check_chip_options(chips: Sequence[str], options: dict[str, object]) -> None:
    """ValueError for a key no configured chip takes, or a value a driver refuses."""
    used = {k for chip in set(chips) for k in option_names(chip)}
    used |= {f"{chip}.{k}" for chip in set(chips) for k in option_names(chip)}
    unknown = sorted(set(options) - used)
    if unknown:
        takes = "; ".join(
            f"{chip}: {', '.join(sorted(option_names(chip))) or '(none)'}"
            for chip in sorted(set(chips))
        )
        raise ValueError(
            f"'chip_options' {unknown}: no configured chip takes them; the drivers take {takes}"
        )
    for chip in sorted(set(chips)):
        try:
            registry.make_driver(chip, _NoBus(), f"({chip})", **options_for(chip, options))
        except (ValueError, TypeError) as exc:
            raise ValueError(f"'chip_options' for {chip}: {exc}") from None


def resolve_chips(chips: Sequence[str], devices: Sequence[str]) -> list[str]:
    """One chip name per device (pln2033.chips.check_chips), the message naming the parameter."""
    try:
        names = registry.check_chips(list(c for c in chips if c), len(devices))
    except ValueError as exc:
        raise ValueError(f"'chips': {exc}") from None
    for chip in sorted(set(names)):
        if not available(chip):
            raise ValueError(
                f"'chips': the {chip} driver is not installed in this version; "
                f"available: {', '.join(available_chips())}"
            )
    return names


def available(chip: str) -> bool:
    """The chip's driver module can be imported (a family still being written is not)."""
    try:
        registry.chip_info(chip)
    except ImportError:
        return False
    return True


def available_chips() -> list[str]:
    return [c for c in registry.chip_names() if available(c)]


def cpi_union() -> tuple[int, int, int]:
    """(lowest, highest, step) of the CPI any settable available chip accepts: the node's
    ``cpi`` range; step 50 when every chip's values are multiples of it, else 1."""
    ranges = [registry.chip_info(c).cpi for c in available_chips()]
    settable = [r for r in ranges if not r.fixed] or ranges
    step = 50 if all(r.min % 50 == 0 and r.step % 50 == 0 for r in settable) else 1
    return min(r.min for r in settable), max(r.max for r in settable), step


def spi_speed(info: ChipInfo, wanted_hz: int) -> tuple[int, str]:
    """The SPI clock for a chip: ``wanted_hz`` capped to its maximum, and a log line if capped."""
    if wanted_hz <= info.max_spi_hz:
        return wanted_hz, ""
    return info.max_spi_hz, (
        f"spi_speed_hz {wanted_hz} is above the {info.title}'s {info.max_spi_hz} Hz: "
        f"using {info.max_spi_hz} Hz"
    )


def firmware_source(info: ChipInfo, patch_file: str, srom_file: str) -> tuple[str, str]:
    """(file to load, log line) for one chip: the patch for a "patch" chip, the SROM for a
    "srom" chip; a chip that takes none ignores both with a log line."""
    if info.firmware == "patch":
        return patch_file, ""
    if info.firmware == "srom":
        return srom_file, ""
    given = [n for n, v in (("patch_file", patch_file), ("srom_file", srom_file)) if v]
    note = f"the {info.title} takes no firmware: {' and '.join(given)} ignored" if given else ""
    return "", note


def read_firmware(info: ChipInfo, path: str) -> list[int] | None:
    """The words/bytes of ``path`` for this chip's firmware kind (None for '')."""
    if not path:
        return None
    if info.firmware == "srom":
        from pln2033.pmw33xx.driver import read_srom_file

        return read_srom_file(path)
    from pln2033.pln2033 import read_patch_file

    return read_patch_file(path)


def chip_info_for(chip: str, register_map: str = "") -> ChipInfo:
    """The ChipInfo of ``chip``; the PLN2033's follows the register map in force."""
    if chip == registry.DEFAULT_CHIP and register_map:
        from pln2033.pln2033 import RegisterMap, pln2033_info

        return pln2033_info(RegisterMap.load(register_map))
    return registry.chip_info(chip)


def check_cpi(chips: Sequence[str], cpi: int, register_map: str = "") -> list[str]:
    """ValueError when a settable chip refuses ``cpi``; log lines for the fixed ones that
    ignore it."""
    notes = []
    for chip in sorted(set(chips)):
        info = chip_info_for(chip, register_map)
        if info.cpi.fixed:
            notes.append(
                f"the {info.title}'s resolution is fixed (it follows height_m): 'cpi' {cpi} "
                "does not apply to it"
            )
        elif problem := info.cpi.problem(cpi, info.title):
            raise ValueError(f"'cpi': {problem}")
    return notes


def check_board_config(
    devices: Sequence[str],
    chips: Sequence[str],
    options: dict[str, object],
    cpi: int,
    register_map: str = "",
) -> tuple[list[str], list[str]]:
    """Every chips-related check the node and the agent make before the poller starts:
    (one chip per device, log lines). ValueError says what is wrong."""
    per_device = resolve_chips(chips, devices)
    check_chip_options(per_device, options)
    return per_device, check_cpi(per_device, cpi, register_map)
