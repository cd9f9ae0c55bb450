"""One sensor of the poller: its driver, its hot path and its slice of the shared memory.

The poll itself (status + delta X + delta Y in one transfer), the monotone totals, the
ring record, the lift-gap estimate and the CPI cache; :mod:`mm_beagle.poller.poller` runs
the channels at 1 kHz and serves commands between polls. No ROS, no numpy.
"""

from __future__ import annotations

import math
import struct
import time
from collections.abc import Callable
from typing import Any, Protocol, cast

from mm_beagle.poller import ring_layout
from mm_beagle.poller import shared_state as ss
from mm_beagle.poller.lift_gap import LiftGapEstimator
from pln2033 import INCH_M, Motion
from pln2033 import chips as registry
from pln2033.pln2033 import PLN2033
from pln2033.sensor import QUALITY_NONE, ChipInfo, SensorDriver


class Bus(Protocol):
    """What the poller itself does with a device's bus (its driver does the rest)."""

    def close(self) -> None: ...


RECORD = ring_layout.RECORD  # one poll in the ring
# a sensor's I_SEQ, I_X_TOTAL, I_Y_TOTAL, I_STAMP_NS, F_X_TOTAL_M, F_Y_TOTAL_M: one run of
# its shared memory (SharedState.sensor_bytes), native order
_HEAD = struct.Struct("=4q2d")
_HEAD_AT = 8 * ss.I_SEQ
_STAMP = struct.Struct("<q")  # a ring record's first field
# a signed 16-bit count's high byte as its value: count = _HIGH_BYTE[high] + low
_HIGH_BYTE = tuple((b - 256 if b & 0x80 else b) << 8 for b in range(256))


def no_clock() -> int:
    """The clock of a poll whose stamp is given whole (``ch.poll(stamp_ns, no_clock)``)."""
    return 0


def _detached(*_args: object) -> Any:
    """A channel's driver calls before any driver is attached (never made: see ``ok``)."""
    raise RuntimeError("the channel has no driver attached")


def _no_resync() -> None:
    """No fast poll holds copies of the totals (no PLN2033 driver attached)."""


