"""THE fusion loop: input records into a :class:`~mm_pc.core.fusion.ekf.PoseEKF` in stamp order.

:class:`FusionCore` gates, re-acquires, picks the motion model (mouse, wheels standing in)
and looks up wires, and counts every input per source. ``mm-fusion`` pushes the records it
reads from its topics; the simulated-run replay (:func:`mm_pc.sim.field_run.run_fusion`, and
through it ``mm-bench maps`` and the monitor's Maps tab) pushes the records of a simulated
run one request at a time (:meth:`FusionCore.step`). So every fusion figure in the docs comes
from the loop the node runs. Records and their readers are in :mod:`.inputs`.
"""

from __future__ import annotations

import heapq
import itertools
import math
from collections import deque
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

import numpy as np

from mm_pc.core.fixes.perimeter import PerimeterSegment, nearest_segment
from mm_pc.core.fusion.ekf import GATE_1D, GATE_2D, PoseEKF, pose_increment
from mm_pc.core.fusion.inputs import (
    AxisInput,
    HeadingInput,
    MotionInput,
    PositionInput,
    RangeInput,
)

__all__ = ["FusionCore", "SourceCounts", "increment_noise"]


def increment_noise(
    fwd: float, left: float, dtheta: float, q_pos: float, q_yaw_dist: float, q_yaw_turn: float
) -> np.ndarray:
    """3x3 covariance of an increment: the distance/turn random walk of the EKF (:mod:`.ekf`)."""
    d = math.hypot(fwd, left)
    return np.diag([q_pos * d, q_pos * d, q_yaw_dist * d + q_yaw_turn * abs(dtheta)])


# --- the time-ordered front end -----------------------------------------------------------------

_COUNT_KINDS = ("accepted", "rejected", "invalid", "unusable", "stale", "reacquired")
_PRIORITY = {"mouse": 0, "wheel": 1}


@dataclass
class SourceCounts:
    """Per-source counts. ``rejected``: failed the filter's gate; ``reacquired``: applied
    ungated after too many rejections in a row (also counted in ``accepted``)."""

    accepted: int = 0
    rejected: int = 0
    invalid: int = 0
    unusable: int = 0
    stale: int = 0
    reacquired: int = 0
    last_reason: str = ""
    in_a_row: int = field(default=0, repr=False)

    def as_dict(self) -> dict[str, int]:
        return {k: getattr(self, k) for k in _COUNT_KINDS}


