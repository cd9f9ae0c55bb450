"""The calibration run's state (model/calibration_run.py): steps, sums, checks; no Qt.

The session's use of it (the pose integrating on, the fit of a guided run) is in
tests/monitor/test_monitor_session.py; the step checks of a spin that moved, a
straight that turned and a piece of the figure eight, and the auto driver on the
simulated guided run, are in tests/monitor/test_monitor_calibration_steps.py.
"""

from __future__ import annotations

import numpy as np
import pytest

from mm_pc.core.geometry import DEFAULT_MOUNTS
from mm_pc.monitor.model.calibration_run import CalibrationRun

DEVICES = ("/dev/spidev1.0", "/dev/spidev1.1")


def straight(run: CalibrationRun, intervals: int, dy: float = 0.001) -> None:
    """Both sensors ``dy`` (m) forward per interval."""
    for _ in range(intervals):
        run.record([(0.0, dy), (0.0, dy)])


def test_a_step_keeps_only_what_came_between_start_and_stop():
    run = CalibrationRun()
    straight(run, 50)  # before Start: not kept
    assert run.kind is None and run.current_step(2) is None and run.sums(DEVICES) == {}
    run.start_step("straight")
    assert run.sums(DEVICES) == {DEVICES[0]: (0.0, 0.0), DEVICES[1]: (0.0, 0.0)}
    straight(run, 200)
    run.record([(0.0005, 0.001), (0.0, 0.001)])
    sums = run.sums(DEVICES)
    assert sums[DEVICES[0]] == pytest.approx((0.0005, 0.201))
    assert sums[DEVICES[1]] == pytest.approx((0.0, 0.201))
    step = run.current_step(2)
    assert step.kind == "straight" and step.d.shape == (201, 2, 2)
    live = run.step_check(DEFAULT_MOUNTS)
    check = run.stop_step(DEFAULT_MOUNTS)
    assert check.ok and live.ok and check.message == ""
    np.testing.assert_allclose(check.distance, [0.201, 0.201], rtol=1e-5)
    straight(run, 50)  # after Stop: not kept
    assert run.kind is None and len(run.steps) == 1
    assert run.steps[0][0].d.shape == (201, 2, 2)


def test_refusals_change_nothing():
    run = CalibrationRun()
    with pytest.raises(ValueError, match="no calibration step is recording"):
        run.stop_step(DEFAULT_MOUNTS)
    with pytest.raises(ValueError, match="no recorded calibration step to discard"):
        run.discard_step()
    with pytest.raises(ValueError, match="step kind must be one of"):
        run.start_step("wiggle")
    run.start_step("spin")
    with pytest.raises(ValueError, match="a spin step is recording; stop it first"):
        run.start_step("straight")
    with pytest.raises(ValueError, match="a spin step is still recording; press Stop first"):
        run.fit(DEVICES, DEFAULT_MOUNTS, sensor=0)
    assert run.kind == "spin" and run.steps == []
    check = run.stop_step(DEFAULT_MOUNTS)  # nothing recorded: kept, but refused
    assert not check.ok and len(run.steps) == 1
    assert check.message.startswith("not a spin: it moved 0.0 cm and turned 0°")
    # a failed step blocks the next one until it is discarded (issue 29)
    with pytest.raises(ValueError, match=r"step 1 failed \(not a spin: .*press Discard failed"):
        run.start_step("straight")
    assert run.kind is None and len(run.steps) == 1
    assert run.discard_step() == 0 and run.steps == []
    run.start_step("straight")
    straight(run, 10)
    short = run.stop_step(DEFAULT_MOUNTS)
    assert not short.ok and short.message.startswith("straight too short: 1.0 cm")
    assert [s.kind for s, _ in run.steps] == ["straight"]
    with pytest.raises(ValueError, match=r"step 1 \(straight\): straight too short"):
        run.fit(DEVICES, DEFAULT_MOUNTS, sensor=0)
