"""The sim backend's channel: the production :class:`~mm_beagle.poller.channel.Channel`
plus the emulator's ground truth, kept out of the production hot path.

After every write of its channel a :class:`SimChannel` copies what its emulated sensor
really did (counts that entered the chip's counter, counts a lift cleared) into the
shared state's ``I_GEN_*``/``I_LIFT_LOST_*`` fields, in the driver's counts, under the
sequence lock of a write of its own. The bookkeeping lives in a
:class:`SimChannelStats`; :func:`truth_of` finds it for the self-test and reports.
Only the sim backend imports this module.
"""

from __future__ import annotations

import time
from collections.abc import Callable

from mm_beagle.poller import shared_state as ss
from mm_beagle.poller.channel import Channel
from pln2033 import Motion


class SimChannelStats:
    """One emulated sensor's ground truth since its channel's first initialisation.

    ``stats`` is the emulator's counter record (``counted_x``, ``lift_cleared_x``,
    ``lift_motion_x``, ...; emulator counts). ``ratio`` is driver counts per emulator
    count (1: the chip's own counter; the OTOS's emulator counts at the PAA5160's
    20 000 CPI, its driver reports 1000 CPI). ``base`` is the emulator's record at
    that initialisation less what the shared state already holds (non-zero after a
    restart: the truth carries on, as the totals do).
    """

    def __init__(self, ints: memoryview, stats, cpi_y: int, emulated_cpi: int) -> None:
        self.ints = ints
        self.stats = stats
        ratio = cpi_y / emulated_cpi if emulated_cpi else 1.0
        self.ratio = 1.0 if abs(ratio - 1.0) < 0.01 else ratio
        k = self.ratio
        # counts before the first initialisation were discarded on purpose
        self.base = (
            stats.counted_x - round(ints[ss.I_GEN_X] / k),
            stats.counted_y - round(ints[ss.I_GEN_Y] / k),
            stats.lift_cleared_x + round(stats.lift_motion_x) - round(ints[ss.I_LIFT_LOST_X] / k),
            stats.lift_cleared_y + round(stats.lift_motion_y) - round(ints[ss.I_LIFT_LOST_Y] / k),
        )

    def write(self) -> None:
        """The truth now, into the shared state (its own write under the sequence lock)."""
        ints, stats, base, k = self.ints, self.stats, self.base, self.ratio
        gen_x, gen_y = stats.counted_x - base[0], stats.counted_y - base[1]
        lost_x = stats.lift_cleared_x + round(stats.lift_motion_x) - base[2]
        lost_y = stats.lift_cleared_y + round(stats.lift_motion_y) - base[3]
        if k != 1.0:
            gen_x, gen_y, lost_x, lost_y = (round(v * k) for v in (gen_x, gen_y, lost_x, lost_y))
        ints[ss.I_VERSION] += 1  # odd: writing
        ints[ss.I_GEN_X] = gen_x
        ints[ss.I_GEN_Y] = gen_y
        ints[ss.I_LIFT_LOST_X] = lost_x
        ints[ss.I_LIFT_LOST_Y] = lost_y
        ints[ss.I_VERSION] += 1  # even: consistent


class SimChannel(Channel):
    """A Channel on an emulated sensor: each poll and read also updates the ground truth.

    (A chip other than the PLN2033 polls through ``record``, which this class
    overrides too: its ``poll`` instance attribute set by ``attach`` still lands here.)
    """

    truth: SimChannelStats | None = None

    def attach(self, driver) -> None:
        super().attach(driver)
        stats = getattr(self.bus, "stats", None)  # none on the benchmark's stub bus
        if driver is not None and stats is not None and self.truth is None:
            emulated_cpi = getattr(self.bus, "cpi_y", 0) or self.cpi_y
            self.truth = SimChannelStats(self.ints, stats, self.cpi_y, emulated_cpi)
        if self.truth is None and self.fast and driver is not None:
            # no truth to keep (the benchmark's stub bus): the production hot path as it is
            self.poll = self._fast_poll  # type: ignore[method-assign]  # per-instance

    def poll(self, offset_ns: int, now: Callable[[], int] = time.perf_counter_ns) -> int:
        s = super().poll(offset_ns, now)
        if self.truth is not None:
            self.truth.write()
            self._resync()  # the fast poll's copy of the lock word
        return s

    def record(self, stamp_ns: int, m: Motion | None, extra_flags: int = 0) -> None:
        super().record(stamp_ns, m, extra_flags)
        if self.truth is not None:
            self.truth.write()
            self._resync()


def truth_of(ch: Channel) -> SimChannelStats | None:
    """The emulator's ground truth of channel ``ch`` (None: no emulator behind it)."""
    return ch.truth if isinstance(ch, SimChannel) else None
