"""Per-poll sensor displacements from the Beagle node's single 1 kHz polls (``get_samples``).

Pure numpy, no ROS: replies are read duck-typed (attributes of
``mm_interfaces/srv/GetSamples_Response``, or the ``mm_interfaces/msg/SensorPolls`` of a
recording: the same fields), so the monitor, mm-odometry and a replay run this one
implementation.

A client asks ``get_sensor_data`` (monotone totals, per sensor: ``seq`` = polls done,
measured totals in counts and metres) and, for each sensor, ``get_samples`` from the
poll after the previous request up to that ``seq``. :class:`PollTracker` turns that
into **steps**: one per poller tick, paired across sensors, each with its duration,
per sensor the displacement in metres (sensor frame: X right, Y forward), the lift
mask, and whether it is a **gap** step. The pose is then integrated step by step
(:meth:`mm_pc.core.odometry.Odometry.integrate`), so the request rate changes only
how often the pose is shown, never the pose (docs/pose-math.md, "Per-poll integration").

Pairing: the poller polls the sensors of one tick one after the other, each poll stamped
with its own read time (ns, system clock; an older poller stamped all of a tick alike).
A poll of sensor i read at most :data:`MAX_READ_SKEW_NS` after sensor 0's belongs to
that tick (:func:`snap_to_ticks`); the step's stamp is sensor 0's. Each later sensor's
displacement is then moved back to sensor 0's read time by :func:`deskew` (its own
velocity times its read delay): without it ``two-sensor`` read the heading from the two
sensors ~0.1 ms apart, a yaw bias of delay x speed / spacing (1.3 mm per 10 m at
0.5 m/s through the real processes, docs/pose-math.md). Reads that are not polls (a
settings read for a command, flag 16) carry a stamp of their own; their counts are added
to the same sensor's next tick (counts are never dropped). Polls of one sensor in ticks
the other sensor has no poll for (it was down) are added to the next common tick too,
and that step is marked a gap -- except the last poll before a CPI change (a poll_cpi
differs from the next): the poller's drain read at the old CPI, recorded as a poll of
that sensor alone while the others were up.

Gaps: when the polls of an interval are missing (``dropped`` > 0: the ring overran;
the reply ends before the totals' ``seq``; no reply; its counts or metres disagree with
the totals), the interval becomes one gap step carrying the whole displacement from the
totals, so nothing is lost and the caller can mark it.

CPI: each poll is scaled by its own resolution (``poll_cpi`` of the reply, issue 28), so
a CPI change inside a request interval is integrated exactly and is no gap (a tick that
sums polls of two CPIs, e.g. the drain read before the change, adds each at its own).
A reply without ``poll_cpi`` (an old node or recording) has one ``cpi`` for all its
polls: a CPI change inside its interval shows only as polls whose metres disagree with
the totals', and stays a gap step from the totals, as before.

Lifts: a poll counts as lifted when its lift bit or its low-quality bit is set
(:func:`unseen`: the chip saw the floor too poorly to trust the counts, issue 15); on a
chip whose low-quality polls still carry motion (the OTOS, its IMU carried the pose:
:func:`unseen_bits` of the totals' ``chip``) only the lift bit does. The polls of a lifted
sensor are filled by :func:`mm_pc.core.filters.interpolate_lift_gaps`; a step is held
back while a lift of any sensor is open or closed fewer than :data:`LIFT_CONTEXT_POLLS`
polls ago, and the last :data:`LIFT_CONTEXT_POLLS` steps are kept as the filler's left
context, so the steps (and the pose) do not depend on where the request boundaries fell.
"""

from __future__ import annotations

import inspect
import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from mm_pc.core.filters import interpolate_lift_gaps
from mm_pc.core.poll_flags import (  # the bits of GetSamples' flags, defined once
    FLAG_COMMAND_READ,
    FLAG_LIFT,
    FLAG_LOW_QUALITY,
    FLAG_MOTION,
    FLAG_OVERFLOW,
    FLAG_SPI_ERROR,
    FLAG_UNSEEN,
)
from mm_pc.core.sensor_data import Reading
from pln2033 import INCH_M
from pln2033 import chips as chip_registry

__all__ = [
    "FLAG_COMMAND_READ",
    "FLAG_LIFT",
    "FLAG_LOW_QUALITY",
    "FLAG_MOTION",
    "FLAG_OVERFLOW",
    "FLAG_SPI_ERROR",
    "FLAG_UNSEEN",
    "LIFT_CONTEXT_POLLS",
    "PollBatch",
    "PollSteps",
    "PollTracker",
    "SensorTotals",
    "integrate_steps",
    "unseen",
    "unseen_bits",
]


def unseen(flags) -> np.ndarray:
    """Bool array, True where a poll's ``flags`` say its sensor did not see the floor
    (:data:`FLAG_UNSEEN`: lifted, or surface quality below the chip's threshold)."""
    return (np.asarray(flags, dtype=np.int64) & FLAG_UNSEEN) != 0


def unseen_bits(chip: str) -> int:
    """The flags after which a poll of ``chip`` is a gap for the lift filling:
    :data:`FLAG_UNSEEN`, but only :data:`FLAG_LIFT` for a chip whose low-quality polls
    still carry motion (``ChipInfo.poor_polls_carry_motion``: the OTOS's warning, its IMU
    carried the pose; filling them would replace measured motion by a guess). An unknown
    or empty chip name (an old node or recording) keeps FLAG_UNSEEN."""
    if chip:
        try:
            if chip_registry.chip_info(chip).poor_polls_carry_motion:
                return FLAG_LIFT
        except (ValueError, ImportError):
            pass
    return FLAG_UNSEEN


