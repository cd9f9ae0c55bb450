"""The monitor's processing pipeline, without Qt or ROS.

Every reply of mm_beagle (live, or replayed from a recording) goes through
:meth:`MonitorSession.process`:

1. **Deltas from the monotone totals.** The displacement of a sensor since
   the previous reply is ``total - previous total`` (plus the node's lift-gap
   estimates when enabled). A slow reply therefore just covers a longer
   interval: nothing is counted twice and nothing is lost, whatever the
   network does; and the monitor takes no counts away from other clients.
   A changed node identity (``instance_id``, drawn at each node start) or a
   ``seq`` that goes back means the node restarted: the reply becomes the new
   baseline (an event is logged; no jump on the map) -- also when the new node
   has run longer than the old one, so that its ``seq`` is higher.
2. **Median filter** per sensor and axis (optional, :mod:`mm_pc.core.filters`).
3. **Calibration** (mounting angle and scale, :mod:`mm_pc.core.calibration`).
4. **Pose math** (:mod:`mm_pc.core.odometry`, method selectable; the mounts
   with the calibration's fitted positions); while a calibration run is open
   the raw displacements of a recording step are also kept, and the pose
   carries on with the calibration in force (a frozen pose would resume where
   the robot no longer is). When the reply
   carries the single polls its totals cover (``Reply.polls``, fetched with
   ``get_samples`` by the bridge), the pose is integrated **per poll**
   (:class:`mm_pc.core.polls.PollTracker`), so the request rate, a pause or a
   slow link change only how often the pose is shown; polls that are missing
   (ring overrun, a failed fetch) become one **gap** step from the totals,
   counted in ``stats.gaps``, logged, and kept in :attr:`MonitorSession.gaps`
   for the map. Without polls (an old recording) the pose is integrated per reply.
   A CPI change is no gap: each poll carries its CPI (``poll_cpi``, issue 28) and is
   integrated at it; the change is counted in ``stats.cpi_changes``, logged and kept in
   :attr:`MonitorSession.cpi_changes` (where the robot was). Polls without ``poll_cpi``
   (an old node or recording) still make an interval with a CPI change a gap step.
5. One row in the :class:`~.history.History` per reply, read by the views
   (the per-reply values: Graphs and Data show what each request served).

:meth:`MonitorSession.process_batch` takes the replies the bridge delivers
together (up to a screen frame's worth): each reply is checked and gets its
row as above, the single polls of all of them go through the poll tracker
(:meth:`PollTracker.step_many`: each reply's steps as one by one) and the pose
integration once, and a row's pose is the pose after its own reply's steps, so
the history does not depend on the grouping (docs/monitor.md, "Threads").

Units and frames: metres, seconds, radians. Sensor displacements are in the
sensor frame of the seed (X right, Y forward); poses are odom -> base_link
(REP 103/105). Sensor world positions are the mount points carried by the pose.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from mm_pc.core.calibration import Calibration
from mm_pc.core.calibration_fit import MIN_STRAIGHT_M, CalibrationStep, MountFit, StepCheck
from mm_pc.core.filters import SensorMedianFilter
from mm_pc.core.geometry import DEFAULT_MOUNTS, SensorMount
from mm_pc.core.odometry import METHODS, Odometry, Pose2D, Sample
from mm_pc.core.polls import PollBatch, PollTracker, SensorTotals, integrate_steps
from mm_pc.core.sensor_data import Reading, Reply
from mm_pc.monitor.model.calibration_run import CalibrationRun
from mm_pc.monitor.model.chips import quality_figure
from mm_pc.monitor.model.history import History

__all__ = ["Gap", "LogEntry", "MonitorSession", "SessionStats", "sensor_columns"]

#: Per-sensor history columns (prefixed ``s0_``, ``s1_``, ...):
#: raw_dx/raw_dy  displacement served for the interval (m, sensor frame)
#: dx/dy          after the median filter and the calibration (m)
#: vx/vy          speed (m/s): dx, dy summed over the rows of the last SPEED_WINDOW_S
#:                divided by the time this sensor's newest-poll stamps span over them (not
#:                dx/dt of one reply: at 500 Hz a reply's stamps a poll apart between the
#:                sensors made the second sensor's dx/dt swing 0..606 mm/s at 200)
#: wx/wy          the sensor's position in odom (m)
#: lifts          polls with the lift bit set in the interval
#: cpi            resolution in force
#: quality        the chip's surface-quality figure at the newest poll (SQUAL, ...; NaN: the
#:                chip has none, or an old node / recording)
#: lowq           polls below the chip's quality threshold in the interval (treated like lifts)
SENSOR_FIELDS = ("raw_dx", "raw_dy", "dx", "dy", "vx", "vy", "wx", "wy", "lifts", "cpi",
                 "quality", "lowq")
#: Robot columns: t (s since the first reply), dt (s), rtt (s), x/y/yaw (odom, m, rad),
#: residual (m; two-sensor method only, else NaN), calibrating (1 while the wizard records).
ROBOT_FIELDS = ("t", "dt", "rtt", "x", "y", "yaw", "residual", "calibrating")
#: The map's path (:attr:`MonitorSession.map_history`): t, x, y, yaw and s<k>_wx, s<k>_wy as
#: above, one row per reply -- or, where the reply brought its single polls, the per-poll
#: poses kept every MAP_SPACING_M of travel or MAP_SPACING_RAD of turn (so a long reply,
#: after a pause or a slow link, is drawn along the path it covered, not as a chord).
MAP_FIELDS = ("t", "x", "y", "yaw")
MAP_SPACING_M = 0.002
MAP_SPACING_RAD = math.radians(1.0)
#: the speed columns average the rows (replies) of this many seconds back (by the
#: newest poll's stamp each reply carries): at 500 Hz 25 replies, at 15 Hz just one
SPEED_WINDOW_S = 0.05


def _totals(r: Reading) -> SensorTotals:
    """The poll tracker's view of one reading's monotone totals."""
    return SensorTotals(
        seq=r.seq, stamp_ns=r.stamp_ns, x_counts=r.x_total_counts, y_counts=r.y_total_counts,
        x_m=r.x_total, y_m=r.y_total, x_est_m=r.x_lift_total, y_est_m=r.y_lift_total,
        instance_id=r.instance_id, chip=r.chip,
    )


def _map_keep(poses: np.ndarray) -> np.ndarray:
    """Indices of the per-poll poses (N x 3: x, y, yaw) the map keeps: where the travelled
    distance passes a multiple of MAP_SPACING_M or the turned angle one of MAP_SPACING_RAD,
    and always the last (the reply's pose)."""
    n = len(poses)
    if n < 2:
        return np.arange(n)  # [] or the one (last) pose
    # slices, not np.diff(prepend=...): a reply holds a few poses, numpy's call overhead rules
    x, y, yaw = poses[:, 0], poses[:, 1], poses[:, 2]
    dist_bin = np.floor(np.cumsum(np.hypot(x[1:] - x[:-1], y[1:] - y[:-1])) / MAP_SPACING_M)
    turn_bin = np.floor(np.cumsum(np.abs(yaw[1:] - yaw[:-1])) / MAP_SPACING_RAD)
    new = np.empty(n, dtype=bool)
    new[0] = False  # the first pose of a reply continues the previous reply's last row
    new[1] = dist_bin[0] != 0.0 or turn_bin[0] != 0.0  # the bins of pose 0 are 0
    new[2:] = (dist_bin[1:] != dist_bin[:-1]) | (turn_bin[1:] != turn_bin[:-1])
    new[-1] = True
    return np.flatnonzero(new)


class _Deferred(NamedTuple):
    """A reply checked and turned into deltas, waiting for its pose (``t``, ``dt``: s);
    with single polls also the poll tracker's input: the totals, each sensor's polls
    since the previous step (None: missing) and why they could not be joined ('')."""

    reply: Reply
    now: list[Reading]
    raw: list[tuple[float, float]]
    processed: list[tuple[float, float]]
    t: float
    dt: float
    totals: list[SensorTotals] | None = None
    polls: list[PollBatch | None] | None = None
    bad: str = ""


def sensor_columns(k: int) -> dict[str, str]:
    """Field name -> column name for sensor ``k``."""
    return {f: f"s{k}_{f}" for f in SENSOR_FIELDS}


@dataclass(frozen=True)
class LogEntry:
    """One line of the log dialog: raw and processed values of one sensor in one reply."""

    t: float
    sensor: str
    x_counts: int
    y_counts: int
    raw_dx: float
    raw_dy: float
    dx: float
    dy: float
    x_speed: float
    y_speed: float
    cpi: int
    samples: int
    lift_events: int


@dataclass(frozen=True)
class Gap:
    """A stretch of the path without its single polls: drawn from (x0, y0) to (x1, y1)
    (odom, m) as one step from the totals (or no step: a restart). ``t``: s since the
    first reply; ``reason``: why the polls were missing."""

    t: float
    x0: float
    y0: float
    x1: float
    y1: float
    reason: str


@dataclass(frozen=True)
class CpiChange:
    """A sensor's resolution changed between two replies: ``t`` (s since the first reply),
    where the robot was (``x``, ``y``: odom, m, the pose of the reply that showed it),
    the device and its CPI before and after. A setting, not lost data."""

    t: float
    x: float
    y: float
    device: str
    old: int
    new: int


@dataclass
class SessionStats:
    """Counters the health view and the benchmarks read.

    ``polls``: single polls integrated into the pose; ``per_reply``: replies whose
    pose was integrated per reply (no polls came with them); ``gaps``: gap steps;
    ``cpi_changes``: a sensor's CPI seen changed between two replies (no gap).
    """

    replies: int = 0
    used: int = 0
    baselines: int = 0
    restarts: int = 0
    incomplete: int = 0
    rejected: int = 0
    polls: int = 0
    per_reply: int = 0
    gaps: int = 0
    cpi_changes: int = 0
    events: deque = field(default_factory=lambda: deque(maxlen=200))


class MonitorSession:
    """State of one monitoring session: baselines, filters, calibration, odometry, history.

    ``devices``: sensor ids in mount order; None = take them from the first
    reply (in the order served). ``mounts``: one :class:`SensorMount` per
    device (base_link); default: the original robot's two mounts.
    """

    def __init__(
        self,
        devices: Sequence[str] | None = None,
        mounts: Sequence[SensorMount] | None = None,
        method: str = "exact",
        sensor: int = 0,
        calibration: Calibration | None = None,
        use_lift_estimates: bool = True,
        max_rows: int = 1_000_000,
        log_length: int = 5000,
    ) -> None:
        if method not in METHODS:
            raise ValueError(f"unknown pose method {method!r}; known: {', '.join(sorted(METHODS))}")
        self._mounts = tuple(mounts) if mounts is not None else DEFAULT_MOUNTS
        self._method = method
        self._sensor = sensor
        self._calibration = calibration if calibration is not None else Calibration()
        self.use_lift_estimates = bool(use_lift_estimates)
        self.max_rows = max_rows
        self.stats = SessionStats()
        self.log: deque[LogEntry] = deque(maxlen=log_length)
        self.filters: dict[str, SensorMedianFilter] = {}
        self._prev: dict[str, Reading] = {}
        self._t0_ns: int | None = None
        self._cal_run: CalibrationRun | None = None  # the wizard's open run
        self.devices: tuple[str, ...] = ()
        self.history: History | None = None
        self.map_history: History | None = None
        self.odometry: Odometry | None = None
        self.tracker: PollTracker | None = None
        #: stretches without single polls, oldest first (at most 10 000 kept)
        self.gaps: deque[Gap] = deque(maxlen=10_000)
        #: CPI changes seen, oldest first (at most 10 000 kept), and each sensor's last CPI
        self.cpi_changes: deque[CpiChange] = deque(maxlen=10_000)
        self._row_cpi: dict[str, int] = {}
        self._poll_filters: dict[str, SensorMedianFilter] = {}
        #: polls fetched with replies that made no step, joined to the next one's
        self._stash: dict[str, list] = {}
        #: replies of a batch whose rows wait for the batch's per-poll poses
        self._deferred: list[_Deferred] = []
        self._batching = False
        #: the newest rows' (t, dt, per sensor (dx, dy, dt: s between its own poll stamps))
        #: the speed is taken over, and each sensor's stamp of the previous row (ns)
        self._speed_rows: deque[tuple[float, float, list[tuple[float, float, float]]]] = deque()
        self._speed_stamps: list[int] = []
        if devices is not None:
            self._set_devices(tuple(devices))

    # -- configuration ------------------------------------------------------------

    def _set_devices(self, devices: tuple[str, ...]) -> None:
        if not devices or len(set(devices)) != len(devices) or not all(devices):
            raise ValueError(f"devices must be unique, non-empty sensor ids, got {devices!r}")
        mounts = self._mounts_for(len(devices))
        odometry = Odometry(
            self._calibration.mounts(devices, mounts),
            self._method,
            min(self._sensor, len(devices) - 1),
        )
        self.devices = devices
        self._mounts = mounts
        self.odometry = odometry
        self.filters = {d: self.filters.get(d, SensorMedianFilter()) for d in devices}
        self._poll_filters = {d: SensorMedianFilter() for d in devices}
        self.tracker = PollTracker(len(devices), self.use_lift_estimates)
        cols = list(ROBOT_FIELDS)
        for k in range(len(devices)):
            cols += sensor_columns(k).values()
        self.history = History(cols, max_rows=self.max_rows)
        map_cols = list(MAP_FIELDS)
        for k in range(len(devices)):
            map_cols += [f"s{k}_wx", f"s{k}_wy"]
        self.map_history = History(map_cols, max_rows=self.max_rows)
        self._poll_poses: tuple[np.ndarray, np.ndarray] | None = None

    def _mounts_for(self, n: int) -> tuple[SensorMount, ...]:
        if len(self._mounts) >= n:
            return tuple(self._mounts[:n])
        raise ValueError(f"{n} sensors need {n} mounts, the geometry has {len(self._mounts)}")

    @property
    def mounts(self) -> tuple[SensorMount, ...]:
        return self._mounts

    @property
    def method(self) -> str:
        return self._method

    @property
    def sensor(self) -> int:
        """Index of the sensor the one-sensor methods use."""
        return self._sensor

    def configure_odometry(
        self,
        method: str | None = None,
        mounts: Sequence[SensorMount] | None = None,
        sensor: int | None = None,
    ) -> None:
        """Change the pose method, geometry or sensor; the pose carries on from where it is.

        Raises ValueError (nothing changed) for an unknown method, a wrong
        number of mounts, a sensor on the axle line for the one-sensor
        methods, or a bad sensor index.
        """
        method = self._method if method is None else method
        mounts_t = self._mounts if mounts is None else tuple(mounts)
        sensor = self._sensor if sensor is None else sensor
        if method not in METHODS:
            raise ValueError(f"unknown pose method {method!r}; known: {', '.join(sorted(METHODS))}")
        if self.devices and len(mounts_t) != len(self.devices):
            raise ValueError(
                f"the geometry needs one mount per sensor ({len(self.devices)}), "
                f"got {len(mounts_t)}"
            )
        if self.devices:
            pose = self.odometry.pose if self.odometry else None
            calibrated = self._calibration.mounts(self.devices, mounts_t)
            new = Odometry(calibrated, method, sensor, pose=pose)  # raises before any change
            self.odometry = new
        else:
            Odometry(mounts_t, method, sensor)  # validate only
        self._method, self._mounts, self._sensor = method, mounts_t, sensor

    # -- calibration wizard ----------------------------------------------------------
    #
    # The run's state is a CalibrationRun (model/calibration_run.py); the session
    # feeds it the raw displacements; the pose keeps integrating while it is open.

    @property
    def calibration(self) -> Calibration:
        """The calibration in force (applied to every sample before the pose math)."""
        return self._calibration

    @calibration.setter
    def calibration(self, cal: Calibration) -> None:
        """Put ``cal`` in force; its fitted sensor positions become the odometry's mounts."""
        if not isinstance(cal, Calibration):
            raise ValueError(f"expected a Calibration, got {cal!r}")
        if self.devices and self.odometry is not None:
            mounts = cal.mounts(self.devices, self._mounts)
            pose = self.odometry.pose
            sensor = min(self._sensor, len(self.devices) - 1)
            self.odometry = Odometry(mounts, self._method, sensor, pose=pose)
        self._calibration = cal

    @property
    def odometry_mounts(self) -> tuple[SensorMount, ...]:
        """The mounts the pose math uses: the geometry with the calibration's positions."""
        if not self.devices:
            return self._mounts
        return self._calibration.mounts(self.devices, self._mounts)

    @property
    def calibration_run(self) -> CalibrationRun | None:
        """The open calibration run (None: none; the wizard's steps and their checks)."""
        return self._cal_run

    @property
    def calibrating(self) -> bool:
        """True while a calibration run is open (the pose keeps integrating meanwhile)."""
        return self._cal_run is not None

    @property
    def recording_step(self) -> str | None:
        """The kind of the step being recorded, or None."""
        return None if self._cal_run is None else self._cal_run.kind

    def _open_run(self) -> CalibrationRun:
        if self._cal_run is None:
            raise ValueError("no calibration run in progress; start one first")
        return self._cal_run

    def _step_mounts(self) -> tuple[SensorMount, ...]:
        """The mounts of the sensors a step records (none before the first reply)."""
        return self._mounts[: len(self.devices)]

    def start_calibration(self) -> None:
        """Open a run (no steps yet); the pose keeps integrating (calibration in force)."""
        self._cal_run = CalibrationRun()

    def start_calibration_step(self, kind: str) -> None:
        """Start recording a step ("straight" or "spin"); ValueError (nothing changed) if
        no run is open, a step is already recording, or the kind is unknown."""
        self._open_run().start_step(kind)

    def calibration_step_check(self) -> StepCheck | None:
        """The live residuals and pass/fail of the step being recorded (None: none)."""
        run = self._cal_run
        return None if run is None else run.step_check(self._step_mounts())

    def stop_calibration_step(self) -> StepCheck:
        """Stop recording: the step is kept (passing or not) and its check returned.

        Nothing is recorded after this. ValueError if no step is recording.
        """
        if self._cal_run is None:
            raise ValueError("no calibration step is recording")
        return self._cal_run.stop_step(self._step_mounts())

    def discard_calibration_step(self, index: int | None = None) -> int:
        """Drop a recorded step (default the failed one, else the last); its index.
        ValueError if there is none."""
        if self._cal_run is None:
            raise ValueError("no recorded calibration step to discard")
        return self._cal_run.discard_step(index)

    def calibration_steps(self) -> list[tuple[CalibrationStep, StepCheck]]:
        """The recorded steps with their checks, in order."""
        return [] if self._cal_run is None else list(self._cal_run.steps)

    def calibration_sums(self) -> dict[str, tuple[float, float]]:
        """Raw summed X, Y (m) per sensor of the step being recorded ({} if none)."""
        return {} if self._cal_run is None else self._cal_run.sums(self.devices)

    def compute_calibration(
        self,
        true_distance: float | None = None,
        spin_angle: float = 2 * math.pi,
        min_distance: float = MIN_STRAIGHT_M,
        scale_reference: str = "sensors",
    ) -> MountFit:
        """Fit the whole mount from the recorded steps (does not apply it).

        ``true_distance``: each straight's measured length (m) or None;
        ``spin_angle``: what each spin turned (rad); ``scale_reference``: the scale
        without a measured length (``calibration_fit.SCALE_REFERENCES``). Returns the
        :class:`MountFit` (``.calibration()`` the fit, ``.straight_run`` the
        seed's formula on the same straights). Raises ValueError (a
        :class:`CalibrationRefusedError` for a refused run) with what to do;
        nothing changes.
        """
        return self._open_run().fit(
            self.devices,
            self._mounts,
            sensor=min(self._sensor, len(self.devices) - 1),
            true_distance=true_distance,
            spin_angle=spin_angle,
            min_distance=min_distance,
            scale_reference=scale_reference,
        )

    def finish_calibration(self, calibration: Calibration | None) -> None:
        """End the run; apply ``calibration`` if given (None = keep the old one)."""
        self._cal_run = None
        if calibration is not None:
            self.calibration = calibration

    # -- filters ----------------------------------------------------------------------

    def set_filter(self, device: str, window: int, filter_x: bool, filter_y: bool) -> None:
        """Median filter settings of one sensor; ValueError (nothing changed) on bad input."""
        if device not in self.filters:
            raise ValueError(f"unknown sensor {device!r}; known: {', '.join(self.filters)}")
        f = self.filters[device]
        f.window = window  # validates first
        f.filter_x, f.filter_y = bool(filter_x), bool(filter_y)
        pf = self._poll_filters[device]  # the same filter over the single polls
        pf.window, pf.filter_x, pf.filter_y = f.window, f.filter_x, f.filter_y

    def clear_filters(self) -> None:
        """Disable every filter and forget their history."""
        for f in (*self.filters.values(), *self._poll_filters.values()):
            f.filter_x = f.filter_y = False
            f.reset()

    # -- processing --------------------------------------------------------------------

    def chip(self, device: str) -> str:
        """The chip the newest reply named for ``device`` ('' = not known yet, or an old
        node: a PLN2033; :mod:`mm_pc.monitor.model.chips` tells what it is)."""
        r = self._prev.get(device)
        return r.chip if r is not None else ""

    def _total(self, r: Reading) -> tuple[float, float]:
        if self.use_lift_estimates:
            return r.x_total + r.x_lift_total, r.y_total + r.y_lift_total
        return r.x_total, r.y_total

    def process_batch(self, replies: Sequence[Reply]) -> int:
        """Take replies delivered together, oldest first; the number of rows made.

        The same history, pose and gaps as :meth:`process` one by one, whatever the
        grouping (a replay feeds the replies singly): the batch's polls are stepped
        as one by one (:meth:`PollTracker.step_many`) and integrated in one go, and
        each row takes the pose after its own reply's steps. Only the map keeps one
        forced row per batch instead of per reply.
        """
        self._batching = True
        try:
            return sum(self.process(r) for r in replies)
        finally:
            self._batching = False
            self._flush()

    def process(self, reply: Reply) -> bool:
        """Take one reply; True when it produced a history row.

        A reply missing a sensor is kept for nobody: the baselines stay, so
        the next complete reply covers the gap (no count lost).
        """
        self.stats.replies += 1
        if not self.devices:
            if not reply.readings:
                self.stats.incomplete += 1
                return False
            self._set_devices(tuple(r.id for r in reply.readings))
        by_id = reply.by_id()
        if any(d not in by_id for d in self.devices):
            self.stats.incomplete += 1
            self._stash_polls(reply)
            return False
        now = [by_id[d] for d in self.devices]
        if not all(math.isfinite(v) for r in now for v in (*self._total(r), r.stamp_ns)):
            self.stats.rejected += 1
            self.stats.events.append(("rejected", "a reply with a non-finite total"))
            self._stash_polls(reply)
            return False
        prev = [self._prev.get(d) for d in self.devices]
        if any(p is None for p in prev) or any(
            r.seq < p.seq or r.instance_id != p.instance_id for r, p in zip(now, prev, strict=True)
        ):  # a new identity is a restart even when the new node's seq is past the old one's
            restarted = all(p is not None for p in prev)
            self._flush()  # the rows before the restart get the poses before it
            self._baseline(now, restarted)
            return False
        dt = (now[0].stamp_ns - prev[0].stamp_ns) / 1e9
        if dt <= 0:
            self._stash_polls(reply)
            return False  # nothing new was polled since the previous reply
        self._step(reply, now, prev, dt)
        for r in now:
            self._prev[r.id] = r
        return True

    def _baseline(self, now: list[Reading], restarted: bool) -> None:
        for r in now:
            self._prev[r.id] = r
        if self._t0_ns is None:
            self._t0_ns = now[0].stamp_ns
        self.tracker.baseline([_totals(r) for r in now])
        self._stash.clear()
        self._row_cpi.clear()  # a new start (or restart) at another CPI is no CPI change
        self._speed_rows.clear()
        self._speed_stamps = [r.stamp_ns for r in now]
        self.stats.baselines += 1
        if restarted:
            self.stats.restarts += 1
            why = "the Beagle node restarted; new baseline (its counts meanwhile are lost)"
            self.stats.events.append(("restart", why))
            p = self.pose
            t = (now[0].stamp_ns - self._t0_ns) / 1e9
            self.gaps.append(Gap(t, p.x, p.y, p.x, p.y, why))

    def _step(self, reply: Reply, now: list[Reading], prev: list[Reading], dt: float) -> None:
        t = (now[0].stamp_ns - self._t0_ns) / 1e9
        raw, processed = [], []
        for r, p in zip(now, prev, strict=True):
            (x1, y1), (x0, y0) = self._total(r), self._total(p)
            rx, ry = x1 - x0, y1 - y0
            raw.append((rx, ry))
            fx, fy = self.filters[r.id].push(rx, ry)
            processed.append(self.calibration.apply(r.id, fx, fy))
        if self._cal_run is not None:
            self._cal_run.record(raw, dt)
        self.stats.used += 1
        if reply.polls is not None:
            self._stash_polls(reply)
            polls, bad = self._take_polls()
            totals = [_totals(r) for r in now]
            self._deferred.append(_Deferred(reply, now, raw, processed, t, dt, totals, polls, bad))
            if not self._batching:
                self._flush()
            return
        self._flush()  # rows in the order of their replies
        self.stats.per_reply += 1
        pose = self.odometry.update(Sample.of(dt, *processed))
        self._row(_Deferred(reply, now, raw, processed, t, dt), pose, self.odometry.residual)
        self._append_map(t, pose)

    def _flush(self) -> None:
        """The rows of the deferred replies: their polls stepped as one by one and
        integrated in one go, each row with the pose after its own reply's steps (so a
        row does not depend on which replies came together); the map's rows from the
        per-poll poses."""
        if not self._deferred:
            return
        group, self._deferred = self._deferred, []
        before, res_before = self.odometry.pose, self.odometry.residual
        self.tracker.use_lift_estimates = self.use_lift_estimates
        steps, ends = self.tracker.step_many([(d.totals, d.polls) for d in group])
        poses, resid = self._integrate(steps, group, ends, before)
        for d, e in zip(group, ends, strict=True):
            if poses is None or e == 0:
                self._row(d, before, res_before)
            else:
                r = float(resid[e - 1])
                self._row(d, Pose2D(*map(float, poses[e - 1])), None if math.isnan(r) else r)
        self._append_map(group[-1].t, self.odometry.pose)

    def _row(self, d: _Deferred, pose: Pose2D, residual: float | None) -> None:
        """The history row and the log lines of one reply with ``pose`` as its pose."""
        reply, now, raw, processed, t, dt = d[:6]
        row = [
            t,
            dt,
            reply.rtt_s,
            pose.x,
            pose.y,
            pose.yaw,
            math.nan if residual is None else residual,
            1.0 if self.calibrating else 0.0,
        ]
        c, s = math.cos(pose.yaw), math.sin(pose.yaw)
        speeds = self._speeds(t, dt, now, processed)
        for r, (rx, ry), (dx, dy), m, (vx, vy) in zip(
                now, raw, processed, self._mounts, speeds, strict=True):
            wx, wy = pose.x + c * m.x - s * m.y, pose.y + s * m.x + c * m.y
            old = self._row_cpi.get(r.id, 0)
            if r.cpi and old and r.cpi != old:
                self._cpi_changed(t, pose, r.id, old, r.cpi)
            self._row_cpi[r.id] = r.cpi or old
            row += [rx, ry, dx, dy, vx, vy, wx, wy, r.lift_events, r.cpi,
                    quality_figure(r.chip, r.quality), r.low_quality_events]
            self.log.append(
                LogEntry(
                    t, r.id, r.x_counts, r.y_counts, rx, ry, dx, dy,
                    r.x_speed, r.y_speed, r.cpi, r.samples, r.lift_events,
                )
            )
        self.history.append(row)

    def _cpi_changed(self, t: float, pose: Pose2D, device: str, old: int, new: int) -> None:
        self.stats.cpi_changes += 1
        self.cpi_changes.append(CpiChange(t, pose.x, pose.y, device, old, new))
        self.stats.events.append(
            ("cpi", f"{device}: CPI {old} -> {new} at {t:.3f} s (a setting, no data lost)")
        )

    def _speeds(self, t: float, dt: float, now: list[Reading],
                processed: list[tuple[float, float]]) -> list[tuple[float, float]]:
        """Each sensor's (vx, vy) (m/s): its displacements of the rows within
        SPEED_WINDOW_S before ``t`` (this one included) over the time its own newest-poll
        stamps moved on over them (the rows' ``dt``, sensor 0's, when they did not move
        at all in the window)."""
        stamps = [r.stamp_ns for r in now]
        last = self._speed_stamps if len(self._speed_stamps) == len(now) else stamps
        own = [max(s1 - s0, 0) / 1e9 for s1, s0 in zip(stamps, last, strict=True)]
        self._speed_stamps = stamps
        rows = self._speed_rows
        rows.append((t, dt, [(dx, dy, d) for (dx, dy), d in zip(processed, own, strict=True)]))
        while len(rows) > 1 and rows[0][0] <= t - SPEED_WINDOW_S:
            rows.popleft()
        out = []
        for k in range(len(processed)):
            span = sum(r[2][k][2] for r in rows) or sum(r[1] for r in rows)
            out.append((sum(r[2][k][0] for r in rows) / span,
                        sum(r[2][k][1] for r in rows) / span))
        return out

    def _append_map(self, t: float, pose: Pose2D) -> None:
        """The map's rows for this reply: its per-poll poses (decimated) or the reply's pose."""
        if self._poll_poses is not None:
            ts, poses = self._poll_poses
            self._poll_poses = None
            keep = _map_keep(poses)
            ts, poses = ts[keep], poses[keep]
        else:
            ts, poses = np.array([t]), np.array([[pose.x, pose.y, pose.yaw]])
        c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
        rows = np.empty((len(ts), 4 + 2 * len(self._mounts)))
        rows[:, 0] = ts
        rows[:, 1:4] = poses
        for k, m in enumerate(self._mounts):
            rows[:, 4 + 2 * k] = poses[:, 0] + c * m.x - s * m.y
            rows[:, 5 + 2 * k] = poses[:, 1] + s * m.x + c * m.y
        self.map_history.extend(rows)

    def _take_polls(self) -> tuple[list[PollBatch | None], str]:
        """Each sensor's polls stashed since the previous step, joined (None: missing, or
        not joinable), and why they could not be joined ('')."""
        batches: list[PollBatch | None] = []
        bad = ""
        for dev in self.devices:
            parts = self._stash.pop(dev, [])
            try:
                batches.append(PollBatch.join(parts) if parts and None not in parts else None)
            except ValueError as e:
                batches.append(None)
                bad = f"{dev}: {e}"
        return batches, bad

    def _integrate(self, steps, group: list[_Deferred], ends: list[int], before: Pose2D):
        """Filter, calibrate and integrate the steps of the deferred replies ``group``
        (``ends``: steps made up to each), record their gaps; the (N, 3) poses and (N,)
        residuals, or (None, None) when there is nothing to integrate."""
        if not len(steps):
            return None, None
        d = steps.d.copy()
        for k, dev in enumerate(self.devices):
            dx, dy = d[:, k, 0], d[:, k, 1]
            pf = self._poll_filters[dev]
            if pf.filter_x or pf.filter_y:
                dx, dy = pf.push_many(dx, dy)
            d[:, k, 0], d[:, k, 1] = self.calibration.apply(dev, dx, dy)
        poses, resid = integrate_steps(self.odometry, steps, d, return_residual=True)
        poses = np.asarray(poses, float)
        self._poll_poses = ((steps.stamp_ns - self._t0_ns) / 1e9, poses)
        self.stats.polls += int((~steps.gap).sum())
        gaps = np.flatnonzero(steps.gap)
        if not len(gaps):
            return poses, resid
        reasons = [*["polls missing"] * len(gaps), *self.tracker.gap_reasons]
        reasons = reasons[len(reasons) - len(gaps) :]
        owner = np.searchsorted(ends, gaps, side="right")  # the reply that made each gap
        for j, why, r in zip(gaps.tolist(), reasons, owner.tolist(), strict=True):
            start = poses[j - 1] if j > 0 else before.as_array()
            d_r = group[r]
            if d_r.bad:
                why = f"{why} ({d_r.bad})"
            self.stats.gaps += 1
            self.stats.events.append(("gap", f"no single polls: {why}; step from the totals"))
            self.gaps.append(Gap(d_r.t, *map(float, start[:2]), *map(float, poses[j, :2]), why))
        return poses, resid

    def _stash_polls(self, reply: Reply) -> None:
        """Keep the polls of a reply until a reply makes a step (None = a failed fetch)."""
        if reply.polls is None:
            return
        for dev, res in reply.polls.items():
            self._stash.setdefault(dev, []).append(res)

    def forget_baselines(self, keep_t0: bool = True) -> None:
        """Take the next reply as a new baseline (switching between live and recorded data).

        Without this the first reply of the other source would be taken as a
        delta against this source's totals. ``keep_t0=False`` also restarts
        the time axis at the next reply.
        """
        self._prev.clear()
        self._stash.clear()
        self._row_cpi.clear()
        if not keep_t0:
            self._t0_ns = None

    # -- reset ------------------------------------------------------------------------------

    @property
    def pose(self) -> Pose2D:
        return self.odometry.pose if self.odometry else Pose2D()

    def reset(self) -> None:
        """Clear paths, graphs and the pose (back to the origin); the baselines stay,
        so the counts from now on continue without a jump."""
        if self.odometry is not None:
            self.odometry.reset()
        if self.history is not None:
            self.history.clear()
            self.map_history.clear()
        for f in (*self.filters.values(), *self._poll_filters.values()):
            f.reset()
        self.log.clear()
        self.gaps.clear()
        self.cpi_changes.clear()
        self._speed_rows.clear()
        if self._prev and self.devices:
            self._t0_ns = self._prev[self.devices[0]].stamp_ns
