"""Philips PLN2033 (SPI mode 1): register map as data, driver, emulator.

No public datasheet: every register fact is an assumption the user can override with a
YAML file (``default_regmap.yaml`` here holds the defaults); docs/pln2033.md.
"""

from .driver import INFO, PLN2033, pln2033_info, read_patch_file
from .emulator import EmulatedPLN2033
from .regmap import REGISTER_NAMES, RegisterMap

__all__ = [
    "INFO",
    "PLN2033",
    "REGISTER_NAMES",
    "EmulatedPLN2033",
    "RegisterMap",
    "pln2033_info",
    "read_patch_file",
]
