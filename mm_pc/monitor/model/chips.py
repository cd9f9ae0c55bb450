"""Which chip each sensor is, as the monitor shows it (no Qt, no ROS).

The node names each sensor's chip in ``SensorData.chip`` and ``SensorSettings.chip``
(issue 15). A node or a recording from before that has no chip field: it decodes as
``chip == ''``, which means a PLN2033 **without** a quality figure (its ``quality``
decodes as 0, which must not be read as SQUAL 0). The chip's facts (title, quality
figure and threshold, CPI range) come from the driver layer's registry,
:func:`pln2033.chips.chip_info`; a chip name this monitor does not know (a newer node)
is shown by its name, with no threshold and no local CPI check (the node still checks).
"""

from __future__ import annotations

import math

from pln2033.chips import DEFAULT_CHIP, chip_info
from pln2033.sensor import ChipInfo, CpiRange

__all__ = [
    "chip_key",
    "chip_title",
    "cpi_range",
    "info_of",
    "quality_figure",
    "quality_label",
    "quality_threshold",
]


def chip_key(chip: str) -> str:
    """The registry name of ``chip`` ('' = an old node or recording: the PLN2033)."""
    return str(chip or "").strip().lower() or DEFAULT_CHIP


def info_of(chip: str) -> ChipInfo | None:
    """The registry's :class:`ChipInfo` of ``chip``, None for a chip not known here."""
    try:
        return chip_info(chip_key(chip))
    except (ValueError, ImportError):
        return None


def chip_title(chip: str) -> str:
    """What the monitor calls the chip, e.g. 'PixArt PMW3360' (the name if unknown)."""
    info = info_of(chip)
    return info.title if info is not None else chip_key(chip)


def quality_threshold(chip: str) -> int:
    """The chip's quality threshold (below it a poll is treated like a lift; 0 = none)."""
    info = info_of(chip)
    return info.quality_threshold if info is not None else 0


def quality_label(chip: str) -> str:
    """The chip's quality figure's name ('SQUAL'), '' when it has none."""
    info = info_of(chip)
    if info is None:
        return "quality"
    return info.quality_name


def quality_figure(chip: str, quality: int) -> float:
    """``quality`` as a number to plot, NaN where it is none: an old node or recording
    (``chip == ''``, whose zero-filled 0 is no reading), -1 (the chip has none), or a chip
    that has no quality figure."""
    if not chip or int(quality) < 0:
        return math.nan
    info = info_of(chip)
    if info is not None and not info.quality_name:
        return math.nan
    return float(quality)


def cpi_range(chip: str, settings=None) -> CpiRange | None:
    """The resolutions ``chip`` can be set to: from a ``SensorSettings`` that carries
    them (``cpi_max`` > 0: the node's own word), else from the registry (None if the
    chip is unknown here)."""
    if settings is not None and int(getattr(settings, "cpi_max", 0) or 0) > 0:
        lo, hi = int(settings.cpi_min), int(settings.cpi_max)
        step = max(int(getattr(settings, "cpi_step", 1) or 1), 1)
        if 0 < lo <= hi:
            return CpiRange(lo, hi, step)
    info = info_of(chip)
    return info.cpi if info is not None else None
