"""Calibration wizard: the whole mount of every sensor from a guided run.

Pages: (1) instructions; (2) record -- explicit steps, each between Start
(straight or spin) and Stop: the session keeps the raw (unfiltered,
uncalibrated) displacements of every interval of the step, nothing after
Stop; the map keeps drawing the robot meanwhile (calibration in force). Live
residuals (distance, how far the path left a line, the spin angle) and a
pass/fail per step: a step whose motion does not fit its kind (a spin that
moved, a straight that turned) is stopped at once with the reason, and no
step starts until the failed one is discarded. With ``mm-monitor --sim
calibration_run`` the page drives the run itself (:class:`AutoDrive`, which
presses Start/Stop per recorded interval). Next once a straight and a spin
passed, every step passed and nothing records; (3) the straights' measured length (optional)
and the angle of each spin; (4) results per sensor with their standard
errors and the predicted heading drift per metre (the whole-mount fit,
``MonitorSession.compute_calibration``), the seed's straight-run angle next
to it, the sim's true mounts when known, and which of the two to use; a
refused run is shown with what to do and changes nothing; (5) save: the YAML
file (``Calibration.save``) and the calibration in force
(``MonitorContext.set_calibration``), then an offer to restart the path.

Cancel (or closing the window) at any time ends the run with the old
calibration still in force (``finish_calibration(None)``); Finish applies the
computed calibration (Save also writes it to the file). The math:
:mod:`mm_pc.core.calibration_fit`; units shown are cm, mm and degrees, kept
in metres and radians.
"""

from __future__ import annotations

import math
from contextlib import suppress
from pathlib import Path

import numpy as np
from PySide6.QtCore import Qt
from PySide6.QtWidgets import (
    QComboBox,
    QFileDialog,
    QFormLayout,
    QHBoxLayout,
    QHeaderView,
    QLabel,
    QLineEdit,
    QProgressBar,
    QPushButton,
    QTableWidget,
    QTableWidgetItem,
    QVBoxLayout,
    QWidget,
    QWizard,
    QWizardPage,
)

from mm_pc.core.calibration import Calibration
from mm_pc.core.calibration_fit import MIN_STRAIGHT_M, MountFit
from mm_pc.monitor.context import MonitorContext
from mm_pc.monitor.model.calibration_autodrive import DONE, GUIDED_KINDS, AutoDrive
from mm_pc.monitor.settings import last_folder, remember_folder
from mm_pc.monitor.widgets.style import ERROR_STYLE

__all__ = ["CalibrationWizard", "parse_spin_angle", "parse_true_distance"]

OK_STYLE = "color: #1b7a1b"
#: the kind of file dialog (``settings.last_folder``) the Save page's Browse remembers
FOLDER_KIND = "calibration"
PAGE_INTRO, PAGE_DRIVE, PAGE_DISTANCE, PAGE_RESULTS, PAGE_SAVE = range(5)
USE_FIT, USE_STRAIGHT_RUN = "whole-mount fit", "straight-run formula (seed)"


def parse_true_distance(text: str) -> float | None:
    """The true run length typed in cm -> metres; empty -> None (scale 1).

    ValueError with what is allowed for junk, NaN, inf, or a length <= 0.
    """
    t = text.strip()
    if not t:
        return None
    allowed = "a number of cm > 0, or empty for scale 1"
    try:
        cm = float(t)
    except ValueError:
        raise ValueError(f"true distance must be {allowed}, got {t!r}") from None
    if not math.isfinite(cm) or cm <= 0:
        raise ValueError(f"true distance must be {allowed}, got {t!r}")
    return cm / 100


def parse_spin_angle(text: str) -> float:
    """The angle of each spin typed in degrees -> rad; empty -> a full turn.

    ValueError with what is allowed for junk, NaN, inf, or an angle <= 0.
    """
    t = text.strip()
    if not t:
        return 2 * math.pi
    allowed = "a number of degrees > 0 (360 = one full turn), or empty for 360"
    try:
        deg = float(t)
    except ValueError:
        raise ValueError(f"spin angle must be {allowed}, got {t!r}") from None
    if not math.isfinite(deg) or deg <= 0:
        raise ValueError(f"spin angle must be {allowed}, got {t!r}")
    return math.radians(deg)


