"""Page 2: record the guided run -- Start/Stop per step, the live residuals of the step
being recorded, the recorded steps with pass/fail, one sensor's note, and for a
``--sim calibration_run`` node the run driven for the user (:class:`AutoDrive`)."""

from __future__ import annotations

import math

import numpy as np
from PySide6.QtWidgets import (
    QHBoxLayout,
    QHeaderView,
    QLabel,
    QProgressBar,
    QPushButton,
    QVBoxLayout,
    QWidget,
    QWizardPage,
)

from mm_pc.core.calibration_fit import MIN_STRAIGHT_M
from mm_pc.monitor.context import MonitorContext
from mm_pc.monitor.model.calibration_autodrive import DONE, GUIDED_KINDS, AutoDrive
from mm_pc.monitor.model.calibration_run import one_sensor_note
from mm_pc.monitor.widgets.calibration_wizard.choices import (
    OK_STYLE,
)
from mm_pc.monitor.widgets.calibration_wizard.table_helpers import (
    make_table,
    set_row,
)
from mm_pc.monitor.widgets.style import ERROR_STYLE


class DrivePage(QWizardPage):
    """Start/Stop per step; live residuals of the recording step; the steps so far; for
    a ``--sim calibration_run`` node, "Drive the calibration run for me"."""

    COLUMNS = ("Sensor", "X sum (cm)", "Y sum (cm)", "Distance (cm)", "Off line (mm)",
               "Spin (deg)")
    STEP_COLUMNS = ("Step", "Kind", "Distance (cm)", "Off line (mm)", "Result")

    def __init__(self, ctx: MonitorContext, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.ctx = ctx
        self.setTitle("Record the guided run")
        self.setSubTitle("Start a step, move the robot, Stop. Straight forward and back, then "
                         "a full turn on the spot each way.")
        self.straight_button = QPushButton("Start straight")
        self.straight_button.clicked.connect(lambda: self.start("straight"))
        self.spin_button = QPushButton("Start spin")
        self.spin_button.clicked.connect(lambda: self.start("spin"))
        self.stop_button = QPushButton("Stop")
        self.stop_button.clicked.connect(self.stop)
        self.discard_button = QPushButton("Discard last step")
        self.discard_button.clicked.connect(self.discard)
        self.straight_button.setToolTip("record a straight: push the robot straight forward "
                                        "(or back) along a marked edge, then press Stop")
        self.spin_button.setToolTip("record a spin: turn the robot on the spot one full turn, "
                                    "then press Stop")
        self.stop_button.setToolTip("end the step: nothing after Stop is recorded; the step "
                                    "passes or fails")
        self.discard_button.setToolTip("forget the failed step (or, if none failed, the last "
                                       "one)")
        # kept for the old name: Restart = discard everything and open the run again
        self.start_button = self.straight_button
        self.auto_button = QPushButton("Drive the calibration run for me")
        self.auto_button.clicked.connect(self.start_auto)
        self.auto_cancel_button = QPushButton("Cancel driving")
        self.auto_cancel_button.setToolTip("stop pressing Start/Stop; the recorded steps stay")
        self.auto_cancel_button.clicked.connect(self.cancel_auto)
        self.auto_progress = QProgressBar()
        self.auto_progress.setFormat("%v of %m steps")
        self.auto_label = QLabel("")
        self.auto_label.setWordWrap(True)
        self.table = make_table(list(self.COLUMNS))
        self.steps_table = make_table(list(self.STEP_COLUMNS))
        # the Result (a failure's reason) wraps in the room left, never cut at 1024 px
        self.steps_table.horizontalHeader().setSectionResizeMode(
            len(self.STEP_COLUMNS) - 1, QHeaderView.Stretch
        )
        self.steps_table.setWordWrap(True)
        self.steps_table.horizontalHeader().sectionResized.connect(self._steps_resized)
        self.state = QLabel("not started")
        self.state.setWordWrap(True)
        self.one_sensor = QLabel("")  # what the checks can tell with one sensor
        self.one_sensor.setWordWrap(True)
        self.one_sensor.hide()
        self._complete = False
        buttons = QHBoxLayout()
        for b in (self.straight_button, self.spin_button, self.stop_button, self.discard_button):
            buttons.addWidget(b)
        buttons.addStretch(1)
        auto = QHBoxLayout()
        auto.addWidget(self.auto_button)
        auto.addWidget(self.auto_progress, 1)
        auto.addWidget(self.auto_cancel_button)
        self.auto_row = QWidget()
        self.auto_row.setLayout(auto)
        self.auto_row.layout().setContentsMargins(0, 0, 0, 0)
        lay = QVBoxLayout(self)
        lay.addWidget(self.auto_row)
        lay.addWidget(self.auto_label)
        lay.addLayout(buttons)
        lay.addWidget(self.one_sensor)
        lay.addWidget(QLabel("Step being recorded"))
        lay.addWidget(self.table)
        lay.addWidget(self.state)
        lay.addWidget(QLabel("Recorded steps"))
        lay.addWidget(self.steps_table)
        self._setup_auto()
        ctx.reply_processed.connect(self.update_sums)
        ctx.devices_known.connect(self.update_sums)

    @property
    def min_distance(self) -> float:
        """The shortest straight accepted (m)."""
        return MIN_STRAIGHT_M

    # -- the sim's run, driven ----------------------------------------------------------

    def _setup_auto(self) -> None:
        """The auto-drive row: shown for a --sim node, usable on its calibration_run."""
        sim = self.ctx.config.sim
        self.auto_row.setVisible(bool(sim))
        self.auto_label.setVisible(bool(sim))
        if not sim:
            return
        usable = sim == "calibration_run"
        self.auto_button.setToolTip(
            "the sim drives the guided run over and over (straight forward and back, two "
            "full turns each way); this presses Start and Stop for you, per reply, and "
            "records one whole lap (about 35 s, plus up to one lap to find its start)"
            if usable else
            f"the sim drives {sim}, not the guided run: start mm-monitor --sim "
            "calibration_run to have the run driven for you"
        )  # fmt: skip
        self.auto_label.setText(
            "The robot is simulated: the wizard can drive the calibration run for you."
            if usable else
            f"The robot is simulated on {sim}: start mm-monitor --sim calibration_run to have "
            "the calibration run driven for you, or record the steps by hand."
        )  # fmt: skip
        self.auto_progress.setRange(0, len(GUIDED_KINDS))
        self.auto_progress.setValue(0)

    @property
    def auto(self) -> AutoDrive | None:
        """The driver of the open run (None: none started)."""
        run = self.ctx.session.calibration_run
        return None if run is None else run.auto

    def start_auto(self) -> bool:
        """Drive the sim's guided run; False (reason shown) if it cannot start."""
        session = self.ctx.session
        if not session.calibrating:
            session.start_calibration()
        run = session.calibration_run
        why = ""
        if not session.devices:
            why = "no sensor data yet: wait for the first reply"
        elif session.recording_step is not None:
            why = f"a {session.recording_step} step is recording: press Stop first"
        elif run.failed_step() is not None:
            why = "a step failed: press Discard failed step first"
        if why:
            self.auto_label.setText(why)
            return False
        run.auto = AutoDrive(session.odometry_mounts)
        self.auto_progress.setRange(0, run.auto.total)
        self.ctx.status_message.emit("driving the calibration run: " + run.auto.message)
        self.update_sums()
        return True

    def cancel_auto(self) -> None:
        auto = self.auto
        if auto is not None and auto.active:
            auto.cancel(self.ctx.session.calibration_run)
        self.update_sums()
        self.update_steps()

    def _update_auto(self) -> bool:
        """Show the driver's progress; True while it drives."""
        auto = self.auto
        driving = auto is not None and auto.active
        usable = self.ctx.config.sim == "calibration_run"
        self.auto_button.setEnabled(usable and not driving and bool(self.ctx.session.devices))
        self.auto_cancel_button.setEnabled(driving)
        if auto is not None:
            self.auto_progress.setValue(auto.recorded)
            self.auto_label.setText(auto.message)
            self.auto_label.setStyleSheet(
                OK_STYLE if auto.state == DONE else ERROR_STYLE if not auto.active else ""
            )
        return driving

    # -- steps by hand -------------------------------------------------------------------

    def initializePage(self) -> None:  # noqa: N802 - Qt API
        if not self.ctx.session.calibrating:
            self.ctx.session.start_calibration()
            self.ctx.status_message.emit("calibration run open: record the steps")
        self.update_sums()
        self.update_steps()

    def cleanupPage(self) -> None:  # noqa: N802 - Qt API
        """Back to the instructions: the run ends, the old calibration stays."""
        if self.ctx.session.calibrating:
            self.ctx.session.finish_calibration(None)
        self.update_sums()
        self.update_steps()

    def start(self, kind: str) -> bool:
        """Start recording a ``kind`` step; False (message shown) if one is recording or
        a failed step is still in the list."""
        session = self.ctx.session
        if not session.calibrating:
            session.start_calibration()
        try:
            session.start_calibration_step(kind)
        except ValueError as e:
            self.state.setText(str(e))
            return False
        self.ctx.status_message.emit(f"recording a {kind} step: press Stop when the robot stopped")
        self.update_sums()
        return True

    def stop(self) -> None:
        """Stop the step: nothing more is recorded; its pass/fail goes into the list."""
        session = self.ctx.session
        if session.recording_step is None:
            return
        check = session.stop_calibration_step()
        self.ctx.status_message.emit(
            f"{check.kind} step " + ("passed" if check.ok else f"failed: {check.message}")
        )
        self.update_steps()
        self.update_sums()

    def discard(self) -> None:
        """Forget the failed step (if none failed, the last one)."""
        if self.ctx.session.calibration_steps():
            k = self.ctx.session.discard_calibration_step()
            self.ctx.status_message.emit(f"calibration step {k + 1} discarded")
        self.update_steps()
        self.update_sums()

    def _steps_resized(self, section: int, _old: int, _new: int) -> None:
        if section == len(self.STEP_COLUMNS) - 1:  # the Result column: rewrap its rows
            self.steps_table.resizeRowsToContents()

    def update_steps(self) -> None:
        steps = self.ctx.session.calibration_steps()
        self.steps_table.setRowCount(len(steps))
        for k, (step, check) in enumerate(steps):
            set_row(self.steps_table, k, [
                str(k + 1), step.kind,
                " / ".join(f"{v * 100:.1f}" for v in check.distance),
                " / ".join(f"{v * 1000:.1f}" for v in check.deviation),
                "pass" if check.ok else f"fail: {check.message}",
            ])
            item = self.steps_table.item(k, 4)
            item.setToolTip(item.text())
        self.steps_table.resizeRowsToContents()
        failed = any(not c.ok for _, c in steps)
        self.discard_button.setText("Discard failed step" if failed else "Discard last step")
        self._recheck()

    def update_sums(self, *_args) -> None:
        """Show the live residuals of the recording step and re-check completeness; a
        step that already failed for good (a spin that moved, a straight that turned)
        is stopped here, at once."""
        session = self.ctx.session
        run = session.calibration_run
        mounts = session.odometry_mounts[: len(session.devices)]
        self.one_sensor.setText(one_sensor_note(mounts[0]) if len(mounts) == 1 else "")
        self.one_sensor.setVisible(len(mounts) == 1)
        by_hand = run is not None and (run.auto is None or not run.auto.active)
        if by_hand and run.kind is not None and run.live_failure(mounts):
            self.stop()
            return
        if run is not None and len(run.steps) != self.steps_table.rowCount():
            self.update_steps()  # the driver stopped or started a step
        driving = self._update_auto()
        devices = session.devices
        recording = session.recording_step
        failed = run is not None and run.failed_step() is not None
        for b in (self.straight_button, self.spin_button):
            b.setEnabled(bool(devices) and recording is None and not failed and not driving)
        self.stop_button.setEnabled(recording is not None and not driving)
        self.discard_button.setEnabled(
            recording is None and bool(session.calibration_steps()) and not driving
        )
        sums = session.calibration_sums()
        check = session.calibration_step_check()
        if self.table.rowCount() != len(devices):
            self.table.setRowCount(len(devices))
        for k, dev in enumerate(devices):
            x, y = sums.get(dev, (0.0, 0.0))
            if check is None:
                dist = dev_mm = spin = ""
            else:
                dist = f"{check.distance[k] * 100:.2f}"
                dev_mm = f"{check.deviation[k] * 1000:.2f}"
                a = check.angle[k]
                spin = f"{math.degrees(a):.0f}" if math.isfinite(a) else ""
            set_row(self.table, k, [dev, f"{x * 100:.2f}", f"{y * 100:.2f}", dist, dev_mm, spin])
        if not devices:
            self.state.setText("no sensor data yet: waiting for the first reply")
        elif recording is None:
            self.state.setText(self._next_hint())
        elif check.ok:
            self.state.setText(f"recording {recording}: passes so far; stop the robot, press Stop")
        elif check.message.startswith("spin too small"):  # not yet: the spin is under way
            turned = float(np.nanmean(check.angle)) if np.any(np.isfinite(check.angle)) else 0.0
            self.state.setText(f"recording spin: about {math.degrees(turned):.0f}° so far; turn "
                               "it on the spot a full turn, then press Stop")
        else:
            self.state.setText(f"recording {recording}: {check.message}")
        self.state.setStyleSheet(ERROR_STYLE if failed else "")
        self._recheck()

    def _next_hint(self) -> str:
        steps = self.ctx.session.calibration_steps()
        kinds = [s.kind for s, c in steps if c.ok]
        bad = next((k for k, (_, c) in enumerate(steps) if not c.ok), None)
        if bad is not None:
            return (f"step {bad + 1} failed: {steps[bad][1].message}. Press Discard failed "
                    "step and record it again")
        if "straight" not in kinds:
            return "press Start straight, push the robot straight forward, press Stop"
        if "spin" not in kinds:
            return "press Start spin, turn the robot one full turn on the spot, press Stop"
        return (f"{len(kinds)} steps passed: record more (back, the other way) or press Next")

    def _recheck(self) -> None:
        session = self.ctx.session
        steps = session.calibration_steps()
        kinds = {s.kind for s, c in steps if c.ok}
        auto = self.auto
        complete = (
            session.recording_step is None
            and all(c.ok for _, c in steps)
            and kinds == {"straight", "spin"}
            and not (auto is not None and auto.active)
        )
        if complete != self._complete:
            self._complete = complete
            self.completeChanged.emit()

    def isComplete(self) -> bool:  # noqa: N802 - Qt API
        return self._complete
