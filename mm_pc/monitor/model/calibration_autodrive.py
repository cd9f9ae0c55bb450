"""Pressing Start/Stop of the calibration run for a simulated robot (no Qt, no ROS).

``mm-monitor --sim calibration_run`` drives the guided run
(:func:`mm_pc.sim.robot.guided_calibration_run`) over and over: straight forward and
back, then full spins left, right, left, right, standing 0.5 s between moves and 1 s
between laps. :class:`AutoDrive` watches every interval the session records
(:meth:`CalibrationRun.record <mm_pc.monitor.model.calibration_run.CalibrationRun.record>`,
so a busy GUI thread cannot shift a press) and:

1. finds where the lap is: a stand of ``LAP_STILL_S`` or more comes before the
   straight forward; a straight that just ended is followed by the other one
   (forward -> back, back -> the first spin); a spin alone does not tell;
2. starts the next move's step while the robot stands, stops it once the robot has
   stood ``STOPPED_S``, and starts the next one at once, until one whole lap
   (:data:`GUIDED_KINDS`) is recorded, a step fails, or the robot stands
   ``IDLE_S`` (the sim is not driving the run). Times are the replies' intervals (s).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from mm_pc.core.geometry import SensorMount
from mm_pc.monitor.model.calibration_run import step_motion
from mm_pc.sim.robot import guided_calibration_steps

__all__ = ["GUIDED_KINDS", "AutoDrive"]

#: the kinds of the guided run's moves, in order (one lap)
GUIDED_KINDS: tuple[str, ...] = tuple(kind for kind, _, _ in guided_calibration_steps())
#: a sensor moving faster than this (m/s) in an interval: the robot moves
MOVING_SPEED = 0.005
#: standing this long (s) after moving ends a move (the guided run stands 0.5 s)
STOPPED_S = 0.2
#: a stand this long (s) is the one between laps (1 s; 0.5 s between moves)
LAP_STILL_S = 0.75
#: no motion for this long (s) while driving: give up
IDLE_S = 10.0
#: the lap not found in this long (s): give up (a lap takes ~34 s)
SYNC_S = 45.0

WAITING, RECORDING, DONE, FAILED = "waiting", "recording", "done", "failed"


class AutoDrive:
    """Start/Stop of one lap of the guided run, decided per recorded interval.

    ``mounts``: the nominal mounts the step checks use. ``state`` is one of
    WAITING (finding the lap), RECORDING, DONE, FAILED; ``message`` says what it
    does or why it stopped; ``recorded`` of ``total`` steps are kept.
    """

    def __init__(self, mounts: Sequence[SensorMount], kinds: Sequence[str] = GUIDED_KINDS):
        self.mounts = tuple(mounts)
        self.kinds = tuple(kinds)
        self.total = len(self.kinds)
        self.recorded = 0
        self.state = WAITING
        self.message = "waiting for the sim's next straight (finding where its lap is)"
        self._next: int | None = None  # index in kinds of the next move
        self._moving = False
        self._still = 0.0  # s standing since the last moving interval
        self._elapsed = 0.0  # s since started (WAITING) or since the last motion (RECORDING)
        self._move: list[Sequence[tuple[float, float]]] = []

    @property
    def active(self) -> bool:
        return self.state in (WAITING, RECORDING)

    def feed(self, run, raw: Sequence[tuple[float, float]], dt: float) -> None:
        """One interval (raw displacements m, length s) of ``run`` (a CalibrationRun)."""
        if not self.active:
            return
        moving = max((math.hypot(*p) for p in raw), default=0.0) > MOVING_SPEED * dt
        self._elapsed = 0.0 if moving and self.state == RECORDING else self._elapsed + dt
        if moving:
            if not self._moving:
                self._moving, self._move = True, []
            self._still = 0.0
            self._move.append(raw)
        else:
            self._still += dt
            if self._moving:
                self._move.append(raw)
                if self._still >= STOPPED_S:
                    self._moving = False
                    self._move_ended(run)
            elif self.state == WAITING and self._still >= LAP_STILL_S:
                self._begin(run, 0)  # the stand between laps: the straight forward is next
        if self.state == WAITING and self._elapsed > SYNC_S:
            self._fail(run, f"no guided run seen in {SYNC_S:.0f} s: is the sim driving "
                            "calibration_run (mm-monitor --sim calibration_run)?")
        elif self.state == RECORDING and self._elapsed > IDLE_S:
            self._fail(run, f"the robot stood {IDLE_S:.0f} s: the sim stopped driving the run")

    def cancel(self, run) -> None:
        """Stop driving; the step being recorded is dropped, the kept ones stay."""
        if self.state == RECORDING:
            run.cancel_step()
        if self.active:
            self.state, self.message = FAILED, "cancelled: the recorded steps stay"

    def _move_ended(self, run) -> None:
        if self.state == WAITING:
            motion = step_motion(np.array(self._move, dtype=float), self.mounts)
            if motion is not None and abs(motion[2]) < math.radians(30):
                # after the straight forward comes the one back; after that, the spins
                self._begin(run, 1 if motion[0] > 0 else 2)
            return
        check = run.stop_step(self.mounts)
        self.recorded += 1
        if not check.ok:
            self._fail(run, f"step {len(run.steps)} failed: {check.message}")
            return
        if self.recorded == self.total:
            self.state = DONE
            self.message = f"done: {self.total} steps recorded; press Next"
            return
        self._start(run, (self._next + 1) % self.total)

    def _begin(self, run, index: int) -> None:
        self.state, self._elapsed = RECORDING, 0.0
        self._start(run, index)

    def _start(self, run, index: int) -> None:
        self._next = index
        kind = self.kinds[index]
        try:
            run.start_step(kind)
        except ValueError as e:
            self._fail(run, str(e))
            return
        self.message = f"recording step {self.recorded + 1} of {self.total}: {kind}"

    def _fail(self, run, why: str) -> None:
        if run.kind is not None:
            run.cancel_step()
        self.state, self.message = FAILED, why