class FusionCore:
    """Feeds input records to a :class:`PoseEKF` in stamp order and counts what happened.

    Order. Records are queued and processed in stamp order, each once no
    periodic source (odometry, GPS, compass, beacons) can still deliver an
    older one: source s, last heard at stamp t_s with an average interval
    p_s, is not expected before t_s + p_s, so a record at stamp t goes in
    when t < t_s + 0.9 p_s for every such source (0.1 p_s for jitter; t <= t_s
    for a source heard only once, whose interval is not known yet). A
    measurement is thus applied after the prediction to its time and before
    the next, whichever topic's queue runs ahead (at a fast replay they drift
    apart by seconds of stamp time; on a robot a fix comes some 100 ms late).
    The output lags by the slowest source's latency plus a tenth of its
    interval. A source not heard for ``max_delay_s`` beyond its interval
    (behind the newest odometry stamp) is no longer waited for, and a record
    of it that still comes more than ``max_delay_s`` behind the processed
    odometry is *stale* and dropped. Wire contacts (events, no
    interval) and unstamped headings are never waited for; a late contact
    is applied on arrival. With no odometry at all, or after :meth:`flush`
    (the caller's "no odometry for a while"), records are processed on
    arrival. An odometry increment faster than ``max_speed`` (m/s) is
    *invalid* and starts a new baseline (a reset or corrupt odometry).

    Motion model. Mouse odometry is the motion model; wheel odometry is a
    stand-in used only when the mouse odometry has been silent for more than
    ``stale_s`` seconds of stamp time (a lifted sensor, a stopped mm-odometry):
    the wheels then cover from their pose at the mouse's last stamp, so no
    stretch is lost, with the noise ``wheel_noise`` (q_pos m^2/m,
    q_yaw_dist rad^2/m, q_yaw_turn rad^2/rad). When mouse odometry returns it
    starts from a new baseline (its increment over the silence is not
    trusted). A frame change or a stamp running backwards three times in a
    row also starts a new baseline.

    Corrections: GPS and trilateration-like positions (gate :data:`GATE_2D`),
    headings and single ranges (:data:`GATE_1D`), wire contacts (ungated, the
    wire found with :func:`mm_pc.core.fixes.perimeter.nearest_segment` when the
    contact does not name it). After ``reacquire_after`` gate rejections in
    a row from one source, its next reading is applied ungated (the filter
    is taken to be lost, as in :func:`mm_pc.sim.field_run.run_fusion`; 0 = never).

    ``notices`` collects (key, text) lines worth logging (motion model
    switches, re-acquisitions, stale or backwards stamps); the caller drains it.
    """

    def __init__(
        self,
        ekf: PoseEKF,
        *,
        wheel_noise: Sequence[float] = (0.03**2, 0.03**2, 0.03**2),
        stale_s: float = 0.5,
        max_delay_s: float = 1.0,
        reacquire_after: int = 10,
        wires: Sequence[PerimeterSegment] = (),
        wire_var: float = 0.03**2,
        wire_max_distance: float = 2.0,
        max_speed: float = 5.0,
        max_queue: int = 10000,
    ) -> None:
        if len(wheel_noise) != 3 or not all(math.isfinite(q) and q >= 0 for q in wheel_noise):
            raise ValueError(f"wheel_noise must be three numbers >= 0, got {list(wheel_noise)}")
        for name, v in (("stale_s", stale_s), ("max_delay_s", max_delay_s)):
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be a finite number of seconds > 0, got {v}")
        if not (math.isfinite(max_speed) and max_speed > 0):
            raise ValueError(f"max_speed must be a finite number of m/s > 0, got {max_speed}")
        if reacquire_after < 0 or max_queue < 1:
            raise ValueError("reacquire_after must be >= 0 and max_queue >= 1")
        self.ekf = ekf
        self.wheel_noise = tuple(float(q) for q in wheel_noise)
        self.stale_s = float(stale_s)
        self.max_delay_s = float(max_delay_s)
        self.reacquire_after = int(reacquire_after)
        self.wires = tuple(wires)
        self.wire_var = float(wire_var)
        self.wire_max_distance = float(wire_max_distance)
        self.max_speed = float(max_speed)
        self.max_queue = int(max_queue)
        self.counts: dict[str, SourceCounts] = {}
        self.notices: list[tuple[str, str]] = []
        #: 'mouse', 'wheel' or None (no increment applied yet).
        self.motion_source: str | None = None
        #: stamp (s) of the newest processed record, None before any.
        self.stamp: float | None = None
        #: the last applied increment (fwd m, left m, dtheta rad, dt s), for the twist.
        self.last_increment: tuple[float, float, float, float] | None = None
        self._queue: list = []
        self._seq = itertools.count()
        self._pushed: dict[str, float] = {}  # newest stamp pushed per odometry source
        self._heard: dict[str, float] = {}  # newest stamp per periodic source
        self._period: dict[str, float] = {}  # average interval (s) per periodic source
        self._backwards: dict[str, int] = {}
        self._idle = False
        self._hold = False  # inside step(): queue only
        self._mouse_prev: MotionInput | None = None
        self._mouse_seen: float | None = None  # newest processed mouse stamp
        self._wheel_hist: deque[MotionInput] = deque()
        self._motion_stamp: float | None = None  # newest processed odometry stamp

    # -- bookkeeping ------------------------------------------------------------------------

    def count(self, source: str, kind: str, reason: str = "") -> None:
        """Count one input of ``source`` as ``kind`` (one of the SourceCounts fields)."""
        c = self.counts.setdefault(source, SourceCounts())
        setattr(c, kind, getattr(c, kind) + 1)
        if reason:
            c.last_reason = reason

    @property
    def idle(self) -> bool:
        """True after :meth:`flush` until the next odometry record (records go in on arrival)."""
        return self._idle

    @property
    def mouse_pose(self) -> MotionInput | None:
        """The mouse odometry record the estimate is at (its odom pose), or None.

        None while the wheels are the motion model or before any mouse record: then
        the estimate does not sit on a mouse pose. For map -> odom = estimate *
        inverse(this pose).
        """
        return self._mouse_prev if self.motion_source == "mouse" else None

    @property
    def pending(self) -> int:
        """Records waiting for the odometry to reach their stamp."""
        return len(self._queue)

    # -- input ------------------------------------------------------------------------------

    def push(self, record) -> None:
        """Queue one record and process everything that can no longer be overtaken."""
        if isinstance(record, MotionInput):
            if not self._accept_motion_stamp(record):
                return
            self._idle = False
        elif record.stamp is None:
            self._measure(record)
            return
        elif (
            self._motion_stamp is not None and record.stamp < self._motion_stamp - self.max_delay_s
        ):
            reason = (
                f"stamp {self._motion_stamp - record.stamp:.2f} s older than the odometry "
                f"(> max_delay {self.max_delay_s:g} s)"
            )
            self.count(record.source, "stale", reason)
            self.notices.append((f"stale {record.source}", f"{record.source}: {reason}"))
            return
        if not isinstance(record, AxisInput):
            self.heard(record.source, record.stamp)
        prio = _PRIORITY.get(record.source, 2)
        # same stamp: odometry first, then the fixes by source name (not by arrival: the
        # result must not depend on which topic came first)
        key = (record.stamp, prio, record.source, next(self._seq))
        heapq.heappush(self._queue, (*key, record))
        if self._hold:
            return
        self._drain()
        while len(self._queue) > self.max_queue:
            self._process(heapq.heappop(self._queue)[-1])

    def step(self, records: Iterable) -> None:
        """Push every record of one moment of a replay and process them all now.

        A replay knows that nothing older can still come, so it need not wait for the
        sources' intervals; the records go in the order :meth:`push` gives them (stamp,
        odometry first, then the fixes by source name), as on the node.
        """
        self._hold = True
        try:
            for record in records:
                self.push(record)
        finally:
            self._hold = False
        self._drain(everything=True)

    def heard(self, source: str, stamp: float | None) -> None:
        """Periodic ``source`` delivered something stamped ``stamp`` s (used or not).

        Also for readings that were not usable (a GPS without fix still ticks),
        so that the source's next record is expected at the right time.
        """
        if stamp is None or not math.isfinite(stamp):
            return
        last = self._heard.get(source)
        if last is not None and stamp <= last:
            return
        if last is not None:
            gap = stamp - last
            p = self._period.get(source)
            self._period[source] = gap if p is None else 0.8 * p + 0.2 * gap
        self._heard[source] = stamp

    def interval(self, source: str) -> float | None:
        """Average interval (s) between ``source``'s messages, None before its second."""
        return self._period.get(source)

    def flush(self) -> None:
        """Process everything queued; until the next odometry record, process on arrival."""
        self._idle = True
        self._drain(everything=True)

    def _accept_motion_stamp(self, rec: MotionInput) -> bool:
        last = self._pushed.get(rec.source)
        if last is not None and rec.stamp < last:
            n = self._backwards.get(rec.source, 0) + 1
            self._backwards[rec.source] = n
            if n < 3:
                reason = f"stamp went backwards by {last - rec.stamp:.3f} s"
                self.count(rec.source, "invalid", reason)
                self.notices.append((f"backwards {rec.source}", f"{rec.source}: {reason}"))
                return False
            self.notices.append(
                (f"restart {rec.source}", f"{rec.source}: time jumped back; new baseline")
            )
            self._drain(everything=True)
            self._forget(rec.source)
        self._backwards[rec.source] = 0
        self._pushed[rec.source] = rec.stamp
        return True

    def _forget(self, source: str) -> None:
        if source == "mouse":
            self._mouse_prev, self._mouse_seen = None, None
        else:
            self._wheel_hist.clear()
        self._motion_stamp = None
        self._heard.clear()
        self._period.clear()

    def _horizon(self) -> tuple[float, float]:
        """(once, strict): a record at stamp t can no longer be overtaken if t <= once
        (sources heard only once: their last stamp) and t < strict (the others:
        t_s + 0.9 p_s)."""
        if self._idle or not self._pushed:
            return math.inf, math.inf
        newest = max(self._pushed.values())
        once = strict = math.inf
        for source, t in self._heard.items():
            p = self._period.get(source)
            if t + (p or 0.0) + self.max_delay_s < newest:
                continue  # gone quiet: not waited for
            if p is None:
                once = min(once, t)
            else:
                strict = min(strict, t + 0.9 * p)
        return once, strict

    def _drain(self, everything: bool = False) -> None:
        once, strict = (math.inf, math.inf) if everything else self._horizon()
        q = self._queue
        while q and q[0][0] <= once and (q[0][0] < strict or everything):
            self._process(heapq.heappop(q)[-1])

    def _process(self, rec) -> None:
        if isinstance(rec, MotionInput):
            if rec.source == "mouse":
                self._mouse(rec)
            else:
                self._wheel(rec)
            self._motion_stamp = max(self._motion_stamp or rec.stamp, rec.stamp)
        else:
            self._measure(rec)
        if rec.stamp is not None:
            self.stamp = rec.stamp if self.stamp is None else max(self.stamp, rec.stamp)

    # -- motion -----------------------------------------------------------------------------

    def _predict(self, rec: MotionInput, before: MotionInput, q=None) -> None:
        try:
            inc = pose_increment(before.pose, rec.pose)
            dt = rec.stamp - before.stamp
            moved = math.hypot(inc[0], inc[1])
            if moved > self.max_speed * dt + 0.05:
                raise ValueError(
                    f"odometry jumped {moved:.2f} m in {dt:.3f} s (> max_speed "
                    f"{self.max_speed:g} m/s); new baseline"
                )
            self.ekf.predict(*inc, q=q(inc) if q else None)
        except ValueError as exc:
            self.count(rec.source, "invalid", str(exc))
            self.notices.append((f"jump {rec.source}", f"{rec.source}: {exc}"))
            return
        self.last_increment = (*inc, dt)
        self.count(rec.source, "accepted")

    def _mouse(self, rec: MotionInput) -> None:
        prev = self._mouse_prev
        self._mouse_prev = rec
        self._mouse_seen = rec.stamp
        if prev is None or prev.frame_id != rec.frame_id or self.motion_source == "wheel":
            if self.motion_source == "wheel":
                self.notices.append(("motion", "mouse odometry is back: it is the motion model"))
            self.motion_source = "mouse"
            self.count(rec.source, "accepted")
            return
        self._predict(rec, prev)

    def _wheel(self, rec: MotionInput) -> None:
        hist = self._wheel_hist
        if hist and hist[-1].frame_id != rec.frame_id:
            hist.clear()
        seen = self._mouse_seen
        mouse_alive = seen is not None and rec.stamp - seen <= self.stale_s
        if mouse_alive or not hist:
            self.count(rec.source, "accepted")
        else:
            if self.motion_source == "wheel":
                anchor = hist[-1]
            else:
                before = [h for h in hist if seen is not None and h.stamp <= seen]
                anchor = before[-1] if before else (hist[0] if seen is not None else hist[-1])
                self.motion_source = "wheel"
                silent = "never heard" if seen is None else f"silent {rec.stamp - seen:.2f} s"
                self.notices.append(
                    ("motion", f"mouse odometry {silent}: wheel odometry is the motion model")
                )
            self._predict(rec, anchor, q=lambda inc: increment_noise(*inc, *self.wheel_noise))
        hist.append(rec)
        keep_from = rec.stamp - self.stale_s - 1.0
        while hist and hist[0].stamp < keep_from:
            hist.popleft()

    # -- corrections ------------------------------------------------------------------------

    def _measure(self, rec) -> None:
        c = self.counts.setdefault(rec.source, SourceCounts())
        ungated = self.reacquire_after > 0 and c.in_a_row >= self.reacquire_after
        try:
            outcome = self._apply(rec, ungated)
        except ValueError as exc:
            self.count(rec.source, "invalid", str(exc))
            return
        if outcome == "unusable":
            self.count(rec.source, "unusable", "no perimeter wire near the estimate")
            return
        if outcome:
            c.accepted += 1
            c.in_a_row = 0
            if ungated:
                c.reacquired += 1
                self.notices.append(
                    (f"reacquire {rec.source}", f"{rec.source}: applied ungated to re-acquire")
                )
        else:
            c.rejected += 1
            c.in_a_row += 1
            d2 = self.ekf.last_distance2
            c.last_reason = f"failed the gate (Mahalanobis^2 {d2:.3g})" if d2 is not None else ""

    def _apply(self, rec, ungated: bool):
        ekf = self.ekf
        if isinstance(rec, PositionInput):
            return ekf.update_position(
                rec.xy, rec.cov, gate=None if ungated else GATE_2D, gate_cov=rec.gate_cov
            )
        if isinstance(rec, HeadingInput):
            return ekf.update_heading(rec.yaw, rec.var, gate=None if ungated else GATE_1D)
        if isinstance(rec, RangeInput):
            return ekf.update_ranges(
                [rec.beacon], [rec.range], rec.sigma, gate=None if ungated else GATE_1D
            )
        if isinstance(rec, AxisInput):
            axis, value = rec.axis, rec.value
            if axis is None:
                s = ekf.state
                if not self.wires:
                    return "unusable"
                wire = nearest_segment((s[0], s[1]), self.wires, self.wire_max_distance)
                if wire is None:
                    return "unusable"
                axis, value = wire.axis, wire.value
            if value is None:
                raise ValueError(f"wire contact {rec!r}: an axis needs its value (m)")
            return ekf.update_axis(axis, value, self.wire_var)
        raise ValueError(f"unknown input record {rec!r}")
