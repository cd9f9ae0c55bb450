"""PixArt PMW3360 and PMW3389 (SPI mode 3): register facts, drivers, emulators.

Sources and what they disagree on: docs/sensors.md, section "PMW3360 and PMW3389".
"""

from .driver import (
    PMW3360,
    PMW3360_INFO,
    PMW3389,
    PMW3389_INFO,
    PMW33xx,
    PollBudget,
    poll_budget,
    read_srom_file,
)
from .emulator import EmulatedPMW33xx, EmulatedPMW3360, EmulatedPMW3389

__all__ = [
    "PMW3360",
    "PMW3360_INFO",
    "PMW3389",
    "PMW3389_INFO",
    "EmulatedPMW33xx",
    "EmulatedPMW3360",
    "EmulatedPMW3389",
    "PMW33xx",
    "PollBudget",
    "poll_budget",
    "read_srom_file",
]
