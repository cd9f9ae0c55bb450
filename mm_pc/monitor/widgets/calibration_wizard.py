"""Calibration wizard: mounting angle and scale per sensor from a straight run (issue item 5).

Pages: (1) instructions, (2) drive straight -- the session sums the raw
(unfiltered, uncalibrated) X/Y of every sensor while the robot stands still
on the map; Next only once every sensor travelled the minimum distance,
(3) optional true length of the run for the scale, (4) results per sensor
(angle offset, distance, scale) from ``MonitorSession.compute_calibration``,
(5) save: the YAML file (``Calibration.save``) and the new calibration in
force (``MonitorContext.set_calibration``).

Cancel (or closing the window) at any time ends the run with the old
calibration still in force (``finish_calibration(None)``); Finish applies the
computed calibration (Save also writes it to the file). The math and its
sign conventions are in :mod:`mm_pc.core.calibration`; units shown are cm and
degrees, kept in metres and radians.
"""

from __future__ import annotations

import math
from contextlib import suppress
from pathlib import Path

from PySide6.QtCore import Qt
from PySide6.QtWidgets import (
    QDoubleSpinBox,
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

from mm_pc.core.calibration import DEFAULT_MIN_DISTANCE_M, Calibration
from mm_pc.monitor.context import MonitorContext
from mm_pc.monitor.widgets.style import ERROR_STYLE

__all__ = ["CalibrationWizard", "parse_true_distance"]

OK_STYLE = "color: #1b7a1b"
PAGE_INTRO, PAGE_DRIVE, PAGE_DISTANCE, PAGE_RESULTS, PAGE_SAVE = range(5)


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
            "<p>A sensor mounted a little turned reports every movement turned by the same "
            "angle, so a straight run looks like a slanted one. This wizard measures that "
            "angle (and, if you know the true length of the run, a scale factor) for every "
            "sensor at once.</p>"
            "<ol><li>Put the robot at the start of a straight line.</li>"
            "<li>On the next page press <b>Start</b>, then drive (or push) the robot "
            "<b>straight forward</b> for at least the minimum distance (more is better: "
            "20&nbsp;cm or more). Do not turn.</li>"
            "<li>Optionally measure the true length of the run with a ruler.</li></ol>"
            "<p>While the run is recorded, the robot <b>stands still on the map</b>: no pose "
            "is computed from uncalibrated data. Cancel at any time keeps the old "
            "calibration.</p>"
        )
        text.setWordWrap(True)
        QVBoxLayout(self).addWidget(text)