#: Polls on each side of a lift the gap filling may look at (its window must fit).
LIFT_CONTEXT_POLLS = 64

#: Shortest step (s) handed to the integrator (a command's read shares its tick's time).
MIN_DT_S = 1e-6

#: Longest a later sensor's read may follow sensor 0's in one poller tick (ns): the
#: poller reads them one after the other (~0.1 ms apart in Python), longer when the
#: loop was preempted between them; a later read is a tick of its own (a gap).
MAX_READ_SKEW_NS = 20_000_000


def snap_to_ticks(ticks: np.ndarray, stamps: np.ndarray, flags: np.ndarray) -> np.ndarray:
    """``stamps`` (ns) of one sensor's polls moved onto the tick stamps ``ticks`` (sensor
    0's polls, ascending): each poll onto the last tick at or before it, less than
    :data:`MAX_READ_SKEW_NS` before, and only the first poll onto one tick (a second is
    one of a tick sensor 0 missed: it keeps its stamp and is folded as before). Command
    reads keep their own stamp."""
    if not len(ticks) or not len(stamps):
        return stamps
    j = np.searchsorted(ticks, stamps, side="right") - 1
    jj = np.maximum(j, 0)
    ok = (j >= 0) & (stamps - ticks[jj] < MAX_READ_SKEW_NS)
    ok &= (flags & FLAG_COMMAND_READ) == 0
    idx = np.flatnonzero(ok)
    if len(idx) > 1:
        ok[idx[1:][jj[idx[1:]] == jj[idx[:-1]]]] = False
    return np.where(ok, ticks[jj], stamps)


def deskew(d: np.ndarray, delay_ns: np.ndarray, dt_s: np.ndarray, carry: np.ndarray,
           prev_delay: np.ndarray) -> np.ndarray:  # fmt: skip
    """Displacements of steps read ``delay_ns`` after their tick, moved to the tick's time.

    ``d``: (k, n, 2) m; ``delay_ns``: (k, n) each sensor's read after the tick's stamp;
    ``dt_s``: (k,) the steps' lengths; ``carry``: (n, 2) what the previous step moved and
    ``prev_delay``: (n,) its delays (both updated in place). The cumulative displacement
    at a tick is the one read less delay x velocity (the step's own: its ``d`` over the
    sensor's own read interval), so each step gives back the previous step's share:
    nothing is lost and the error stays bounded.
    """
    if not delay_ns.any() and not carry.any():
        prev_delay[:] = 0
        return d
    before = np.concatenate([prev_delay[None, :], delay_ns[:-1]])
    own = np.maximum(dt_s[:, None] * 1e9 + delay_ns - before, 1.0)
    r = np.clip(delay_ns / own, 0.0, 1.0)
    moved = d * r[:, :, None]
    out = d - moved
    out[0] += carry
    out[1:] += moved[:-1]
    carry[:] = moved[-1]
    prev_delay[:] = delay_ns[-1]
    return out


class SensorTotals(NamedTuple):
    """One sensor's monotone totals in one ``get_sensor_data`` reply (a NamedTuple: made
    for every reply of both sensors, where a frozen dataclass took 2 µs each).

    ``seq``: polls done so far; ``stamp_ns``: newest poll (ns); ``x_counts``,
    ``y_counts``: measured counts; ``x_m``, ``y_m``: the same in metres (exact
    across CPI changes); ``x_est_m``, ``y_est_m``: the node's estimate of what
    lifts lost (m, not in the measured totals).
    """

    seq: int
    stamp_ns: int
    x_counts: int
    y_counts: int
    x_m: float
    y_m: float
    x_est_m: float = 0.0
    y_est_m: float = 0.0
    instance_id: int = 0  # the node's identity: another value = a restarted node
    chip: str = ""  # the sensor's chip ('' = not known: an old node or recording)

    @classmethod
    def from_msg(cls, msg) -> SensorTotals:
        """From an ``mm_interfaces/SensorData`` (attributes only), read by the one reader."""
        r = Reading.from_msg(msg)
        return cls(
            seq=r.seq,
            stamp_ns=r.stamp_ns,
            x_counts=r.x_total_counts,
            y_counts=r.y_total_counts,
            x_m=r.x_total,
            y_m=r.y_total,
            x_est_m=r.x_lift_total,
            y_est_m=r.y_lift_total,
            instance_id=r.instance_id,
            chip=r.chip,
        )


