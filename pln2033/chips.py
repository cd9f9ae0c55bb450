"""The chip registry: which driver and which emulator serve each chip name.

The poller, the agent, the node and the sim backend pick a driver per device by
its name in the ``chips`` parameter. Modules are imported when a chip is first
used, so a board that polls PLN2033s never imports the other families.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache
from importlib import import_module
from typing import Any

from .sensor import ChipInfo, SensorDriver

DEFAULT_CHIP = "pln2033"


@dataclass(frozen=True)
class ChipSpec:
    """Where one chip's pieces live, as "module:attribute" strings."""

    info: str
    driver: str
    emulator: str


CHIPS: dict[str, ChipSpec] = {
    "pln2033": ChipSpec(
        "pln2033.pln2033.driver:INFO",
        "pln2033.pln2033.driver:PLN2033",
        "pln2033.pln2033.emulator:EmulatedPLN2033",
    ),
    "pmw3360": ChipSpec(
        "pln2033.pmw33xx.driver:PMW3360_INFO",
        "pln2033.pmw33xx.driver:PMW3360",
        "pln2033.pmw33xx.emulator:EmulatedPMW3360",
    ),
    "pmw3389": ChipSpec(
        "pln2033.pmw33xx.driver:PMW3389_INFO",
        "pln2033.pmw33xx.driver:PMW3389",
        "pln2033.pmw33xx.emulator:EmulatedPMW3389",
    ),
    "pmw3901": ChipSpec(
        "pln2033.pmw3901.driver:PMW3901_INFO",
        "pln2033.pmw3901.driver:PMW3901",
        "pln2033.pmw3901.emulator:EmulatedPMW3901",
    ),
    "paa5100": ChipSpec(
        "pln2033.pmw3901.driver:PAA5100_INFO",
        "pln2033.pmw3901.driver:PAA5100",
        "pln2033.pmw3901.emulator:EmulatedPAA5100",
    ),
    "otos": ChipSpec(
        "pln2033.otos.driver:OTOS_INFO",
        "pln2033.otos.driver:OTOS",
        "pln2033.otos.emulator:EmulatedOTOS",
    ),
}


def chip_names() -> tuple[str, ...]:
    return tuple(CHIPS)


def _load(path: str) -> Any:
    module, _, attr = path.partition(":")
    return getattr(import_module(module), attr)


def _spec(chip: str) -> ChipSpec:
    try:
        return CHIPS[chip]
    except KeyError:
        raise ValueError(f"unknown chip '{chip}'; allowed: {', '.join(CHIPS)}") from None


@cache
def chip_info(chip: str) -> ChipInfo:
    """The :class:`ChipInfo` of ``chip`` (ValueError naming the allowed chips)."""
    return _load(_spec(chip).info)


def check_chips(chips: list[str] | tuple[str, ...], n_devices: int) -> list[str]:
    """One chip name per device: ``chips`` as given, one name for every device, or empty for
    all PLN2033. ValueError names the allowed chips or the count mismatch."""
    names = [str(c).strip().lower() for c in chips]
    for name in names:
        _spec(name)
    if not names:
        return [DEFAULT_CHIP] * n_devices
    if len(names) == 1:
        return names * n_devices
    if len(names) != n_devices:
        raise ValueError(
            f"'chips' names {len(names)} chips for {n_devices} devices; give one per device "
            "(in the order of 'devices') or one for all"
        )
    return names


def make_driver(chip: str, bus: object, name: str, **options: Any) -> SensorDriver:
    """The driver of ``chip`` on ``bus`` (``name``: the device path, for messages)."""
    return _load(_spec(chip).driver)(bus, name=name, **options)


def make_emulator(chip: str, **kwargs: Any) -> Any:
    """A register-level emulator of ``chip``; kwargs as the emulators take them (motion, clock,
    lift_windows, noise_counts, fault_windows, reset_after_fault, seed, record,
    low_quality_windows)."""
    return _load(_spec(chip).emulator)(**kwargs)


def cpi_union() -> tuple[int, int]:
    """The lowest and highest CPI any settable registered chip accepts (the node's range)."""
    ranges = [chip_info(c).cpi for c in CHIPS]
    settable = [r for r in ranges if not r.fixed] or ranges
    return min(r.min for r in settable), max(r.max for r in settable)
