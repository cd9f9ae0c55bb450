"""The state of one open calibration run of the wizard (no Qt, no ROS).

A run is a sequence of steps (straight / spin, :mod:`mm_pc.core.calibration_fit`),
each recorded between :meth:`CalibrationRun.start_step` and
:meth:`CalibrationRun.stop_step`: the raw (unfiltered, uncalibrated)
displacement of every interval (m, sensor frame, mount order) is kept, nothing
after Stop. The session owns at most one run; while it is open the pose stands
still (no pose from uncalibrated data).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from mm_pc.core.calibration_fit import (
    MIN_STRAIGHT_M,
    STEP_KINDS,
    CalibrationStep,
    MountFit,
    StepCheck,
    check_step,
    fit_mounts,
)
from mm_pc.core.geometry import SensorMount

__all__ = ["CalibrationRun"]


class CalibrationRun:
    """The recorded steps of a run with their checks, and the step being recorded."""

    def __init__(self) -> None:
        #: (step, its check) of every stopped step, in order
        self.steps: list[tuple[CalibrationStep, StepCheck]] = []
        #: the kind of the step being recorded ("straight" / "spin"), None between steps
        self.kind: str | None = None
        self._rec: list[list[tuple[float, float]]] = []  # its raw per-interval displacements

    def start_step(self, kind: str) -> None:
        """Start recording a step; ValueError (nothing changed) if one is recording or the
        kind is unknown."""
        if self.kind is not None:
            raise ValueError(f"a {self.kind} step is recording; stop it first")
        if kind not in STEP_KINDS:
            raise ValueError(f"step kind must be one of {STEP_KINDS}, got {kind!r}")
        self.kind = kind
        self._rec = []

    def record(self, raw: Sequence[tuple[float, float]]) -> None:
        """One interval's raw displacements (m, mount order); ignored between steps."""
        if self.kind is not None:
            self._rec.append([tuple(p) for p in raw])

    def current_step(self, sensors: int) -> CalibrationStep | None:
        """The step being recorded so far, of ``sensors`` sensors (None: none recording)."""
        if self.kind is None or not sensors:
            return None
        d = np.array(self._rec, dtype=float).reshape(-1, sensors, 2)
        if d.shape[0] == 0:
            d = np.zeros((1, sensors, 2))
        return CalibrationStep(self.kind, d)

    def step_check(self, mounts: Sequence[SensorMount]) -> StepCheck | None:
        """The live residuals and pass/fail of the step being recorded (None: none)."""
        step = self.current_step(len(mounts))
        return None if step is None else check_step(step, tuple(mounts))

    def stop_step(self, mounts: Sequence[SensorMount]) -> StepCheck:
        """Stop recording: the step is kept (passing or not) and its check returned.

        ValueError if no step is recording."""
        step = self.current_step(len(mounts))
        if step is None:
            raise ValueError("no calibration step is recording")
        check = check_step(step, tuple(mounts))
        self.steps.append((step, check))
        self.kind = None
        self._rec = []
        return check

    def discard_step(self, index: int = -1) -> None:
        """Drop a recorded step (default the last); ValueError if there is none."""
        if not self.steps:
            raise ValueError("no recorded calibration step to discard")
        del self.steps[index]

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
    ) -> MountFit:
        """Fit the whole mount from the recorded steps (:func:`fit_mounts`; nothing applied).

        ValueError while a step is still recording; a
        :class:`~mm_pc.core.calibration_fit.CalibrationRefusedError` for a refused run."""
        if self.kind is not None:
            raise ValueError(f"a {self.kind} step is still recording; press Stop first")
        return fit_mounts(
            [s for s, _ in self.steps],
            tuple(devices),
            tuple(mounts),
            true_distance=true_distance,
            spin_angle=spin_angle,
            sensor=sensor,
            min_distance=min_distance,
        )