@dataclass(frozen=True)
class PollBatch:
    """The polls of one ``get_samples`` reply of one sensor, checked.

    ``first_seq``..``next_seq``: the sequence numbers covered; ``dropped``: polls
    asked for that had left the ring; ``cpi``: resolution at the newest poll;
    ``stamp_ns``, ``dx``, ``dy`` (counts), ``flags``: one entry per poll;
    ``poll_cpi``: each poll's resolution (counts per inch), or None when the reply had
    none (an old node or recording: ``cpi`` then stands for every poll, and a CPI change
    inside the interval can only be found by the totals, as a gap).
    """

    first_seq: int
    next_seq: int
    dropped: int
    cpi: int
    stamp_ns: np.ndarray
    dx: np.ndarray
    dy: np.ndarray
    flags: np.ndarray
    instance_id: int = 0  # the node's identity in the reply (0: not given, e.g. a recording)
    poll_cpi: np.ndarray | None = None

    @property
    def cpis(self) -> np.ndarray:
        """Each poll's resolution (counts per inch): ``poll_cpi``, or ``cpi`` for every poll."""
        if self.poll_cpi is not None:
            return self.poll_cpi
        return np.full(len(self.stamp_ns), self.cpi, np.int64)

    @property
    def one_cpi(self) -> bool:
        """Every poll here at ``cpi`` (always so when the reply gave no per-poll CPI)."""
        pc = self.poll_cpi
        return pc is None or not len(pc) or bool((pc == self.cpi).all())

    @classmethod
    def from_reply(cls, res) -> PollBatch:
        """From a ``GetSamples.Response`` (attributes only); ValueError saying what is wrong."""
        try:
            stamp = np.asarray(res.stamp_ns, dtype=np.int64)
            dx = np.asarray(res.dx, dtype=np.int64)
            dy = np.asarray(res.dy, dtype=np.int64)
            flags = np.asarray(res.flags, dtype=np.int64)
            first, nxt = int(res.first_seq), int(res.next_seq)
            dropped, cpi = int(res.dropped), int(res.cpi)
        except (AttributeError, TypeError, ValueError) as e:
            raise ValueError(f"not a get_samples reply: {e}") from None
        n = len(stamp)
        if not (len(dx) == len(dy) == len(flags) == n):
            raise ValueError(
                f"get_samples reply with {n} stamps, {len(dx)} dx, {len(dy)} dy, "
                f"{len(flags)} flags: every poll needs all four"
            )
        if nxt - first != n or first < 0:
            raise ValueError(
                f"get_samples reply covers seq {first}..{nxt} but holds {n} polls"
            )
        if n and cpi <= 0:
            raise ValueError(f"get_samples reply with {n} polls but cpi {cpi}")
        instance = int(getattr(res, "instance_id", 0))
        try:
            pc = np.asarray(getattr(res, "poll_cpi", ()), dtype=np.int64)
        except (TypeError, ValueError) as e:
            raise ValueError(f"not a get_samples reply: poll_cpi: {e}") from None
        if not len(pc):
            return cls(first, nxt, dropped, cpi, stamp, dx, dy, flags, instance)
        if len(pc) != n:
            raise ValueError(
                f"get_samples reply with {n} polls but {len(pc)} poll_cpi: one per poll or none"
            )
        if pc.min() <= 0:
            raise ValueError(f"get_samples reply with a poll at cpi {int(pc.min())}")
        return cls(first, nxt, dropped, cpi, stamp, dx, dy, flags, instance, pc)

    def __len__(self) -> int:
        return len(self.stamp_ns)

    @classmethod
    def join(cls, replies: Sequence) -> PollBatch:
        """Consecutive replies (or batches) of one sensor as one batch; ValueError if they
        do not follow each other (``next_seq`` of one = ``first_seq`` of the next)."""
        parts = [r if isinstance(r, PollBatch) else cls.from_reply(r) for r in replies]
        if not parts:
            raise ValueError("no get_samples replies to join")
        if len(parts) == 1:
            return parts[0]
        for a, b in itertools.pairwise(parts):
            if b.first_seq != a.next_seq and len(b):
                raise ValueError(f"polls up to seq {a.next_seq}, the next from {b.first_seq}")
        parts = [parts[0], *(p for p in parts[1:] if len(p))]
        cpi = next((p.cpi for p in reversed(parts) if len(p)), parts[-1].cpi)
        stamp_ns, dx, dy, flags = (
            np.concatenate([getattr(p, f) for p in parts])
            for f in ("stamp_ns", "dx", "dy", "flags")
        )
        # per-poll CPIs when any part has them (the others' polls at their reply's cpi)
        known = any(p.poll_cpi is not None for p in parts if len(p))
        pc = np.concatenate([p.cpis for p in parts]) if known else None
        return cls(
            parts[0].first_seq, parts[-1].next_seq, sum(p.dropped for p in parts), cpi,
            stamp_ns, dx, dy, flags, 0, pc,
        )  # fmt: skip


@dataclass(frozen=True)
class PollSteps:
    """Steps ready to integrate, oldest first (one per poller tick, or one per gap).

    ``stamp_ns`` (N,): end of each step (ns); ``dt`` (N,): its length (s, > 0);
    ``d`` (N, n_sensors, 2): sensor-frame displacement (dX right, dY forward) in
    metres, lifted polls filled; ``counts`` (N, n_sensors, 2): the measured counts
    (0 for gap steps); ``lifted`` (N, n_sensors): the sensor's lift or low-quality bit
(:func:`unseen`); ``gap`` (N,):
    True for a step that stands for missing polls (its displacement from the totals).
    """

    stamp_ns: np.ndarray
    dt: np.ndarray
    d: np.ndarray
    counts: np.ndarray
    lifted: np.ndarray
    gap: np.ndarray

    @classmethod
    def empty(cls, n_sensors: int) -> PollSteps:
        return cls(
            np.empty(0, np.int64), np.empty(0), np.empty((0, n_sensors, 2)),
            np.empty((0, n_sensors, 2), np.int64), np.empty((0, n_sensors), bool),
            np.empty(0, bool),
        )  # fmt: skip

    def __len__(self) -> int:
        return len(self.dt)

    @staticmethod
    def concat(parts: Sequence[PollSteps], n_sensors: int) -> PollSteps:
        parts = [p for p in parts if len(p)]
        if not parts:
            return PollSteps.empty(n_sensors)
        if len(parts) == 1:
            return parts[0]
        return PollSteps(*(np.concatenate([getattr(p, f) for p in parts]) for f in _FIELDS))


