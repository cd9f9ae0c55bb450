"""PixArt PMW3901 and PAA5100JE-Q optical-flow sensors (SPI): registers, drivers, emulators.

The resolution of these chips follows their height above the floor (:mod:`.flow_scale`);
docs/sensors.md ("PMW3901 and PAA5100") names the source of every register fact.
"""

from .driver import (
    PAA5100,
    PAA5100_INFO,
    PMW3901,
    PMW3901_INFO,
    REGISTER_NAMES,
    InvalidHeightError,
)
from .emulator import EmulatedPAA5100, EmulatedPMW3901
from .flow_scale import BITCRAZE_PMW3901, OPTICAL_FLOW_ROS_PAA5100, FlowOptics

__all__ = [
    "BITCRAZE_PMW3901",
    "OPTICAL_FLOW_ROS_PAA5100",
    "PAA5100",
    "PAA5100_INFO",
    "PMW3901",
    "PMW3901_INFO",
    "REGISTER_NAMES",
    "EmulatedPAA5100",
    "EmulatedPMW3901",
    "FlowOptics",
    "InvalidHeightError",
]
