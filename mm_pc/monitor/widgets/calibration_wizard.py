"""Calibration wizard: the whole mount of every sensor from a guided run.

Pages: (1) instructions; (2) record -- explicit steps, each between Start
(straight or spin) and Stop: the session keeps the raw (unfiltered,
uncalibrated) displacements of every interval of the step, nothing after
Stop; the robot stands still on the map while the run is open. Live
residuals (distance, how far the path left a line, the spin angle) and a
pass/fail per step; Next once a straight and a spin passed, every step
passed and nothing records; (3) the straights' measured length (optional)
and the angle of each spin; (4) results per sensor with their standard
errors and the predicted heading drift per metre (the whole-mount fit,
``MonitorSession.compute_calibration``), the seed's straight-run angle next
to it, and which of the two to use; a refused run is shown with what to do
and changes nothing; (5) save: the YAML file (``Calibration.save``) and the
calibration in force (``MonitorContext.set_calibration``).

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

from PySide6.QtCore import Qt
from PySide6.QtWidgets import (
    QComboBox,
    QFileDialog,
    QFormLayout,
    QHBoxLayout,
    QHeaderView,
    QLabel,
    QLineEdit,
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
            "<p>Each step shows its residuals and passes or fails; a failed step is "
            "discarded and recorded again. While the run is open, the robot <b>stands "
            "still on the map</b>. Cancel at any time keeps the old calibration.</p>"
        )
        text.setWordWrap(True)
        QVBoxLayout(self).addWidget(text)


class DrivePage(QWizardPage):
    """Start/Stop per step; live residuals of the recording step; the steps so far."""

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
        self.discard_button.setToolTip("forget the last recorded step (e.g. a failed one)")
        # kept for the old name: Restart = discard everything and open the run again
        self.start_button = self.straight_button
        self.table = _table(list(self.COLUMNS))
        self.steps_table = _table(list(self.STEP_COLUMNS))
        self.state = QLabel("not started")
        self.state.setWordWrap(True)
        self._complete = False
        buttons = QHBoxLayout()
        for b in (self.straight_button, self.spin_button, self.stop_button, self.discard_button):
            buttons.addWidget(b)
        buttons.addStretch(1)
        lay = QVBoxLayout(self)
        lay.addLayout(buttons)
        lay.addWidget(QLabel("Step being recorded"))
        lay.addWidget(self.table)
        lay.addWidget(self.state)
        lay.addWidget(QLabel("Recorded steps"))
        lay.addWidget(self.steps_table)
        ctx.reply_processed.connect(self.update_sums)
        ctx.devices_known.connect(self.update_sums)

    @property
    def min_distance(self) -> float:
        """The shortest straight accepted (m)."""
        return MIN_STRAIGHT_M

    def initializePage(self) -> None:  # noqa: N802 - Qt API
        if not self.ctx.session.calibrating:
            self.ctx.session.start_calibration()
            self.ctx.status_message.emit("calibration run open: the robot stands still on the map")
        self.update_sums()
        self.update_steps()

    def cleanupPage(self) -> None:  # noqa: N802 - Qt API
        """Back to the instructions: the run ends, the old calibration stays, the robot moves."""
        if self.ctx.session.calibrating:
            self.ctx.session.finish_calibration(None)
        self.update_sums()
        self.update_steps()

    def start(self, kind: str) -> bool:
        """Start recording a ``kind`` step; False (message shown) if one is recording."""
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
        if self.ctx.session.calibration_steps():
            self.ctx.session.discard_calibration_step()
        self.update_steps()
        self.update_sums()

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
        self._recheck()

    def update_sums(self, *_args) -> None:
        """Show the live residuals of the recording step and re-check completeness."""
        session = self.ctx.session
        devices = session.devices
        recording = session.recording_step
        for b in (self.straight_button, self.spin_button):
            b.setEnabled(bool(devices) and recording is None)
        self.stop_button.setEnabled(recording is not None)
        self.discard_button.setEnabled(recording is None and bool(session.calibration_steps()))
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
        else:
            self.state.setText(f"recording {recording}: {check.message}")
        self._recheck()

    def _next_hint(self) -> str:
        steps = self.ctx.session.calibration_steps()
        kinds = [s.kind for s, c in steps if c.ok]
        if any(not c.ok for _, c in steps):
            return "a step failed: press Discard last step and record it again"
        if "straight" not in kinds:
            return "press Start straight, push the robot straight forward, press Stop"
        if "spin" not in kinds:
            return "press Start spin, turn the robot one full turn on the spot, press Stop"
        return (f"{len(kinds)} steps passed: record more (back, the other way) or press Next")

    def _recheck(self) -> None:
        session = self.ctx.session
        steps = session.calibration_steps()
        kinds = {s.kind for s, c in steps if c.ok}
        complete = (
            session.recording_step is None
            and all(c.ok for _, c in steps)
            and kinds == {"straight", "spin"}
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
        lay.addWidget(self.table)
        lay.addWidget(self.drift)
        lay.addLayout(row)
        lay.addWidget(self.error)

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
        self.completeChanged.emit()

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
        lay = QVBoxLayout(self)
        lay.addWidget(QLabel("Calibration file (YAML)"))
        lay.addLayout(row)
        lay.addWidget(self.error)
        lay.addWidget(self.status)
        lay.addStretch(1)

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