_FIELDS = ("stamp_ns", "dt", "d", "counts", "lifted", "gap")


@dataclass
class _Pending:
    """One sensor's polls received but not yet turned into steps."""

    stamp: np.ndarray  # the tick's stamp (after :func:`snap_to_ticks`)
    dx: np.ndarray
    dy: np.ndarray
    flags: np.ndarray
    cpi: np.ndarray  # each poll's resolution (counts per inch)
    raw: np.ndarray | None = None  # the stamps as read (this sensor's own read time)

    @classmethod
    def empty(cls) -> _Pending:
        z = np.empty(0, np.int64)
        return cls(z, z, z, z, z, z)

    def add(self, b: PollBatch) -> None:
        self.stamp = np.concatenate([self.stamp, b.stamp_ns])
        self.raw = np.concatenate([self.raw_stamps, b.stamp_ns])
        self.dx = np.concatenate([self.dx, b.dx])
        self.dy = np.concatenate([self.dy, b.dy])
        self.flags = np.concatenate([self.flags, b.flags])
        self.cpi = np.concatenate([self.cpi, b.cpis])

    @property
    def raw_stamps(self) -> np.ndarray:
        return self.stamp if self.raw is None else self.raw

    def drop(self, k: int) -> None:
        self.stamp, self.dx, self.dy, self.flags, self.cpi, self.raw = (
            a[k:] for a in (self.stamp, self.dx, self.dy, self.flags, self.cpi, self.raw_stamps)
        )


