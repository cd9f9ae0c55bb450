"""The bits of a single poll's ``flags`` (shared-state ring, GetSamples, SensorPolls).

Defined once here, at the lowest layer both the board's poller and the pose math import;
pure Python (no numpy: the board's agent imports this on the spidev path).
``mm_interfaces/msg/SensorPolls.msg`` carries the same values as constants (a test
compares them).
"""

FLAG_LIFT = 1  # the chip reported the lift bit
FLAG_MOTION = 2  # the chip's motion bit was set
FLAG_OVERFLOW = 4  # a delta register overflowed: counts were lost
FLAG_SPI_ERROR = 8  # the read failed: no counts (dx = dy = 0)
#: a read made for a command (e.g. a settings read), between two scheduled polls: it
#: takes no poll slot, so its stamp is no poll period
FLAG_COMMAND_READ = 16
#: the chip's surface-quality figure (SQUAL, ...) was below its threshold
#: (``pln2033.chips.chip_info(chip).quality_threshold``): the counts are unreliable
FLAG_LOW_QUALITY = 32

#: The flags after which a poll's counts are not a measurement of the floor: the sensor
#: was lifted, or it saw the floor too poorly. The pose math treats both the same
#: (gap filling, dropped equations of ``two-sensor``, the held-back steps): the one rule.
FLAG_UNSEEN = FLAG_LIFT | FLAG_LOW_QUALITY

#: name -> bit, in bit order (the .msg constants and the docs list them so)
FLAGS = {
    "FLAG_LIFT": FLAG_LIFT,
    "FLAG_MOTION": FLAG_MOTION,
    "FLAG_OVERFLOW": FLAG_OVERFLOW,
    "FLAG_SPI_ERROR": FLAG_SPI_ERROR,
    "FLAG_COMMAND_READ": FLAG_COMMAND_READ,
    "FLAG_LOW_QUALITY": FLAG_LOW_QUALITY,
}