def _no_busy(_busy: bool) -> None:
    """No fast poll holds a copy of the lift gap's ``busy`` (no PLN2033 driver attached)."""


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
        # and this runs twice per 1 kHz poll (and the board's agent has no numpy);
        # the ring as bytes: one ring_layout.RECORD packed per poll
        self.ints, self.floats, self.ring = state.sensor_views(index)
        self.row = state.sensor_bytes(index)  # ints then floats, as bytes
        self.n = ring_size
        self.driver: SensorDriver | None = None
        self.bus: Bus | None = None
        self.cpi_x = self.cpi_y = 0
        self.scale_x = self.scale_y = 0.0  # metres per count at the CPI in force
        self.cpi_wanted = 0  # the CPI the chip should have: configured, then as commanded
        # A restarted poller (the node restarts a stuck one) carries on where the
        # shared totals stand; one killed mid-write leaves the version odd.
        if self.ints[ss.I_VERSION] & 1:
            self.ints[ss.I_VERSION] += 1
        self.consecutive_errors = 0
        self.next_retry = 0.0
        self.last_error = ""
        self.gap = LiftGapEstimator()  # in counts
        self.gap_m = LiftGapEstimator()  # in metres: right across a CPI change
        self._set_gap_busy: Callable[[bool], None] = _no_busy  # the fast poll's gap.busy copy
        self._fast_poll: Callable[..., int] = _detached
        self._resync: Callable[[], None] = _no_resync  # the fast poll's copies of the totals
        # deferred (the agent): the fast poll keeps seq, totals and metres to itself and
        # they reach the shared memory at publish() (each service); else at every poll
        self.deferred = False
        self.publish: Callable[[], None] = _no_resync  # set by attach (a deferred fast poll)
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
        if not self.fast:
            # bound once per channel, so the run loop's ch.poll() needs no branch per poll
            self.poll = self._poll_generic  # type: ignore[method-assign]  # per-instance dispatch
        self._threshold = self.info.quality_threshold
        self._poor_is_gap = not self.info.poor_polls_carry_motion

    def attach(self, driver: SensorDriver | None) -> None:
        """Use ``driver`` for polls (None: the sensor is down)."""
        self.publish()  # what the previous driver's fast poll holds
        self.publish = _no_resync
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
                made = self._make_fast_poll()
                self._fast_poll, self._resync, self._set_gap_busy, self.publish = made
                if type(self).poll is Channel.poll:  # no subclass wraps it: call it directly
                    self.poll = self._fast_poll  # type: ignore[method-assign]  # as below
            else:
                self._read = driver.read_motion
                self.info = driver.info  # the PMW3901's follows its height
                self._threshold = self.info.quality_threshold
                self._poor_is_gap = not self.info.poor_polls_carry_motion
                if hasattr(driver, "last_pose"):  # the OTOS: its on-chip pose too
                    self.poll = self._poll_with_pose  # type: ignore[method-assign]  # as above

    def _poll_generic(self, offset_ns: int, now: Callable[[], int] = time.perf_counter_ns) -> int:
        """One motion read of a chip other than the PLN2033, recorded (see :meth:`poll`)."""
        s = now()
        self.record(s + offset_ns, self._read())
        return s

    def _poll_with_pose(self, offset_ns: int, now: Callable[[], int] = time.perf_counter_ns) -> int:
        """The OTOS: its motion read also brings the on-chip pose; both are stored."""
        s = now()
        m = self._read()
        reading = getattr(self.driver, "last_pose", None)  # the OTOS's, of the read above
        if reading is not None:
            self.store_chip_pose(reading, s + offset_ns)
        self.record(s + offset_ns, m)
        return s

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
        self._resync()

    @property
    def seq(self) -> int:
        """Polls recorded (the shared I_SEQ: the fast poll writes it, keeps no attribute)."""
        return self.ints[ss.I_SEQ]

    def poll(self, offset_ns: int, now: Callable[[], int] = time.perf_counter_ns) -> int:
        """One motion read, recorded, stamped ``now() + offset_ns`` with ``now()`` read right
        before the transfer (the poll loop: the perf counter and its offset to the wall clock;
        a whole stamp: ``poll(stamp_ns, no_clock)``); returns ``now()``'s reading. Raises
        SensorError. The PLN2033's: the 1 kHz hot path (:meth:`_make_fast_poll`'s function,
        which :meth:`attach` also binds as ``poll`` itself)."""
        return self._fast_poll(offset_ns, now)

    def _make_fast_poll(
        self,
    ) -> tuple[Callable[..., int], Callable[[], None], Callable[[bool], None], Callable[[], None]]:
        """The PLN2033's poll (:meth:`poll`), made at each ``attach``, the function that
        re-reads its copies of the lock word, seq, totals and CPI (:meth:`record`,
        :meth:`set_cpi_cache`, :meth:`store_chip_pose` and the sim channel's truth call it:
        any other writer of the lock word must), the one that sets its copy of the lift
        gap's ``busy``, and :attr:`publish` (``deferred`` channels: the agent's).

        The common poll (no lift, no overflow, no lift gap open or waiting for
        its after-window) is recorded here with as few Python operations as
        possible: what is fixed while this driver is attached (its bus transfer, burst,
        status bits, this channel's shared-memory views) is held by the function instead
        of read from attributes, the lock word, seq, the four totals it adds to, the CPI
        and the scales are kept as its own copies too (written to the shared memory, never
        read back from it, except by the resync above), field indices are literals (see
        shared_state), and the shared memory is written by two ``pack_into`` between the
        lock word's two stores: the ring record, then seq, counts, stamp and metres (one
        run of the sensor's memory); anything else goes through :meth:`record`, the one general
        implementation. The lift gap costs the hot path nothing but the ``busy`` check (the
        estimator's, mirrored after each of its updates): the polls before a gap are read
        back from the ring when it starts.

        ``deferred``: the poll writes the ring record only (no lock word, no head: each
        costs about as much as the record); :attr:`publish` writes seq, counts, stamp and
        metres under the lock, and the resync publishes before it re-reads, so a writer
        that adds to them (:meth:`record`) publishes first. For a shared state nobody reads
        between two publishes (the agent's, sent by its link at each service).
        """
        xfer, tx, decode, record = self._xfer, self._tx, self._decode, self.record
        unusual, motion_bit = self._unusual, self._motion_bit
        ints, floats, ring, n = self.ints, self.floats, self.ring, self.n
        put, size, high = RECORD.pack_into, RECORD.size, _HIGH_BYTE
        put_head, row, at = _HEAD.pack_into, self.row, _HEAD_AT
        ch = self
        version = seq = xt = yt = cpi = 0
        xm = ym = sx = sy = 0.0
        busy = self.gap.busy

        def resync() -> None:
            nonlocal version, seq, xt, yt, xm, ym, sx, sy, cpi
            version, seq, xt, yt = ints[0], ints[16], ints[17], ints[18]
            xm, ym = floats[0], floats[1]
            sx, sy, cpi = ch.scale_x, ch.scale_y, ch.cpi_y

        def set_busy(value: bool) -> None:
            nonlocal busy
            busy = value

        def fast_poll(offset_ns: int, now: Callable[[], int] = time.perf_counter_ns) -> int:
            nonlocal version, seq, xt, yt, xm, ym
            s = now()
            rx = xfer(tx)
            stamp_ns = s + offset_ns
            try:
                _, s1, s0, _, x1, x0, _, y1, y0 = rx  # the burst: status, delta X, delta Y
            except ValueError:  # not 9 bytes: the general path says why
                record(stamp_ns, decode(rx))
                return s
            status = s1 << 8 | s0
            if status & unusual or busy:
                record(stamp_ns, decode(rx))
                return s
            dx = high[x1] + x0  # signed 16 bit
            dy = high[y1] + y0
            version += 1
            ints[0] = version  # I_VERSION, odd: writing
            # the record: stamp, dx, dy, status, cpi, flags (FLAG_MOTION), quality (none)
            put(ring, seq % n * size, stamp_ns, dx, dy, status, cpi,
                2 if status & motion_bit else 0, -1)  # fmt: skip
            xt += dx
            yt += dy
            xm += dx * sx
            ym += dy * sy
            seq += 1
            put_head(row, at, seq, xt, yt, stamp_ns, xm, ym)  # I_SEQ .. F_Y_TOTAL_M
            version += 1
            ints[0] = version  # even: consistent
            return s

        if not ch.deferred:
            resync()
            return fast_poll, resync, set_busy, _no_resync

        # deferred (the agent's): per poll only the ring record and the fast poll's own
        # copies of seq and counts; publish() writes seq, counts, the newest stamp (read
        # back from the ring) and the metres (the counts since the last resync at its scale:
        # the CPI only changes through set_cpi_cache, which publishes first)
        xt0 = yt0 = published = 0
        stamp_of = _STAMP.unpack_from

        def publish() -> None:
            nonlocal published
            if seq == published:
                return
            published = seq
            v = ints[0]
            ints[0] = v + 1  # I_VERSION, odd: writing
            put_head(row, at, seq, xt, yt, stamp_of(ring, (seq - 1) % n * size)[0],
                     xm + (xt - xt0) * sx, ym + (yt - yt0) * sy)  # fmt: skip
            ints[0] = v + 2  # even: consistent

        def resync_deferred() -> None:
            # what this fast poll holds goes out before another writer's values come in
            # (a writer that adds to seq or the totals, record, publishes before it writes)
            nonlocal seq, xt, yt, xm, ym, sx, sy, cpi, xt0, yt0, published
            publish()
            seq, xt, yt = ints[16], ints[17], ints[18]
            xt0, yt0, published = xt, yt, seq
            xm, ym = floats[0], floats[1]
            sx, sy, cpi = ch.scale_x, ch.scale_y, ch.cpi_y

        def deferred_poll(offset_ns: int, now: Callable[[], int] = time.perf_counter_ns) -> int:
            nonlocal seq, xt, yt
            s = now()
            rx = xfer(tx)
            stamp_ns = s + offset_ns
            try:
                _, s1, s0, _, x1, x0, _, y1, y0 = rx  # as fast_poll
            except ValueError:
                record(stamp_ns, decode(rx))
                return s
            status = s1 << 8 | s0
            if status & unusual or busy:
                record(stamp_ns, decode(rx))
                return s
            dx = high[x1] + x0
            dy = high[y1] + y0
            put(ring, seq % n * size, stamp_ns, dx, dy, status, cpi,
                2 if status & motion_bit else 0, -1)  # fmt: skip
            xt += dx
            yt += dy
            seq += 1
            return s

        seq = published = ints[16]  # nothing to publish yet
        resync_deferred()
        return deferred_poll, resync_deferred, set_busy, publish

    def record(self, stamp_ns: int, m: Motion | None, extra_flags: int = 0) -> None:
        """Add one read to the totals and the ring (under the sequence lock).

        ``m`` None records a failed poll. ``extra_flags`` marks reads made for a
        command (settings, the drain before a CPI change): they take no poll
        slot, so they do not lengthen a lift gap.
        """
        self.publish()  # the fast poll's deferred totals first: added to below
        ints, floats = self.ints, self.floats
        ints[ss.I_VERSION] += 1  # odd: writing
        if m is None:
            dx = dy = status = 0
            quality = QUALITY_NONE
            flags = ss.FLAG_SPI_ERROR
        else:
            dx, dy = m.dx, m.dy
            status = m.status & 0xFFFF
            quality = m.quality
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
                self._update_lift_gap(dx, dy, gap, stamp_ns)
        seq = ints[ss.I_SEQ]
        RECORD.pack_into(
            self.ring,
            seq % self.n * RECORD.size,
            stamp_ns, dx, dy, status, self.cpi_y, flags | extra_flags, quality,
        )  # fmt: skip
        ints[ss.I_SEQ] = seq + 1
        ints[ss.I_STAMP_NS] = stamp_ns
        ints[ss.I_VERSION] += 1  # even: consistent
        self._resync()  # the fast poll goes on from these totals

    def _update_lift_gap(self, dx: int, dy: int, lifted: bool, stamp_ns: int) -> None:
        """Feed one poll to the estimators (its stamp: the fill runs per unit of time);
        add their estimate when it is complete."""
        if lifted and not self.gap.busy:
            self._prime_lift_gap()
        est = self.gap.update(dx, dy, lifted, stamp_ns)
        self._set_gap_busy(self.gap.busy)
        est_m = self.gap_m.update(dx * self.scale_x, dy * self.scale_y, lifted, stamp_ns)
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
        ring, unpack, size = self.ring, RECORD.unpack_from, RECORD.size
        n, seq = self.n, self.seq
        stop = ss.FLAG_LIFT | (ss.FLAG_LOW_QUALITY if self._poor_is_gap else 0)
        ratio = self.scale_x / self.scale_y if self.scale_y else 1.0  # X's CPI next to Y's
        rows = []  # (stamp, dx, dy, metres per count), newest first
        before = None  # the stamp of the read before the oldest of them: its interval
        oldest = max(seq - n + 1, 0)  # the ring's oldest slot still read
        for s in range(seq - 1, max(seq - 1 - self.gap.window, oldest - 1), -1):
            stamp, dx, dy, _status, cpi, flags, _q = unpack(ring, s % n * size)
            if flags & stop:
                before = stamp
                break
            rows.append((stamp, dx, dy, INCH_M / cpi if cpi else self.scale_y))
        else:
            if seq - 1 - len(rows) >= oldest:
                before = unpack(ring, (seq - 1 - len(rows)) % n * size)[0]
        rows.reverse()
        prev = [before, *(r[0] for r in rows)][: len(rows)]
        dts = [None if p is None else (r[0] - p) / 1e9 for r, p in zip(rows, prev, strict=True)]
        last = rows[-1][0] if rows else before  # the newest read's stamp
        self.gap.prime([(r[1], r[2], d) for r, d in zip(rows, dts, strict=True)], last)
        self.gap_m.prime(
            [(r[1] * r[3] * ratio, r[2] * r[3], d) for r, d in zip(rows, dts, strict=True)], last
        )

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
        self._resync()  # the fast poll's copies of the CPI and scales


# --- the process -------------------------------------------------------------------------------