class PollTracker:
    """Turns (totals, polls) per request into per-poll steps; one per client of a node.

    Call :meth:`baseline` with the first reply's totals (and again after a node
    restart), then for every later reply :meth:`step` with its totals and the
    ``get_samples`` reply of each sensor (None when it failed or was not asked),
    fetched with ``since_seq`` = :meth:`cursor` and ``max_samples`` = the totals'
    ``seq`` minus it. ``use_lift_estimates``: a gap step adds the node's lift
    estimates of its interval (the per-poll steps fill lifts themselves).
    """

    def __init__(self, n_sensors: int, use_lift_estimates: bool = True) -> None:
        if n_sensors < 1:
            raise ValueError(f"a PollTracker needs at least one sensor, got {n_sensors}")
        self.n = n_sensors
        self.use_lift_estimates = bool(use_lift_estimates)
        self._cursor: list[int] | None = None
        self._unseen = [FLAG_UNSEEN] * n_sensors  # per sensor: a gap's flags (baseline's chips)
        #: gap steps made so far, and why (newest last, at most 200 kept)
        self.gaps = 0
        self.gap_reasons: list[str] = []
        #: polls turned into steps so far (per sensor, all entries incl. command reads)
        self.polls_used = [0] * n_sensors

    # -- state ---------------------------------------------------------------------

    @property
    def started(self) -> bool:
        return self._cursor is not None

    def cursor(self, i: int) -> int | None:
        """The ``since_seq`` to ask sensor ``i``'s polls from (None before a baseline)."""
        return None if self._cursor is None else self._cursor[i]

    def baseline(self, totals: Sequence[SensorTotals]) -> None:
        """Start (again) from these totals: nothing before them is integrated."""
        self._check_totals(totals)
        self._instance = [t.instance_id for t in totals]
        self._unseen = [unseen_bits(t.chip) for t in totals]  # per sensor: a gap's flags
        self._cursor = [t.seq for t in totals]
        self._acc_counts = [(t.x_counts, t.y_counts) for t in totals]  # totals at the cursor
        self._acc_m = [(t.x_m, t.y_m) for t in totals]
        # totals (m) up to the end of the last step made, and the estimates at that reply
        self._emitted_m = [[t.x_m, t.y_m] for t in totals]
        self._est_ref = [(t.x_est_m, t.y_est_m) for t in totals]
        self._last_stamp = max(t.stamp_ns for t in totals)
        self._pending = [_Pending.empty() for _ in range(self.n)]
        self._ctx_counts = np.zeros((0, self.n, 2), np.int64)
        self._ctx_lifted = np.zeros((0, self.n), bool)
        self._ctx_scale = np.zeros((0, self.n))  # metres per count of those ticks
        self._ctx_dt = np.zeros(0)  # their intervals (s): the fill runs per unit of time
        self._carry = np.zeros((self.n, 2))  # :func:`deskew`'s share not yet given back
        self._delay = np.zeros(self.n)  # the read delays (ns) of the last step

    def _check_totals(self, totals: Sequence[SensorTotals]) -> None:
        if len(totals) != self.n:
            raise ValueError(f"expected totals of {self.n} sensor(s), got {len(totals)}")

    def restart_in(self, totals: Sequence[SensorTotals]) -> str:
        """Why these totals come from another node run than the baseline's ('' if the same).

        A changed ``instance_id`` is a restart whatever the counters say (a new
        node that ran longer than the old one has a higher ``seq``); a ``seq``
        that went back is one too (nodes without an identity).
        """
        if self._cursor is None:
            return ""
        self._check_totals(totals)
        for i, t in enumerate(totals):
            if t.instance_id != self._instance[i]:
                return f"sensor {i}'s node identity changed: the node restarted"
            if t.seq < self._cursor[i]:
                return (
                    f"sensor {i}'s seq went back ({self._cursor[i]} -> {t.seq}): "
                    "the node restarted"
                )
        return ""

    # -- one request ------------------------------------------------------------------

    def step(
        self, totals: Sequence[SensorTotals], polls: Sequence[PollBatch | None]
    ) -> PollSteps:
        """The steps this reply makes ready (possibly none; a gap step when polls are missing).

        Raises ValueError before a :meth:`baseline`, for the wrong number of
        sensors, or for totals that went back (a restart: call :meth:`baseline`).
        """
        if self._cursor is None:
            raise ValueError("PollTracker.step before baseline()")
        self._check_totals(totals)
        if len(polls) != self.n:
            raise ValueError(f"expected polls of {self.n} sensor(s), got {len(polls)}")
        restart = self.restart_in(totals)
        if restart:
            raise ValueError(f"{restart}; take a new baseline")
        problem = self._why_not_usable(totals, polls)
        if problem:
            return self._gap(totals, problem)
        for i, (t, b) in enumerate(zip(totals, polls, strict=True)):
            if b is not None and len(b):
                self._pending[i].add(b)
            self._cursor[i] = t.seq
            self._acc_counts[i] = (t.x_counts, t.y_counts)
            self._acc_m[i] = (t.x_m, t.y_m)
        steps = self._pair()
        if not self._pending_any():
            self._est_ref = [(t.x_est_m, t.y_est_m) for t in totals]
        return steps

    def step_many(
        self, items: Sequence[tuple[Sequence[SensorTotals], Sequence[PollBatch | None]]]
    ) -> tuple[PollSteps, list[int]]:
        """:meth:`step` for each ``(totals, polls)`` in turn, in one go: the steps of all of
        them and, per item, how many steps were made up to and including it.

        Exactly what the calls one by one give, whatever the grouping (a client that
        takes replies in batches keeps the pose, the gaps and each reply's share of the
        steps of one that takes them singly). The common case -- every sensor polled in
        the same ticks, no lift, no command read, no CPI change, nothing held back -- is
        paired once for all items; anything else goes item by item through :meth:`step`.
        """
        fast = self._step_many_plain(items)
        if fast is not None:
            return fast
        parts, ends, made = [], [], 0
        for totals, polls in items:
            s = self.step(totals, polls)
            parts.append(s)
            made += len(s)
            ends.append(made)
        return PollSteps.concat(parts, self.n), ends

    def _step_many_plain(self, items) -> tuple[PollSteps, list[int]] | None:
        """:meth:`step_many` for the common case, or None (nothing changed) when it is not.

        The checks are :meth:`step`'s for each item (:meth:`restart_in`,
        :meth:`_why_not_usable` with the cursors moved on item by item), done for all
        items at once; the state left is the one the items one by one leave."""
        n = self.n
        if self._cursor is None or not items or self._pending_any():
            return None
        lens: list[int] = []
        cpi: int | None = None
        cursor = list(self._cursor)
        for totals, polls in items:
            if len(totals) != n or len(polls) != n:
                return None
            k: int | None = None
            for i, (t, b) in enumerate(zip(totals, polls, strict=True)):
                if (
                    b is None or t.seq <= cursor[i] or b.dropped or b.first_seq != cursor[i]
                    or b.next_seq != t.seq or t.instance_id != self._instance[i]
                    or (b.instance_id and t.instance_id and b.instance_id != t.instance_id)
                    or (k is not None and len(b) != k) or (cpi is not None and b.cpi != cpi)
                    or not b.one_cpi
                ):  # fmt: skip
                    return None  # missing, or not the same ticks, or step() would object
                k, cpi = len(b), b.cpi
                cursor[i] = t.seq
            if k is None:
                return None  # no sensors
            lens.append(k)
        if cpi is None:
            return None  # no sensors
        cols = [[polls[i] for _, polls in items] for i in range(n)]
        stamps = [np.concatenate([b.stamp_ns for b in c]) for c in cols]
        first = stamps[0]
        if first[0] <= self._last_stamp or (len(first) > 1 and not (first[1:] > first[:-1]).all()):
            return None
        kk = len(first)
        counts = np.empty((kk, n, 2), np.int64)
        delay = np.zeros((kk, n), np.int64)
        for i, c in enumerate(cols):
            flags = np.concatenate([b.flags for b in c])
            if (flags & (self._unseen[i] | FLAG_COMMAND_READ)).any():
                return None
            if i and not np.array_equal(snap_to_ticks(first, stamps[i], flags), first):
                return None
            delay[:, i] = stamps[i] - first
            counts[:, i, 0] = np.concatenate([b.dx for b in c])
            counts[:, i, 1] = np.concatenate([b.dy for b in c])
        ends = list(itertools.accumulate(lens))
        sums = np.add.reduceat(counts, [0, *ends[:-1]], axis=0)  # (items, n, 2) per item
        tot = np.array(
            [[self._acc_counts[i] for i in range(n)]]
            + [[(t.x_counts, t.y_counts) for t in totals] for totals, _ in items], np.int64
        )
        if not np.array_equal(sums, np.diff(tot, axis=0)):
            return None
        scale = INCH_M / cpi  # cpi > 0: PollBatch checked it for polls
        want = np.diff(np.array(
            [[self._acc_m[i] for i in range(n)]]
            + [[(t.x_m, t.y_m) for t in totals] for totals, _ in items], float
        ), axis=0)  # fmt: skip
        got = sums * scale
        diff = np.abs(want - got)  # math.isclose(got, want, rel_tol=1e-9, abs_tol=1e-12)
        close = (got == want) | (diff <= np.abs(1e-9 * want)) | (diff <= np.abs(1e-9 * got))
        if not (close | (diff <= 1e-12)).all():
            return None  # the totals disagree (an old node's CPI change): step() decides
        # usable: the state the items one by one leave behind
        last = items[-1][0]
        self._cursor = [t.seq for t in last]
        self._acc_counts = [(t.x_counts, t.y_counts) for t in last]
        self._acc_m = [(t.x_m, t.y_m) for t in last]
        self._est_ref = [(t.x_est_m, t.y_est_m) for t in last]
        for i in range(n):
            self.polls_used[i] += kk
        for s in sums.tolist():  # added item by item, as step() adds them
            for i in range(n):
                self._emitted_m[i][0] += float(s[i][0] * scale)
                self._emitted_m[i][1] += float(s[i][1] * scale)
        dt = np.maximum(np.diff(first, prepend=self._last_stamp) / 1e9, MIN_DT_S)
        self._last_stamp = int(first[-1])
        lifted = np.zeros((kk, n), bool)
        self._ctx_counts = np.concatenate([self._ctx_counts, counts])[-LIFT_CONTEXT_POLLS:]
        self._ctx_lifted = np.concatenate([self._ctx_lifted, lifted])[-LIFT_CONTEXT_POLLS:]
        self._ctx_scale = np.concatenate([self._ctx_scale, np.full((kk, n), scale)])[
            -LIFT_CONTEXT_POLLS:
        ]
        self._ctx_dt = np.concatenate([self._ctx_dt, dt])[-LIFT_CONTEXT_POLLS:]
        d = deskew(counts.astype(float) * scale, delay, dt, self._carry, self._delay)
        return PollSteps(first, dt, d, counts, lifted, np.zeros(kk, bool)), ends

    def _why_not_usable(self, totals, polls) -> str:
        cursor = self._cursor
        if cursor is None:
            raise ValueError("PollTracker: no baseline")  # step() checks it first
        for i, (t, b) in enumerate(zip(totals, polls, strict=True)):
            want = t.seq - cursor[i]
            if want == 0:
                continue
            if b is None:
                return f"sensor {i}: no polls for seq {cursor[i]}..{t.seq}"
            if b.instance_id and t.instance_id and b.instance_id != t.instance_id:
                return f"sensor {i}: polls from another node run than the totals"
            if b.dropped or b.first_seq != cursor[i]:
                return (
                    f"sensor {i}: {max(b.dropped, b.first_seq - cursor[i])} polls "
                    "had left the node's ring buffer"
                )
            if b.next_seq != t.seq:
                return f"sensor {i}: polls up to seq {b.next_seq}, totals at {t.seq}"
            ax, ay = self._acc_counts[i]
            sx, sy = int(b.dx.sum()), int(b.dy.sum())
            if (sx, sy) != (t.x_counts - ax, t.y_counts - ay):
                return (
                    f"sensor {i}: polls sum to ({sx}, {sy}) counts, the totals moved "
                    f"({t.x_counts - ax}, {t.y_counts - ay})"
                )
            mx, my = self._acc_m[i]
            if b.one_cpi:
                scale = INCH_M / b.cpi
                gx, gy = sx * scale, sy * scale
            else:  # each poll at its own CPI, as the node's totals add them
                per = INCH_M / b.cpis
                gx, gy = float((b.dx * per).sum()), float((b.dy * per).sum())
            for got, want_m in ((gx, t.x_m - mx), (gy, t.y_m - my)):
                if not math.isclose(got, want_m, rel_tol=1e-9, abs_tol=1e-12):
                    if b.poll_cpi is None:  # an old node or recording: no per-poll CPI
                        return f"sensor {i}: the CPI changed within the interval"
                    return (
                        f"sensor {i}: its polls at their own CPI come to "
                        f"({gx:.9g}, {gy:.9g}) m, the totals moved "
                        f"({t.x_m - mx:.9g}, {t.y_m - my:.9g}) m"
                    )
        return ""

    def _pending_any(self) -> bool:
        return any(len(p.stamp) for p in self._pending)

    def _gap(self, totals: Sequence[SensorTotals], why: str) -> PollSteps:
        """One step with the totals' displacement since the last step; forget the polls."""
        d = np.empty((1, self.n, 2))
        for i, t in enumerate(totals):
            ex, ey = self._emitted_m[i]
            gx, gy = t.x_m - ex, t.y_m - ey
            if self.use_lift_estimates:
                gx += t.x_est_m - self._est_ref[i][0]
                gy += t.y_est_m - self._est_ref[i][1]
            d[0, i] = gx, gy
        d[0] += self._carry  # the read-delay share held back by the last steps
        self._carry[:], self._delay[:] = 0.0, 0.0
        stamp = max(t.stamp_ns for t in totals)
        dt = max((stamp - self._last_stamp) / 1e9, MIN_DT_S)
        self.gaps += 1
        self.gap_reasons = [*self.gap_reasons[-199:], why]
        self.baseline(totals)
        return PollSteps(
            np.array([stamp], np.int64), np.array([dt]), d,
            np.zeros((1, self.n, 2), np.int64), np.zeros((1, self.n), bool),
            np.array([True]),
        )  # fmt: skip

    # -- pairing and lift filling -------------------------------------------------------

    def _same_ticks(self, pend: list[_Pending]):
        """The common case, cheaply: every sensor holds polls of the same poller ticks (their
        stamps equal after :func:`snap_to_ticks`) and none read for a command. Returns
        (ticks, counts, lifted, folded, used, scale, metres) as :meth:`_match_ticks`
        would, or None."""
        first = pend[0].stamp
        k = len(first)
        for p in pend:
            if len(p.stamp) != k or (p.flags & FLAG_COMMAND_READ).any():
                return None
            if p is not pend[0] and not np.array_equal(p.stamp, first):
                return None
        if k > 1 and not (first[1:] > first[:-1]).all():
            return None  # repeated stamps: the general path sums them
        counts = np.empty((k, self.n, 2), np.int64)
        lifted = np.empty((k, self.n), bool)
        scale = np.empty((k, self.n))
        for i, p in enumerate(pend):
            counts[:, i, 0] = p.dx
            counts[:, i, 1] = p.dy
            lifted[:, i] = (p.flags & self._unseen[i]) != 0
            scale[:, i] = INCH_M / np.maximum(p.cpi, 1)
        return first, counts, lifted, np.zeros(k, bool), [k] * self.n, scale, None

    def _match_ticks(self, pend: list[_Pending]):
        """Polls paired by stamp: ticks present for every sensor (real polls, not command
        reads); each poll summed into the tick at or after it. (None, ...) when no tick.

        Also each tick's metres per count (``scale`` (k, n): its own poll's CPI) and,
        when polls of other CPIs were summed into a tick (the drain read before a CPI
        change, polls folded across one), ``metres`` (k, n, 2): every tick's polls each
        at its own CPI, used for those ticks (else None)."""
        real = [p.stamp[(p.flags & FLAG_COMMAND_READ) == 0] for p in pend]
        ticks = real[0]
        for s in real[1:]:
            ticks = np.intersect1d(ticks, s, assume_unique=False)
        ticks = np.unique(ticks)
        if not len(ticks):
            return None, None, None, None, None, None, None
        k = len(ticks)
        counts = np.zeros((k, self.n, 2), np.int64)
        lifted = np.zeros((k, self.n), bool)
        folded = np.zeros(k, bool)
        scale = np.zeros((k, self.n))
        metres = np.zeros((k, self.n, 2))
        mixed = False
        used = []
        for i, p in enumerate(pend):
            m = int(np.searchsorted(p.stamp, ticks[-1], side="right"))
            idx = np.searchsorted(ticks, p.stamp[:m], side="left")  # the tick at or after
            np.add.at(counts[:, i, 0], idx, p.dx[:m])
            np.add.at(counts[:, i, 1], idx, p.dy[:m])
            own = p.stamp[:m] == ticks[idx]
            lifted[idx[own], i] = (p.flags[:m][own] & self._unseen[i]) != 0
            per = INCH_M / np.maximum(p.cpi[:m], 1)
            scale[idx[own], i] = per[own]
            np.add.at(metres[:, i, 0], idx, p.dx[:m] * per)
            np.add.at(metres[:, i, 1], idx, p.dy[:m] * per)
            mixed = mixed or bool((per != scale[idx, i]).any())
            # polls this sensor made while another had none -- but not those of a tick
            # whose other polls fell before the baseline (the totals of the sensors
            # of one reply are read one after the other, so they may end a tick apart)
            extra = ~own & ((p.flags[:m] & FLAG_COMMAND_READ) == 0)
            extra &= p.stamp[:m] > self._last_stamp
            # nor the last poll before a CPI change: the poller's drain read at the old CPI
            # (recorded as a poll of that sensor alone); the other sensors were not down
            extra[:-1] &= p.cpi[: m - 1] == p.cpi[1:m]
            folded[idx[extra]] = True
            used.append(m)
        return ticks, counts, lifted, folded, used, scale, (metres if mixed else None)

    def _pair(self) -> PollSteps:
        pend = self._pending
        if any(len(p.stamp) == 0 for p in pend):
            return PollSteps.empty(self.n)
        p0 = pend[0]
        ticks0 = p0.raw_stamps[(p0.flags & FLAG_COMMAND_READ) == 0]
        for p in pend[1:]:  # each later sensor's polls onto sensor 0's ticks
            p.stamp = snap_to_ticks(ticks0, p.raw_stamps, p.flags)
        same = self._same_ticks(pend)
        if same is not None:
            ticks, counts, lifted, folded, used, scale, metres = same
        else:
            ticks, counts, lifted, folded, used, scale, metres = self._match_ticks(pend)
            if ticks is None:
                return PollSteps.empty(self.n)
        k = len(ticks)
        cut = self._ready(lifted)
        if cut == 0:
            return PollSteps.empty(self.n)
        delay = np.zeros((cut, self.n), np.int64)
        for i, p in enumerate(pend):  # read delays: taken before they leave the pending lists
            if i:
                pos = np.minimum(np.searchsorted(p.stamp, ticks[:cut]), len(p.stamp) - 1)
                own = p.stamp[pos] == ticks[:cut]
                delay[:, i] = np.where(own, p.raw_stamps[pos] - ticks[:cut], 0)
        # polls up to the last tick taken leave the pending lists
        for i, p in enumerate(pend):
            m = int(np.searchsorted(p.stamp, ticks[cut - 1], side="right")) if cut < k else used[i]
            self.polls_used[i] += m
            p.drop(m)
        for j in np.flatnonzero(folded[:cut]):
            self.gaps += 1
            self.gap_reasons = [
                *self.gap_reasons[-199:],
                f"a sensor polled alone (another was down) up to {int(ticks[j])} ns",
            ]
        dt_all = np.maximum(np.diff(ticks, prepend=self._last_stamp) / 1e9, MIN_DT_S)
        filled = self._fill(counts, lifted, cut, scale, dt_all)
        if metres is not None:  # ticks that summed polls of another CPI: each at its own
            exact = metres[:cut]
            filled = np.where(lifted[:cut, :, None], filled, exact)
        stamps = ticks[:cut]
        dt = dt_all[:cut]
        d = deskew(filled, delay, dt, self._carry, self._delay)
        self._last_stamp = int(stamps[-1])
        for i in range(self.n):
            s_i = scale[:cut, i]
            if metres is None and (s_i == s_i[0]).all():
                self._emitted_m[i][0] += float(counts[:cut, i, 0].sum() * s_i[0])
                self._emitted_m[i][1] += float(counts[:cut, i, 1].sum() * s_i[0])
            else:  # a CPI change among them: each tick at its own
                em = counts[:cut, i] * s_i[:, None] if metres is None else metres[:cut, i]
                self._emitted_m[i][0] += float(em[:, 0].sum())
                self._emitted_m[i][1] += float(em[:, 1].sum())
        ctx_c = np.concatenate([self._ctx_counts, counts[:cut]])[-LIFT_CONTEXT_POLLS:]
        ctx_l = np.concatenate([self._ctx_lifted, lifted[:cut]])[-LIFT_CONTEXT_POLLS:]
        ctx_s = np.concatenate([self._ctx_scale, scale[:cut]])[-LIFT_CONTEXT_POLLS:]
        self._ctx_counts, self._ctx_lifted, self._ctx_scale = ctx_c, ctx_l, ctx_s
        self._ctx_dt = np.concatenate([self._ctx_dt, dt])[-LIFT_CONTEXT_POLLS:]
        return PollSteps(stamps, dt, d, counts[:cut], lifted[:cut], folded[:cut])

    @staticmethod
    def _ready(lifted: np.ndarray) -> int:
        """How many leading ticks can be made steps: up to the start of the first lift
        that closed fewer than LIFT_CONTEXT_POLLS ticks before the newest (or is open)."""
        k = len(lifted)
        any_lift = np.asarray(lifted.any(axis=1))
        late = np.flatnonzero(any_lift[max(0, k - LIFT_CONTEXT_POLLS) :])
        if not len(late):
            return k
        j = max(0, k - LIFT_CONTEXT_POLLS) + int(late[0])
        while j > 0 and any_lift[j - 1]:
            j -= 1
        return j

    def _fill(
        self, counts: np.ndarray, lifted: np.ndarray, cut: int, scale: np.ndarray, dt: np.ndarray
    ) -> np.ndarray:
        """Metres of the first ``cut`` ticks (``scale`` (k, n): each tick's metres per
        count; ``dt`` (k,): each tick's interval, s) with lifted polls filled per unit of
        time (:mod:`pln2033.lift_fill`): in counts where the filler's window is at one
        CPI, in metres where a CPI change falls into it."""
        out = counts[:cut].astype(float) * scale[:cut, :, None]
        if not lifted.any():
            return out
        c0 = len(self._ctx_counts)
        allc = np.concatenate([self._ctx_counts, counts])
        alll = np.concatenate([self._ctx_lifted, lifted])
        alls = np.concatenate([self._ctx_scale, scale])
        alld = np.concatenate([self._ctx_dt, dt])
        for i in range(self.n):
            if lifted[:cut, i].any():
                s_i = alls[:, i]
                if (s_i == s_i[-1]).all():
                    f = interpolate_lift_gaps(allc[:, i, :], alll[:, i], alld) * s_i[-1]
                else:
                    f = interpolate_lift_gaps(allc[:, i, :] * s_i[:, None], alll[:, i], alld)
                out[:, i, :] = f[c0 : c0 + cut]
        return out


def integrate_steps(
    odometry, steps: PollSteps, d: np.ndarray | None = None, return_residual: bool = False
):
    """``odometry.integrate`` over the steps (``d``: their displacements after calibration,
    default ``steps.d``); the lift mask goes along where ``integrate`` takes ``lifted``
    (``two-sensor`` then drops a lifted sensor's equations). Returns the (N, 3) poses, with
    ``return_residual`` also the (N,) residuals (as ``integrate`` gives them)."""
    d = steps.d if d is None else d
    kw = {"return_residual": True} if return_residual else {}
    if steps.lifted.any() and "lifted" in inspect.signature(odometry.integrate).parameters:
        return odometry.integrate(steps.dt, d, lifted=steps.lifted, **kw)
    return odometry.integrate(steps.dt, d, **kw)