class DrivePage(QWizardPage):
    """Start/Restart the run; live raw sums per sensor; complete once all went far enough."""

    COLUMNS = ("Sensor", "X sum (cm)", "Y sum (cm)", "Distance (cm)", "")

    def __init__(self, ctx: MonitorContext, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.ctx = ctx
        self.setTitle("Drive straight")
        self.setSubTitle("Press Start, then drive straight forward; Next is enabled when every "
                         "sensor has travelled the minimum distance.")
        self.start_button = QPushButton("Start")
        self.start_button.clicked.connect(self.start)
        self.restart_button = QPushButton("Restart")
        self.restart_button.setToolTip("zero the sums and begin the run again")
        self.restart_button.clicked.connect(self.start)
        self.min_spin = QDoubleSpinBox()
        self.min_spin.setRange(0.5, 1000.0)
        self.min_spin.setDecimals(1)
        self.min_spin.setSuffix(" cm")
        self.min_spin.setValue(DEFAULT_MIN_DISTANCE_M * 100)
        self.min_spin.valueChanged.connect(lambda _v: self.update_sums())
        self.table = _table(list(self.COLUMNS))
        self.state = QLabel("not started")
        self._complete = False
        buttons = QHBoxLayout()
        buttons.addWidget(self.start_button)
        buttons.addWidget(self.restart_button)
        buttons.addStretch(1)
        buttons.addWidget(QLabel("Minimum distance"))
        buttons.addWidget(self.min_spin)
        lay = QVBoxLayout(self)
        lay.addLayout(buttons)
        lay.addWidget(self.table)
        lay.addWidget(self.state)
        ctx.reply_processed.connect(self.update_sums)
        ctx.devices_known.connect(self.update_sums)

    @property
    def min_distance(self) -> float:
        """The minimum run length in force (m)."""
        return self.min_spin.value() / 100

    def initializePage(self) -> None:  # noqa: N802 - Qt API
        self.update_sums()

    def cleanupPage(self) -> None:  # noqa: N802 - Qt API
        """Back to the instructions: the run ends, the old calibration stays, the robot moves."""
        if self.ctx.session.calibrating:
            self.ctx.session.finish_calibration(None)
        self.update_sums()

    def start(self) -> None:
        """Begin (or begin again) the straight run: sums to zero, the pose stops."""
        self.ctx.session.start_calibration()
        self.ctx.status_message.emit("calibration run started: the robot stands still on the map")
        self.update_sums()

    def update_sums(self, *_args) -> None:
        """Show the raw sums (cm) and re-check the page's completeness."""
        session = self.ctx.session
        running = session.calibrating
        devices = session.devices
        self.start_button.setEnabled(bool(devices) and not running)
        self.restart_button.setEnabled(running)
        sums = session.calibration_sums()
        if self.table.rowCount() != len(devices):
            self.table.setRowCount(len(devices))
        short = []
        for k, dev in enumerate(devices):
            x, y = sums.get(dev, (0.0, 0.0))
            d = math.hypot(x, y)
            ok = running and d >= self.min_distance
            if running and not ok:
                short.append(dev)
            _set_row(
                self.table, k,
                [dev, f"{x * 100:.2f}", f"{y * 100:.2f}", f"{d * 100:.2f}",
                 "enough" if ok else ""],
            )
        if not devices:
            self.state.setText("no sensor data yet: waiting for the first reply")
        elif not running:
            self.state.setText("not started: press Start, then drive straight forward")
        elif short:
            self.state.setText(
                f"recording; still short of {self.min_spin.value():g} cm: {', '.join(short)}"
            )
        else:
            self.state.setText("enough distance: stop the robot and press Next")
        complete = running and bool(devices) and not short
        if complete != self._complete:
            self._complete = complete
            self.completeChanged.emit()

    def isComplete(self) -> bool:  # noqa: N802 - Qt API
        return self._complete


class DistancePage(QWizardPage):
    """The run's true length (cm), optional: gives the scale factor."""

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.setTitle("True distance (optional)")
        self.setSubTitle("If you measured how far the robot really went, enter it: each "
                         "sensor's scale becomes true / measured. Leave empty for scale 1.")
        self.edit = QLineEdit()
        self.edit.setPlaceholderText("empty = scale 1")
        self.error = _error_label()
        self.true_distance: float | None = None
        form = QFormLayout(self)
        form.addRow("True distance (cm)", self.edit)
        form.addRow(self.error)

    def validatePage(self) -> bool:  # noqa: N802 - Qt API
        try:
            self.true_distance = parse_true_distance(self.edit.text())
        except ValueError as e:
            self.error.setText(str(e))
            self.error.show()
            return False
        self.error.hide()
        return True


class ResultsPage(QWizardPage):
    """The computed calibration per sensor; errors (too short, sideways) shown here."""

    COLUMNS = ("Sensor", "Angle offset (deg)", "Distance (cm)", "Scale", "Previous offset (deg)")

    def __init__(self, wizard: CalibrationWizard) -> None:
        super().__init__(wizard)
        self._wizard = wizard
        self.setTitle("Results")
        self.setSubTitle("The correction for each sensor (not applied yet).")
        self.table = _table(list(self.COLUMNS))
        self.error = _error_label()
        lay = QVBoxLayout(self)
        lay.addWidget(self.table)
        lay.addWidget(self.error)

    def initializePage(self) -> None:  # noqa: N802 - Qt API
        self._wizard.compute()
        cal = self._wizard.calibration
        old = self._wizard.ctx.session.calibration
        if cal is None:
            self.table.setRowCount(0)
            self.error.setText(f"cannot calibrate: {self._wizard.compute_error}; go Back, "
                               "press Restart and drive straight forward again")
            self.error.show()
        else:
            self.error.hide()
            self.table.setRowCount(len(cal))
            for k, dev in enumerate(cal):
                c = cal[dev]
                _set_row(self.table, k, [
                    dev, f"{c.angle_offset_deg:.2f}", f"{c.distance * 100:.2f}",
                    f"{c.scale:.4f}", f"{old.get(dev).angle_offset_deg:.2f}",
                ])
        self.completeChanged.emit()

    def cleanupPage(self) -> None:  # noqa: N802 - Qt API
        self._wizard.calibration = None

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
        browse = QPushButton("Browse…")
        browse.clicked.connect(self._browse)
        self.save_button = QPushButton("Save")
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
        path, _ = QFileDialog.getSaveFileName(
            self, "Save calibration", self.path_edit.text(), "YAML (*.yaml *.yml)"
        )
        if path:
            self.path_edit.setText(path)


class CalibrationWizard(QWizard):
    """The calibration wizard (a QDialog). ``calibration``: the computed result, or None."""

    def __init__(self, ctx: MonitorContext, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.ctx = ctx
        self.setWindowTitle("Calibration wizard")
        self.setOption(QWizard.NoBackButtonOnStartPage, True)
        self.calibration: Calibration | None = None
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
        self.resize(640, 460)

    def compute(self) -> Calibration | None:
        """Compute from the run so far (true distance and minimum of the pages); None on error."""
        try:
            self.calibration = self.ctx.session.compute_calibration(
                self.distance_page.true_distance, self.drive_page.min_distance
            )
            self.compute_error = ""
        except ValueError as e:
            self.calibration = None
            self.compute_error = str(e)
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
        self._apply(cal)
        page.status.setText(f"saved to {path} and applied")
        return True

    def _apply(self, cal: Calibration) -> None:
        self.ctx.session.finish_calibration(cal)
        self.ctx.set_calibration(cal)
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
