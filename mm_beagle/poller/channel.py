"""One sensor of the poller: its driver, its hot path and its slice of the shared memory.

The poll itself (status + delta X + delta Y in one transfer), the monotone totals, the
ring record, the lift-gap estimate and the CPI cache; :mod:`mm_beagle.poller.poller` runs
the channels at 1 kHz and serves commands between polls. No ROS, no numpy.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any, Protocol, cast

from mm_beagle.poller import shared_state as ss
from mm_beagle.poller.lift_gap import LiftGapEstimator
from pln2033 import INCH_M, Motion
from pln2033 import chips as registry
from pln2033.pln2033 import PLN2033
from pln2033.sensor import QUALITY_NONE, ChipInfo, SensorDriver


class Bus(Protocol):
    """What the poller itself does with a device's bus (its driver does the rest)."""

    def close(self) -> None: ...


def _detached(*_args: object) -> Any:
    """A channel's driver calls before any driver is attached (never made: see ``ok``)."""
    raise RuntimeError("the channel has no driver attached")


def _no_resync() -> None:
    """No fast poll holds copies of the totals (no PLN2033 driver attached)."""


class Channel:
    """One sensor: its driver, state and its slice of the shared memory."""

    def __init__(
        self,
        index: int,
        device: str,
        state: ss.SharedState,
        ring_size: int,
        chip: str = registry.DEFAULT_CHIP,
        info: ChipInfo | None = None,
    ) -> None:
        self.i = index
        self.device = device
        self.chip = chip
        self.info = info or registry.chip_info(chip)
        self.fast = chip == registry.DEFAULT_CHIP  # the PLN2033's hand-tuned hot path
        # memoryviews, not numpy: item access on them is several times cheaper,
        # and this runs twice per 1 kHz poll (and the board's agent has no numpy).
        self.ints, self.floats, self.ring = state.sensor_views(index)
        self.n = ring_size
        self.driver: SensorDriver | None = None
        self.bus: Bus | None = None
        self.cpi_x = self.cpi_y = 0
        self.scale_x = self.scale_y = 0.0  # metres per count at the CPI in force
        self.cpi_wanted = 0  # the CPI the chip should have: configured, then as commanded
        # A restarted poller (the node restarts a stuck one) carries on where the
        # shared totals stand; one killed mid-write leaves the version odd.
        self.seq = int(self.ints[ss.I_SEQ])
        if self.ints[ss.I_VERSION] & 1:
            self.ints[ss.I_VERSION] += 1
        self.consecutive_errors = 0
        self.next_retry = 0.0
        self.last_error = ""
        self.gap = LiftGapEstimator()  # in counts
        self.gap_m = LiftGapEstimator()  # in metres: right across a CPI change
        self._gap_busy = False  # self.gap.busy, as the hot path reads it
        self._fast_poll: Callable[[int], None] = _detached
        self._resync: Callable[[], None] = _no_resync  # the fast poll's copies of the totals
        # the hot path's view of the driver (see attach)
        self._xfer: Callable[[list[int]], list[int]] = _detached
        self._decode: Callable[[list[int]], Motion] = _detached
        self._read: Callable[[], Motion] = _detached
        self._tx: list[int] = []
        self._unusual = 0xFFFF
        self._motion_bit = 0
        self.ok = False  # up and its last poll succeeded: the run loop's fast case
        self.ints[ss.I_STATE] = ss.STATE_STARTING
        self.ints[ss.I_QUALITY] = QUALITY_NONE
        if self.fast:  # the hot path writes no quality: the PLN2033 has none
            ring_quality = self.ring[6]
            for k in range(len(ring_quality)):
                ring_quality[k] = QUALITY_NONE
        else:
            # bound once per channel, so the run loop's ch.poll() needs no branch per poll
            self.poll = self._poll_generic  # type: ignore[method-assign]  # per-instance dispatch
        self._threshold = self.info.quality_threshold
        self._poor_is_gap = not self.info.poor_polls_carry_motion

    def attach(self, driver: SensorDriver | None) -> None:
        """Use ``driver`` for polls (None: the sensor is down)."""
        self.driver = driver
        self.ok = driver is not None
        if driver is not None:
            if self.fast:  # the PLN2033's driver: its burst and its decoding, used directly
                pln = cast(PLN2033, driver)
                self._xfer = pln.bus.xfer2
                self._decode = pln.decode_motion
                self._tx = pln.motion_tx
                self._unusual = pln.unusual_status_bits
                self._motion_bit = pln.map.status_motion
                self._fast_poll, self._resync = self._make_fast_poll()
                if type(self).poll is Channel.poll:  # no subclass wraps it: call it directly
                    self.poll = self._fast_poll  # type: ignore[method-assign,assignment]  # as below
            else:
                self._read = driver.read_motion
                self.info = driver.info  # the PMW3901's follows its height
                self._threshold = self.info.quality_threshold
                self._poor_is_gap = not self.info.poor_polls_carry_motion
                if hasattr(driver, "last_pose"):  # the OTOS: its on-chip pose too
                    self.poll = self._poll_with_pose  # type: ignore[method-assign]  # as above

    def _poll_generic(self, stamp_ns: int) -> None:
        """One motion read of a chip other than the PLN2033, recorded. Raises SensorError."""
        self.record(stamp_ns, self._read())

    def _poll_with_pose(self, stamp_ns: int) -> None:
        """The OTOS: its motion read also brings the on-chip pose; both are stored."""
        m = self._read()
        reading = getattr(self.driver, "last_pose", None)  # the OTOS's, of the read above
        if reading is not None:
            self.store_chip_pose(reading, stamp_ns)
        self.record(stamp_ns, m)

    def store_chip_pose(self, reading, stamp_ns: int) -> None:
        """The chip's own pose and velocity (OTOS frame: x right, y forward, heading CCW)
        into the shared state in base_link terms (REP 103: x forward, y left)."""
        pose, vel = reading.pose, reading.velocity
        yaw = pose.h
        vxw, vyw = vel.y, -vel.x  # world velocity in the odometry frame's axes
        c, s = math.cos(yaw), math.sin(yaw)
        ints, f = self.ints, self.floats
        ints[ss.I_VERSION] += 1  # odd: writing
        f[ss.F_CHIP_X] = pose.y
        f[ss.F_CHIP_Y] = -pose.x
        f[ss.F_CHIP_YAW] = yaw
        f[ss.F_CHIP_VX] = c * vxw + s * vyw
        f[ss.F_CHIP_VY] = -s * vxw + c * vyw
        f[ss.F_CHIP_WZ] = vel.h
        ints[ss.I_CHIP_POSE_NS] = stamp_ns
        ints[ss.I_VERSION] += 1  # even: consistent

    def poll(self, stamp_ns: int) -> None:
        """One motion burst, recorded: the 1 kHz hot path (:meth:`_make_fast_poll`'s
        function, which :meth:`attach` also binds as ``poll`` itself). Raises SensorError."""
        self._fast_poll(stamp_ns)

    def _make_fast_poll(self) -> tuple[Callable[[int], None], Callable[[], None]]:
        """The PLN2033's poll as a function of the stamp, made at each ``attach``, and the
        function that re-reads its copies of the totals (:meth:`record` calls it).

        The common poll (no lift, no overflow, no lift gap open or waiting for
        its after-window) is recorded here with as few Python operations as
        possible: what is fixed while this driver is attached (its bus transfer, burst,
        status bits, this channel's shared-memory views) is held by the function instead
        of read from attributes, the four totals it adds to are kept as its own copies too
        (written to the shared memory, never read back from it, except after a
        :meth:`record`), and field indices are literals (see shared_state);
        anything else goes through :meth:`record`, the one general implementation. The
        lift gap costs the hot path nothing but the ``_gap_busy`` check (the estimator's
        ``busy``, mirrored after each of its updates): the polls before a gap are read
        back from the ring when it starts.
        """
        xfer, tx, decode, record = self._xfer, self._tx, self._decode, self.record
        unusual, motion_bit = self._unusual, self._motion_bit
        ints, floats, n = self.ints, self.floats, self.n
        stamps, rdx, rdy, rstatus, rcpi, rflags, _rq = self.ring
        ch = self
        xt, yt, xm, ym = ints[2], ints[3], floats[0], floats[1]

        def resync() -> None:
            nonlocal xt, yt, xm, ym
            xt, yt, xm, ym = ints[2], ints[3], floats[0], floats[1]

        def fast_poll(stamp_ns: int) -> None:
            nonlocal xt, yt, xm, ym
            rx = xfer(tx)
            status = (rx[1] << 8) | rx[2] if len(rx) == 9 else 0xFFFF
            if status & unusual or ch._gap_busy:
                record(stamp_ns, decode(rx))
                return
            dx = (((rx[4] << 8) | rx[5]) ^ 0x8000) - 0x8000  # signed 16 bit
            dy = (((rx[7] << 8) | rx[8]) ^ 0x8000) - 0x8000
            seq = ch.seq
            slot = seq % n
            version = ints[0] + 1
            ints[0] = version  # I_VERSION, odd: writing
            rdx[slot] = dx
            rdy[slot] = dy
            rstatus[slot] = status
            stamps[slot] = stamp_ns
            rcpi[slot] = ch.cpi_y
            rflags[slot] = 2 if status & motion_bit else 0  # FLAG_MOTION
            if dx:
                xt += dx
                ints[2] = xt  # I_X_TOTAL
                xm += dx * ch.scale_x
                floats[0] = xm  # F_X_TOTAL_M
            if dy:
                yt += dy
                ints[3] = yt  # I_Y_TOTAL
                ym += dy * ch.scale_y
                floats[1] = ym  # F_Y_TOTAL_M
            ch.seq = seq = seq + 1
            ints[1] = seq  # I_SEQ
            ints[10] = stamp_ns  # I_STAMP_NS
            ints[0] = version + 1  # even: consistent

        return fast_poll, resync

    def record(self, stamp_ns: int, m: Motion | None, extra_flags: int = 0) -> None:
        """Add one read to the totals and the ring (under the sequence lock).

        ``m`` None records a failed poll. ``extra_flags`` marks reads made for a
        command (settings, the drain before a CPI change): they take no poll
        slot, so they do not lengthen a lift gap.
        """
        ints, floats = self.ints, self.floats
        slot = self.seq % self.n
        stamps, rdx, rdy, rstatus, rcpi, rflags, rquality = self.ring
        ints[ss.I_VERSION] += 1  # odd: writing
        if m is None:
            rdx[slot] = rdy[slot] = rstatus[slot] = 0
            rquality[slot] = QUALITY_NONE
            flags = ss.FLAG_SPI_ERROR
        else:
            dx, dy = m.dx, m.dy
            rdx[slot] = dx
            rdy[slot] = dy
            rstatus[slot] = m.status & 0xFFFF
            quality = m.quality
            rquality[slot] = quality
            # below the chip's threshold: the counts are not trusted, the poll is a gap
            # poll for the lift estimate (they stay in the measured totals, as a lift's do);
            # not on a chip whose poor reads still carry motion (the OTOS's warning: its
            # IMU carried the pose, so an estimate on top would count that motion twice)
            poor = 0 <= quality < self._threshold
            flags = (
                (ss.FLAG_LIFT if m.lifted else 0)
                | (ss.FLAG_MOTION if m.moved else 0)
                | (ss.FLAG_OVERFLOW if m.overflow else 0)
                | (ss.FLAG_LOW_QUALITY if poor else 0)
            )
            ints[ss.I_QUALITY] = quality
            if poor:
                ints[ss.I_LOW_QUALITY] += 1
            if dx:
                ints[ss.I_X_TOTAL] += dx
                floats[ss.F_X_TOTAL_M] += dx * self.scale_x
            if dy:
                ints[ss.I_Y_TOTAL] += dy
                floats[ss.F_Y_TOTAL_M] += dy * self.scale_y
            if m.lifted:
                ints[ss.I_LIFT_TOTAL] += 1
            if m.overflow:
                ints[ss.I_OVERFLOWS] += 1
            gap = m.lifted or (poor and self._poor_is_gap)
            if not (extra_flags and gap):  # a command's read covers no poll slot
                self._update_lift_gap(dx, dy, gap)
        stamps[slot] = stamp_ns
        rcpi[slot] = self.cpi_y
        rflags[slot] = flags | extra_flags
        self.seq += 1
        ints[ss.I_SEQ] = self.seq
        ints[ss.I_STAMP_NS] = stamp_ns
        ints[ss.I_VERSION] += 1  # even: consistent
        self._resync()  # the fast poll goes on from these totals

    def _update_lift_gap(self, dx: int, dy: int, lifted: bool) -> None:
        """Feed one poll to the estimators; add their estimate when it is complete."""
        if lifted and not self.gap.busy:
            self._prime_lift_gap()
        est = self.gap.update(dx, dy, lifted)
        self._gap_busy = self.gap.busy
        est_m = self.gap_m.update(dx * self.scale_x, dy * self.scale_y, lifted)
        if est is not None and est_m is not None:
            floats = self.floats
            floats[ss.F_X_EST_COUNTS] += est[0]
            floats[ss.F_Y_EST_COUNTS] += est[1]
            floats[ss.F_X_EST_M] += est_m[0]
            floats[ss.F_Y_EST_M] += est_m[1]
            floats[ss.F_X_EST_VAR_COUNTS] += est[2] * est[2]
            floats[ss.F_Y_EST_VAR_COUNTS] += est[3] * est[3]
            floats[ss.F_X_EST_VAR_M] += est_m[2] * est_m[2]
            floats[ss.F_Y_EST_VAR_M] += est_m[3] * est_m[3]

    def _prime_lift_gap(self) -> None:
        """A gap starts: hand the estimators the good polls right before it, from the ring.

        Back from the newest recorded poll to the window's length, the ring's
        oldest slot or the previous lifted poll, whichever comes first; each
        poll in metres at the CPI it was counted with.
        """
        _, rdx, rdy, _, rcpi, rflags, _rq = self.ring
        n, seq = self.n, self.seq
        stop = ss.FLAG_LIFT | (ss.FLAG_LOW_QUALITY if self._poor_is_gap else 0)
        ratio = self.scale_x / self.scale_y if self.scale_y else 1.0  # X's CPI next to Y's
        counts, metres = [], []
        for s in range(seq - 1, max(seq - 1 - self.gap.window, seq - n, -1), -1):
            slot = s % n
            if rflags[slot] & stop:
                break
            dx, dy = rdx[slot], rdy[slot]
            cpi = rcpi[slot]
            scale = INCH_M / cpi if cpi else self.scale_y
            counts.append((dx, dy))
            metres.append((dx * scale * ratio, dy * scale))
        counts.reverse()
        metres.reverse()
        self.gap.prime(counts)
        self.gap_m.prime(metres)

    def set_cpi_cache(self, x: int, y: int) -> None:
        """The CPI now in force on the chip: later counts are scaled by it.

        An optical-flow chip's CPI is its effective value rounded to an integer: its metres
        use that CPI too, as every client converting the polls by the messages' CPI does,
        so totals and polls agree (the rounding, at most 0.5 %, goes into the calibration's
        scale with the height error).
        """
        self.cpi_x, self.cpi_y = x, y
        self.scale_x = INCH_M / x if x else 0.0
        self.scale_y = INCH_M / y if y else 0.0
        self.gap_m.unit = self.scale_y
        self.ints[ss.I_CPI_X] = x
        self.ints[ss.I_CPI_Y] = y


# --- the process -------------------------------------------------------------------------------
