"""The state of one open calibration run of the wizard (no Qt, no ROS).

A run is a sequence of steps (straight / spin, :mod:`mm_pc.core.calibration_fit`),
each recorded between :meth:`CalibrationRun.start_step` and
:meth:`CalibrationRun.stop_step`: the raw (unfiltered, uncalibrated)
displacement of every interval (m, sensor frame, mount order) is kept, nothing
after Stop. The pose keeps integrating meanwhile (with the calibration in force).

Besides :func:`~mm_pc.core.calibration_fit.check_step`'s residuals, each step's
rigid motion (two sensors or more, nominal mounts) must fit its kind: a spin
turns in place (at least ``MIN_SPIN_RAD``, its centre moving at most
``MAX_SPIN_MOVE_M``), a straight does not turn (at most ``MAX_STRAIGHT_TURN_RAD``).
With one sensor there is no rigid motion; a push and a turn are told apart by the
direction of its counts (:func:`direction_failure`): a straight runs along the sensor's
Y axis, a spin across its radius, so where the two directions differ by at least
``MIN_DIRECTION_SEPARATION_RAD`` a step must run nearer its own kind's direction
(a sensor on the axle line sees both along Y: :func:`one_sensor_note` says so).
A failed step blocks the next one until it is discarded. An
:class:`~mm_pc.monitor.model.calibration_autodrive.AutoDrive` may press
Start/Stop itself, per interval (:meth:`CalibrationRun.record`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from mm_pc.core.calibration_fit import (
    MIN_SPIN_RAD,
    MIN_STRAIGHT_M,
    STEP_KINDS,
    CalibrationStep,
    MountFit,
    StepCheck,
    check_step,
    fit_mounts,
)
from mm_pc.core.geometry import SensorMount
from mm_pc.core.odometry import Odometry

if TYPE_CHECKING:
    from mm_pc.monitor.model.calibration_autodrive import AutoDrive

__all__ = [
    "MAX_SPIN_MOVE_M",
    "MAX_STRAIGHT_TURN_RAD",
    "MIN_DIRECTION_SEPARATION_RAD",
    "CalibrationRun",
    "direction_failure",
    "motion_failure",
    "one_sensor_note",
    "step_motion",
]

#: A spin turns in place: base_link (the axle centre) may end at most this far (m) from
#: where it started (a hand-turned robot wobbles a little; a push moves it much further).
MAX_SPIN_MOVE_M = 0.05
#: A straight turns at most this much (rad). Generous: before calibration, sensors of the
#: same CPI differ in scale by a few per cent, which the nominal mounts read as a turn
#: growing with the distance (10 % over 1 m: ~70 deg); a smaller turn is left to
#: check_step's spread of the sensors' distances.
MAX_STRAIGHT_TURN_RAD = math.radians(90.0)
#: One sensor: a straight's and a spin's count directions must differ by this much (rad)
#: for the direction to tell them apart (mount yaw errors of a few degrees and a
#: position off by a few mm turn them by less than half of it).
MIN_DIRECTION_SEPARATION_RAD = math.radians(30.0)
#: One sensor: shortest chord (m) whose direction is trusted (a few counts of noise).
MIN_DIRECTION_CHORD_M = 0.01


def _kind_directions(mount: SensorMount) -> dict[str, float]:
    """The direction (rad, from the sensor's +Y axis toward +X, mod pi) its counts run in
    on a straight and on a spin, for the nominal ``mount``: a straight moves the sensor
    along the robot's forward axis, (0, A) ideally; a spin by C moves it by (-C x, -C y)
    (sensor frame, the calibration fit's model); a sensor turned by yaw reports them
    turned by -yaw, i.e. ``yaw`` further toward +X (a straight's raw sum is
    (A sin yaw, A cos yaw))."""
    return {
        "straight": math.remainder(mount.yaw, math.pi),
        "spin": math.remainder(math.atan2(mount.x, mount.y) + mount.yaw, math.pi),
    }


def _off(a: float, b: float) -> float:
    """Angle between two undirected lines (rad, 0..pi/2)."""
    return abs(math.remainder(a - b, math.pi))


def one_sensor_note(mount: SensorMount) -> str:
    """What the one-sensor check can tell at ``mount`` (the wizard's drive page says it)."""
    dirs = _kind_directions(mount)
    sep = _off(dirs["straight"], dirs["spin"])
    if sep < MIN_DIRECTION_SEPARATION_RAD:
        return (
            f"One sensor, {math.degrees(sep):.0f}° between a straight's and a spin's count "
            "direction at its mount (it sits near the axle line): the checks cannot tell a "
            "push from a turn. Make sure each step is what you press; a second sensor checks "
            "each step's motion."
        )
    return (
        "One sensor: a push and a turn are told apart by the direction of its counts (a "
        f"straight along its Y axis, a spin {math.degrees(sep):.0f}° off it at this mount); "
        "a second sensor would also check each step's motion."
    )


def direction_failure(kind: str, d: np.ndarray, mounts: Sequence[SensorMount]) -> str:
    """One sensor: why the step's count direction does not fit ``kind`` ("" = it fits, or
    cannot tell: two sensors or more (:func:`step_motion` checks those), a chord under
    ``MIN_DIRECTION_CHORD_M``, or a mount where both kinds run alike)."""
    d = np.asarray(d, dtype=float)
    if d.ndim != 3 or d.shape[1] != 1 or not mounts:
        return ""
    chord = d[:, 0].sum(axis=0)
    if math.hypot(*chord) < MIN_DIRECTION_CHORD_M:
        return ""
    dirs = _kind_directions(mounts[0])
    sep = _off(dirs["straight"], dirs["spin"])
    if sep < MIN_DIRECTION_SEPARATION_RAD:
        return ""
    seen = math.atan2(chord[0], chord[1])
    own = _off(seen, dirs[kind])
    if own <= sep / 2:
        return ""
    other = "spin" if kind == "straight" else "straight"
    ratio = abs(chord[0]) / max(abs(chord[1]), 1e-12)
    what = (
        f"its counts ran {math.degrees(_off(seen, dirs['straight'])):.0f}° off the sensor's "
        f"Y axis (X/Y = {ratio:.2f}), like a {other}'s (a {kind} runs "
        f"{math.degrees(_off(dirs[kind], dirs['straight'])):.0f}° off it at this mount)"
    )
    if kind == "spin":
        return f"not a spin: {what}: it was pushed, not turned; discard it and turn the robot " \
            "on the spot"
    return f"not a straight: {what}: the robot turned; discard it and push it straight " \
        "along an edge"


def step_motion(d: np.ndarray, mounts: Sequence[SensorMount]) -> tuple[float, float, float] | None:
    """base_link's (x m, y m, yaw rad) at the end of the displacements ``d`` (N, n, 2 m,
    sensor frame) from the nominal ``mounts``: the two-sensor rigid motion (no no-slip
    assumption, so a sideways push is not read as a turn). None with fewer than two
    sensors (one sensor cannot tell a turn from a push)."""
    d = np.asarray(d, dtype=float)
    n = d.shape[1] if d.ndim == 3 else 0
    if n < 2 or len(mounts) < n or d.shape[0] == 0:
        return None
    poses = Odometry(tuple(mounts)[:n], "two-sensor").integrate(1.0, d)
    x, y, yaw = (float(v) for v in poses[-1])
    return x, y, yaw


def motion_failure(kind: str, motion: tuple[float, float, float] | None, final: bool) -> str:
    """Why the step's rigid motion does not fit ``kind`` ("" = it fits, or cannot tell).

    ``final``: the step has stopped (a spin must then have turned enough); while it
    records only what can no longer be undone fails (a spin that moved, a straight that
    turned)."""
    if motion is None:
        return ""
    moved, turned = math.hypot(motion[0], motion[1]), abs(motion[2])
    what = f"it moved {moved * 100:.1f} cm and turned {math.degrees(turned):.0f}°"
    if kind == "spin":
        if moved > MAX_SPIN_MOVE_M or (final and turned < MIN_SPIN_RAD):
            return (
                f"not a spin: {what}: a spin turns in place (at least "
                f"{math.degrees(MIN_SPIN_RAD):.0f}°, moving at most {MAX_SPIN_MOVE_M * 100:.0f} "
                "cm); discard it and turn the robot on the spot"
            )
    elif turned > MAX_STRAIGHT_TURN_RAD:
        return (
            f"not a straight: {what}: a straight does not turn (at most "
            f"{math.degrees(MAX_STRAIGHT_TURN_RAD):.0f}°); discard it and push the robot "
            "straight along an edge"
        )
    return ""


class CalibrationRun:
    """The recorded steps of a run with their checks, and the step being recorded."""

    def __init__(self) -> None:
        #: (step, its check) of every stopped step, in order
        self.steps: list[tuple[CalibrationStep, StepCheck]] = []
        #: the kind of the step being recorded ("straight" / "spin"), None between steps
        self.kind: str | None = None
        #: the driver pressing Start/Stop itself (a simulated robot), or None
        self.auto: AutoDrive | None = None
        self._rec: list[list[tuple[float, float]]] = []  # its raw per-interval displacements

    def failed_step(self) -> int | None:
        """Index of the first recorded step that failed, or None."""
        return next((k for k, (_, c) in enumerate(self.steps) if not c.ok), None)

    def start_step(self, kind: str) -> None:
        """Start recording a step; ValueError (nothing changed) if one is recording, a
        failed step is still in the list, or the kind is unknown."""
        if self.kind is not None:
            raise ValueError(f"a {self.kind} step is recording; stop it first")
        if kind not in STEP_KINDS:
            raise ValueError(f"step kind must be one of {STEP_KINDS}, got {kind!r}")
        bad = self.failed_step()
        if bad is not None:
            raise ValueError(
                f"step {bad + 1} failed ({self.steps[bad][1].message}); press Discard failed "
                "step before recording the next one"
            )
        self.kind = kind
        self._rec = []

    def record(self, raw: Sequence[tuple[float, float]], dt: float | None = None) -> None:
        """One interval's raw displacements (m, mount order) and its length (s); kept
        while a step records; the auto driver (if any) then sees the interval."""
        if self.kind is not None:
            self._rec.append([tuple(p) for p in raw])
        if self.auto is not None and dt is not None and dt > 0:
            self.auto.feed(self, raw, dt)

    def current_step(self, sensors: int) -> CalibrationStep | None:
        """The step being recorded so far, of ``sensors`` sensors (None: none recording)."""
        if self.kind is None or not sensors:
            return None
        d = np.array(self._rec, dtype=float).reshape(-1, sensors, 2)
        if d.shape[0] == 0:
            d = np.zeros((1, sensors, 2))
        return CalibrationStep(self.kind, d)

    @staticmethod
    def _check(step: CalibrationStep, mounts: Sequence[SensorMount], final: bool) -> StepCheck:
        chk = check_step(step, tuple(mounts))
        why = motion_failure(step.kind, step_motion(step.d, mounts), final)
        if not why and final and chk.ok:
            why = direction_failure(step.kind, step.d, mounts)
        if not why:
            return chk
        return StepCheck(step.kind, False, why, chk.distance, chk.deviation, chk.spread,
                         chk.angle)  # fmt: skip

    def step_check(self, mounts: Sequence[SensorMount]) -> StepCheck | None:
        """The live residuals and pass/fail of the step being recorded (None: none)."""
        step = self.current_step(len(mounts))
        return None if step is None else self._check(step, mounts, final=False)

    def live_failure(self, mounts: Sequence[SensorMount]) -> str:
        """Why the step being recorded has already failed for good ("" = not, or none
        recording): a spin that moved, a straight that turned. The wizard stops it."""
        step = self.current_step(len(mounts))
        if step is None:
            return ""
        return motion_failure(step.kind, step_motion(step.d, mounts), final=False)

    def stop_step(self, mounts: Sequence[SensorMount]) -> StepCheck:
        """Stop recording: the step is kept (passing or not) and its check returned.

        ValueError if no step is recording."""
        step = self.current_step(len(mounts))
        if step is None:
            raise ValueError("no calibration step is recording")
        check = self._check(step, mounts, final=True)
        self.steps.append((step, check))
        self.kind = None
        self._rec = []
        return check

    def cancel_step(self) -> None:
        """Drop the step being recorded without keeping it (nothing if none records)."""
        self.kind = None
        self._rec = []

    def discard_step(self, index: int | None = None) -> int:
        """Drop a recorded step: ``index``, by default the failed one (else the last);
        its index is returned. ValueError if there is none."""
        if not self.steps:
            raise ValueError("no recorded calibration step to discard")
        if index is None:
            bad = self.failed_step()
            index = len(self.steps) - 1 if bad is None else bad
        index = range(len(self.steps))[index]  # IndexError for a bad index, -1 = the last
        del self.steps[index]
        return index

    def sums(self, devices: Sequence[str]) -> dict[str, tuple[float, float]]:
        """Raw summed X, Y (m) per sensor of the step being recorded ({} if none)."""
        step = self.current_step(len(devices))
        if step is None:
            return {}
        tot = step.totals
        return {d: (float(tot[i, 0]), float(tot[i, 1])) for i, d in enumerate(devices)}

    def fit(
        self,
        devices: Sequence[str],
        mounts: Sequence[SensorMount],
        sensor: int,
        true_distance: float | None = None,
        spin_angle: float = 2 * math.pi,
        min_distance: float = MIN_STRAIGHT_M,
        scale_reference: str = "sensors",
    ) -> MountFit:
        """Fit the whole mount from the recorded steps (:func:`fit_mounts`; nothing applied).

        ValueError while a step is still recording or a failed step is in the list; a
        :class:`~mm_pc.core.calibration_fit.CalibrationRefusedError` for a refused run."""
        if self.kind is not None:
            raise ValueError(f"a {self.kind} step is still recording; press Stop first")
        bad = self.failed_step()
        if bad is not None:
            step, chk = self.steps[bad]
            raise ValueError(f"step {bad + 1} ({step.kind}): {chk.message}")
        return fit_mounts(
            [s for s, _ in self.steps],
            tuple(devices),
            tuple(mounts),
            true_distance=true_distance,
            spin_angle=spin_angle,
            sensor=sensor,
            min_distance=min_distance,
            scale_reference=scale_reference,
        )