def _error_label() -> QLabel:
    label = QLabel("")
    label.setStyleSheet(ERROR_STYLE)
    label.setWordWrap(True)
    label.hide()
    return label


def _table(columns: list[str]) -> QTableWidget:
    table = QTableWidget(0, len(columns))
    table.setHorizontalHeaderLabels(columns)
    table.verticalHeader().setVisible(False)
    table.setEditTriggers(QTableWidget.NoEditTriggers)
    table.horizontalHeader().setSectionResizeMode(QHeaderView.ResizeToContents)
    return table


def _set_row(table: QTableWidget, row: int, values: list[str]) -> None:
    for c, v in enumerate(values):
        item = table.item(row, c)
        if item is None:
            item = QTableWidgetItem(v)
            if c:
                item.setTextAlignment(Qt.AlignRight | Qt.AlignVCenter)
            table.setItem(row, c, item)
        elif item.text() != v:
            item.setText(v)


class IntroPage(QWizardPage):
    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.setTitle("Calibrate the sensors")
        text = QLabel(
            "<p>The wizard fits, for every sensor at once, its mounting angle, its X and Y "
            "scale and where it sits relative to the turning centre, from a guided run:</p>"
            "<ol><li>Mark a straight line (a ruler or a wall edge) and, if you can, its "
            "length (1&nbsp;m is good).</li>"
            "<li>Press <b>Start straight</b>, push the robot <b>straight forward</b> along "
            "the edge, stop it, press <b>Stop</b>. Then the same <b>back</b>. Twice is "
            "better than once.</li>"
            "<li>Press <b>Start spin</b>, turn the robot <b>on the spot one full turn</b> "
            "(back to where it pointed), press <b>Stop</b>. Once left, once right, twice "
            "each is better.</li></ol>"
            "<p>Each step shows its residuals and passes or fails; a step that cannot be "
            "what you pressed (a spin that moved, a straight that turned) stops at once "
            "with the reason. Discard the failed step and record it again. The map keeps "
            "drawing the robot with the old calibration. Cancel at any time keeps the old "
            "calibration.</p>"
            "<p>With <tt>mm-monitor --sim calibration_run</tt> the next page can drive "
            "the whole run for you.</p>"
        )
        text.setWordWrap(True)
        QVBoxLayout(self).addWidget(text)


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
        self.table = _table(list(self.COLUMNS))
        self.steps_table = _table(list(self.STEP_COLUMNS))
        # the Result (a failure's reason) wraps in the room left, never cut at 1024 px
        self.steps_table.horizontalHeader().setSectionResizeMode(
            len(self.STEP_COLUMNS) - 1, QHeaderView.Stretch
        )
        self.steps_table.setWordWrap(True)
        self.steps_table.horizontalHeader().sectionResized.connect(self._steps_resized)
        self.state = QLabel("not started")
        self.state.setWordWrap(True)
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
            _set_row(self.steps_table, k, [
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
            _set_row(self.table, k, [dev, f"{x * 100:.2f}", f"{y * 100:.2f}", dist, dev_mm, spin])
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


class DistancePage(QWizardPage):
    """The straights' true length (cm, optional: gives the scales) and each spin's angle."""

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.setTitle("Distance and spin angle")
        self.setSubTitle("If you measured how far each straight went, enter it: the scales "
                         "become true / measured (empty: the sensors' mean Y scale stays 1). "
                         "Each spin turned this far (empty: 360 deg, one full turn).")
        self.edit = QLineEdit()
        self.edit.setPlaceholderText("empty = scale from the sensors")
        self.edit.setToolTip("the measured length of each straight in cm (e.g. 100); empty "
                             "keeps the sensors' mean Y scale at 1")
        self.spin_edit = QLineEdit()
        self.spin_edit.setPlaceholderText("empty = 360")
        self.spin_edit.setToolTip("how far each spin turned, in degrees (360 = one full turn)")
        self.error = _error_label()
        self.true_distance: float | None = None
        self.spin_angle = 2 * math.pi
        form = QFormLayout(self)
        form.addRow("True distance of each straight (cm)", self.edit)
        form.addRow("Angle of each spin (deg)", self.spin_edit)
        form.addRow(self.error)

    def validatePage(self) -> bool:  # noqa: N802 - Qt API
        try:
            self.true_distance = parse_true_distance(self.edit.text())
            self.spin_angle = parse_spin_angle(self.spin_edit.text())
        except ValueError as e:
            self.error.setText(str(e))
            self.error.show()
            return False
        self.error.hide()
        return True


def _pm(value: float, se: float | None, fmt: str) -> str:
    return format(value, fmt) + ("" if se is None else f" ± {format(se, fmt)}")


class ResultsPage(QWizardPage):
    """The fitted mount per sensor with standard errors, the drift, the seed's angle."""

    COLUMNS = ("Sensor", "Yaw (deg)", "Scale X", "Scale Y", "x (cm)", "y (cm)",
               "Straight-run angle (deg)", "Previous angle (deg)")
    TRUTH_COLUMNS = ("Sensor", "Yaw fitted (deg)", "Yaw true (deg)", "x fitted (cm)",
                     "x true (cm)", "y fitted (cm)", "y true (cm)")

    def __init__(self, wizard: CalibrationWizard) -> None:
        super().__init__(wizard)
        self._wizard = wizard
        self.setTitle("Results")
        self.setSubTitle("The fitted correction for each sensor (± one standard error; not "
                         "applied yet) and the seed's straight-run angle on the same straights.")
        self.table = _table(list(self.COLUMNS))
        self.drift = QLabel("")
        self.drift.setWordWrap(True)
        self.use_box = QComboBox()
        self.use_box.addItems([USE_FIT, USE_STRAIGHT_RUN])
        self.use_box.setToolTip("<p>whole-mount fit: angle, scales and position of every sensor "
                                "(recommended); straight-run formula: the original's angle "
                                "only, to compare</p>")
        self.use_box.currentTextChanged.connect(lambda _t: self._wizard.choose())
        self.error = _error_label()
        row = QHBoxLayout()
        row.addWidget(QLabel("Use"))
        row.addWidget(self.use_box)
        row.addStretch(1)
        lay = QVBoxLayout(self)
        self.truth_label = QLabel("The sim's sensors are mounted with a known error: the "
                                  "fit next to the truth")
        self.truth_table = _table(list(self.TRUTH_COLUMNS))
        lay.addWidget(self.table)
        lay.addWidget(self.truth_label)
        lay.addWidget(self.truth_table)
        lay.addWidget(self.drift)
        lay.addLayout(row)
        lay.addWidget(self.error)
        self._show_truth(None)

    def initializePage(self) -> None:  # noqa: N802 - Qt API
        self._wizard.compute()
        fit = self._wizard.fit
        old = self._wizard.ctx.session.calibration
        if fit is None:
            self.table.setRowCount(0)
            self.drift.setText("")
            self.error.setText(f"cannot calibrate: {self._wizard.compute_error}")
            self.error.show()
        else:
            self.error.hide()
            self.table.setRowCount(len(fit.devices))
            for k, (dev, c) in enumerate(zip(fit.devices, fit.sensors, strict=True)):
                se = c.angle_offset_se
                _set_row(self.table, k, [
                    dev,
                    _pm(c.angle_offset_deg, None if se is None else math.degrees(se), ".3f"),
                    _pm(c.scale_x, c.scale_x_se, ".4f"),
                    _pm(c.scale_y, c.scale_y_se, ".4f"),
                    _pm(c.x * 100, None if c.x_se is None else c.x_se * 100, ".2f"),
                    _pm(c.y * 100, None if c.y_se is None else c.y_se * 100, ".2f"),
                    f"{fit.straight_run[dev].angle_offset_deg:.3f}",
                    f"{old.get(dev).angle_offset_deg:.3f}",
                ])
            parts = [f"{m}: {math.degrees(v):.3f} deg per metre"
                     for m, v in fit.drift_per_m.items()]
            self.drift.setText(
                "Predicted heading drift driving straight (1 sigma, from the fit's "
                "uncertainty): " + "; ".join(parts)
                + f". Method in use: {self._wizard.ctx.session.method}."
            )
        self._show_truth(fit)
        self.completeChanged.emit()

    def _show_truth(self, fit: MountFit | None) -> None:
        """The fit next to the sim's true mounts (``MonitorConfig.sim_mounts``), if known:
        angle offset = true yaw - the geometry's yaw; positions in base_link."""
        ctx = self._wizard.ctx
        truth = ctx.config.sim_mounts
        shown = fit is not None and bool(truth) and len(truth) >= len(fit.devices)
        self.truth_label.setVisible(shown)
        self.truth_table.setVisible(shown)
        if not shown:
            return
        nominal = ctx.session.odometry_mounts
        cal = fit.calibration()
        self.truth_table.setRowCount(len(fit.devices))
        for k, dev in enumerate(fit.devices):
            c, t = cal[dev], truth[k]
            yaw_true = math.degrees(t.yaw - (nominal[k].yaw if k < len(nominal) else 0.0))
            x = c.x if c.position is not None else math.nan
            y = c.y if c.position is not None else math.nan
            _set_row(self.truth_table, k, [
                dev,
                f"{c.angle_offset_deg:.3f}", f"{yaw_true:.3f}",
                f"{x * 100:.2f}", f"{t.x * 100:.2f}",
                f"{y * 100:.2f}", f"{t.y * 100:.2f}",
            ])
        # as tall as its rows: the page keeps its room for the drift and the choice
        table = self.truth_table
        table.resizeRowsToContents()
        rows = sum(table.rowHeight(r) for r in range(table.rowCount()))
        table.setMaximumHeight(table.horizontalHeader().sizeHint().height() + rows
                               + 2 * table.frameWidth() + table.horizontalScrollBar().sizeHint()
                               .height())

    def cleanupPage(self) -> None:  # noqa: N802 - Qt API
        self._wizard.calibration = None
        self._wizard.fit = None

    def isComplete(self) -> bool:  # noqa: N802 - Qt API
        return self._wizard.calibration is not None


class SavePage(QWizardPage):
    """Path + Browse + Save (writes and applies); Finish applies without writing."""

    def __init__(self, wizard: CalibrationWizard) -> None:
        super().__init__(wizard)
        self._wizard = wizard
        self.setTitle("Save")
        self.setSubTitle("Save writes the file the monitor loads at start and puts the "
                         "calibration in force. Finish without saving uses it for this "
                         "session only.")
        self.path_edit = QLineEdit(str(wizard.ctx.config.calibration_file))
        self.path_edit.setToolTip("the monitor loads this file at start (default "
                                  "~/.config/mouse-monitor/calibration.yaml)")
        browse = QPushButton("Browse…")
        browse.clicked.connect(self._browse)
        self.save_button = QPushButton("Save")
        self.save_button.setToolTip("write the file and put the calibration in force")
        self.save_button.clicked.connect(lambda: self._wizard.save(self.path_edit.text()))
        row = QHBoxLayout()
        row.addWidget(self.path_edit, 1)
        row.addWidget(browse)
        row.addWidget(self.save_button)
        self.error = _error_label()
        self.status = QLabel("")
        self.status.setStyleSheet(OK_STYLE)
        self.status.setWordWrap(True)
        self.restart_label = QLabel(
            "The map's path so far was drawn with the old calibration. Restart it here to "
            "draw the robot with the new one from the origin."
        )
        self.restart_label.setWordWrap(True)
        self.restart_button = QPushButton("Restart the path here")
        self.restart_button.setToolTip("clear the path and values; the pose starts again at "
                                       "the origin, with the new calibration")
        self.restart_button.clicked.connect(self.restart_path)
        self.restart_label.hide()
        self.restart_button.hide()
        lay = QVBoxLayout(self)
        lay.addWidget(QLabel("Calibration file (YAML)"))
        lay.addLayout(row)
        lay.addWidget(self.error)
        lay.addWidget(self.status)
        lay.addWidget(self.restart_label)
        lay.addWidget(self.restart_button, 0, Qt.AlignLeft)
        lay.addStretch(1)

    def offer_restart(self) -> None:
        """After the calibration is in force: offer to restart the path from here."""
        self.restart_label.show()
        self.restart_button.show()
        self.restart_button.setEnabled(True)

    def restart_path(self) -> None:
        """Restart the path and values (``MonitorContext.reset``): the pose from the origin
        with the new calibration."""
        self._wizard.ctx.reset()
        self.restart_button.setEnabled(False)
        self.restart_label.setText("path restarted: the robot is drawn with the new "
                                   "calibration from the origin")
        self._wizard.ctx.status_message.emit("path restarted with the new calibration")

    def _browse(self) -> None:
        """A save dialog in the folder the last calibration went to (never the repository)."""
        start = Path(last_folder(FOLDER_KIND)) / Path(self.path_edit.text()).name
        path, _ = QFileDialog.getSaveFileName(
            self, "Save calibration", str(start), "YAML (*.yaml *.yml)"
        )
        if path:
            self.path_edit.setText(path)
            remember_folder(FOLDER_KIND, path)


class CalibrationWizard(QWizard):
    """The calibration wizard (a QDialog).

    ``fit``: the :class:`MountFit` of the run, or None; ``calibration``: the
    one chosen on the results page (the fit, or the seed's straight-run
    formula), or None.
    """

    def __init__(self, ctx: MonitorContext, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.ctx = ctx
        self.setWindowTitle("Calibration wizard")
        self.setOption(QWizard.NoBackButtonOnStartPage, True)
        self.calibration: Calibration | None = None
        self.fit: MountFit | None = None
        self.compute_error = ""
        self.applied = False
        self._done = False
        self.intro_page = IntroPage(self)
        self.drive_page = DrivePage(ctx, self)
        self.distance_page = DistancePage(self)
        self.results_page = ResultsPage(self)
        self.save_page = SavePage(self)
        for pid, page in (
            (PAGE_INTRO, self.intro_page),
            (PAGE_DRIVE, self.drive_page),
            (PAGE_DISTANCE, self.distance_page),
            (PAGE_RESULTS, self.results_page),
            (PAGE_SAVE, self.save_page),
        ):
            self.setPage(pid, page)
        self.setStartId(PAGE_INTRO)
        self.resize(820, 560)

    def compute(self) -> Calibration | None:
        """Fit from the recorded steps (distance and spin angle of the pages); None on a
        refused run (``compute_error`` says why and what to do; nothing changes)."""
        try:
            self.fit = self.ctx.session.compute_calibration(
                self.distance_page.true_distance, self.distance_page.spin_angle
            )
            self.compute_error = ""
        except ValueError as e:
            self.fit = None
            self.calibration = None
            self.compute_error = str(e)
            return None
        return self.choose()

    def choose(self) -> Calibration | None:
        """The calibration of the method picked on the results page."""
        if self.fit is None:
            self.calibration = None
        elif self.results_page.use_box.currentText() == USE_STRAIGHT_RUN:
            self.calibration = self.fit.straight_run
        else:
            self.calibration = self.fit.calibration()
        return self.calibration

    def save(self, path: str | Path) -> bool:
        """Write the computed calibration to ``path`` and apply it; False (nothing applied,
        message on the page) if it cannot be written."""
        page = self.save_page
        cal = self.calibration
        if cal is None:
            page.error.setText("nothing to save: no calibration was computed")
            page.error.show()
            return False
        path = Path(str(path).strip()).expanduser()
        try:
            if not str(path) or path.is_dir():
                raise OSError(f"{str(path)!r} is not a file name")
            path.parent.mkdir(parents=True, exist_ok=True)
            cal.save(path)
        except OSError as e:
            page.error.setText(f"not saved and not applied: {e}")
            page.error.show()
            page.status.setText("")
            return False
        page.error.hide()
        remember_folder(FOLDER_KIND, path)
        self._apply(cal, str(path))
        page.status.setText(f"saved to {path} and applied")
        page.offer_restart()
        return True

    def _apply(self, cal: Calibration, source: str = "") -> None:
        self.ctx.session.finish_calibration(cal)
        self.ctx.set_calibration(cal, source or "calibration wizard (not saved)")
        self.applied = True
        self.ctx.status_message.emit("new calibration in force")

    def done(self, result: int) -> None:
        """Finish applies the result; Cancel/close ends the run with the old calibration."""
        if result == QWizard.Accepted and not self.validateCurrentPage():
            return
        if not self._done:
            self._done = True
            if result == QWizard.Accepted and self.calibration is not None:
                if not self.applied:
                    self._apply(self.calibration)
            elif self.ctx.session.calibrating:
                self.ctx.session.finish_calibration(None)
                self.ctx.status_message.emit("calibration cancelled; the old one stays")
            # a closed wizard stays a child of the window: stop listening to every reply
            for signal in (self.ctx.reply_processed, self.ctx.devices_known):
                with suppress(RuntimeError, TypeError):
                    signal.disconnect(self.drive_page.update_sums)
        super().done(result)
