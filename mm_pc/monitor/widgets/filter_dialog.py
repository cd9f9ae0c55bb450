"""Median filter settings per sensor and axis, applied live (issue item 6).

One row per sensor: an "X" and a "Y" check box (the X box switches the
filter of the sensor's X axis -- the original had them swapped) and the
window in samples (1..999). Ticking a box, or Enter in the window field,
applies that sensor at once; "Apply" applies every row. A refused window
(junk, 0, 1000, 2.5) is shown in red next to its field and nothing of that
apply changes. "Clear filters" switches every filter off and forgets their
history (``MonitorSession.clear_filters``).

The filters act on the per-reply displacements (metres, sensor frame) before
the calibration and the pose math; see :mod:`mm_pc.core.filters`.
"""

from __future__ import annotations

from contextlib import suppress
from dataclasses import dataclass

from PySide6.QtCore import Qt
from PySide6.QtWidgets import (
    QCheckBox,
    QDialog,
    QDialogButtonBox,
    QGridLayout,
    QLabel,
    QLineEdit,
    QPushButton,
    QVBoxLayout,
    QWidget,
)

from mm_pc.core.filters import MAX_WINDOW, MIN_WINDOW, validate_window
from mm_pc.monitor.context import MonitorContext
from mm_pc.monitor.widgets.style import ERROR_STYLE

__all__ = ["FilterDialog", "parse_window"]


def parse_window(text: str) -> int:
    """A window typed by the user -> samples (int, 1..999); ValueError with the range otherwise."""
    t = text.strip()
    if not t:
        raise ValueError(f"median window is empty: type an integer number of samples in "
                         f"{MIN_WINDOW}..{MAX_WINDOW}")
    try:
        value: object = int(t)
    except ValueError:
        try:
            value = float(t)
        except ValueError:
            value = t  # validate_window names it in the message
    return validate_window(value)


@dataclass
class _Row:
    device: str
    fx: QCheckBox
    fy: QCheckBox
    window: QLineEdit
    error: QLabel


class FilterDialog(QDialog):
    """Median filter per sensor: X/Y enable and window, applied live to the session."""

    def __init__(self, ctx: MonitorContext, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.ctx = ctx
        self.setWindowTitle("Median filters")
        self.rows: dict[str, _Row] = {}
        self._grid_host = QWidget()
        self.grid = QGridLayout(self._grid_host)
        self.note = QLabel(
            f"Window in samples ({MIN_WINDOW}..{MAX_WINDOW}), a true median over the newest "
            "replies. X filters the sensor's X axis (right), Y its Y axis (forward). A check "
            "box applies its sensor at once, Enter in a window field too; Apply applies "
            "every row. At low sample rates a median throws correct large steps away "
            "(a late reply holds more counts), so filters are off by default."
        )
        self.note.setWordWrap(True)
        self.status = QLabel("")
        self.apply_button = QPushButton("Apply")
        self.apply_button.clicked.connect(self.apply_all)
        self.clear_button = QPushButton("Clear filters")
        self.clear_button.setToolTip("switch every filter off and forget the samples they hold")
        self.clear_button.clicked.connect(self.clear_filters)
        buttons = QDialogButtonBox(QDialogButtonBox.Close)
        buttons.addButton(self.apply_button, QDialogButtonBox.ApplyRole)
        buttons.addButton(self.clear_button, QDialogButtonBox.ResetRole)
        for b in buttons.buttons():  # Enter in a field applies that field, never closes
            b.setAutoDefault(False)
            b.setDefault(False)
        buttons.rejected.connect(self.reject)
        lay = QVBoxLayout(self)
        lay.addWidget(self.note)
        lay.addWidget(self._grid_host)
        lay.addWidget(self.status)
        lay.addWidget(buttons)
        self._build_rows()
        ctx.devices_known.connect(self._build_rows)
        ctx.session_reset.connect(self.load_from_session)

    # -- construction ----------------------------------------------------------------------

    def _build_rows(self, *_args) -> None:
        """One row per known sensor (again when the sensors become known late)."""
        while self.grid.count():
            w = self.grid.takeAt(0).widget()
            if w is not None:
                w.deleteLater()
        self.rows.clear()
        devices = self.ctx.session.devices
        if not devices:
            self.grid.addWidget(QLabel("No sensor data yet: the rows appear with the first reply."))
            self.apply_button.setEnabled(False)
            return
        self.apply_button.setEnabled(True)
        for c, title in enumerate(("Sensor", "Filter X", "Filter Y", "Window (samples)")):
            self.grid.addWidget(QLabel(f"<b>{title}</b>"), 0, c)
        for i, dev in enumerate(devices, start=1):
            row = _Row(dev, QCheckBox("X"), QCheckBox("Y"), QLineEdit(), QLabel(""))
            row.window.setMaximumWidth(80)
            row.window.setToolTip(f"{MIN_WINDOW}..{MAX_WINDOW} samples; Enter applies")
            row.error.setStyleSheet(ERROR_STYLE)
            row.error.setWordWrap(True)
            row.error.hide()
            self.grid.addWidget(QLabel(dev), 2 * i - 1, 0)
            self.grid.addWidget(row.fx, 2 * i - 1, 1)
            self.grid.addWidget(row.fy, 2 * i - 1, 2)
            self.grid.addWidget(row.window, 2 * i - 1, 3)
            self.grid.addWidget(row.error, 2 * i, 0, 1, 4)
            self.rows[dev] = row
        self.load_from_session()
        for row in self.rows.values():
            row.fx.toggled.connect(lambda _on, d=row.device: self.apply_sensor(d))
            row.fy.toggled.connect(lambda _on, d=row.device: self.apply_sensor(d))
            row.window.returnPressed.connect(lambda d=row.device: self.apply_sensor(d))

    def load_from_session(self) -> None:
        """Show the session's filter settings (without applying anything)."""
        for dev, row in self.rows.items():
            f = self.ctx.session.filters.get(dev)
            if f is None:
                continue
            for box, on in ((row.fx, f.filter_x), (row.fy, f.filter_y)):
                box.blockSignals(True)
                box.setChecked(on)
                box.blockSignals(False)
            row.window.setText(str(f.window))
            row.error.hide()

    # -- actions ----------------------------------------------------------------------------

    def _show_error(self, row: _Row, error: ValueError | None) -> None:
        if error is None:
            row.error.hide()
            return
        row.error.setText(f"{row.device}: {error}; nothing changed")
        row.error.setToolTip(row.error.text())
        row.error.show()
        self._fit_height()

    def _fit_height(self) -> None:
        """Grow the dialog so a wrapped error message shows whole (it was cut off when the
        dialog kept the height it had without it)."""
        self.layout().activate()
        need = self.layout().totalHeightForWidth(self.width())
        if need > self.height():
            self.resize(self.width(), need)

    def apply_sensor(self, device: str) -> bool:
        """Apply one sensor's row; False (its filter unchanged, message shown) if refused."""
        row = self.rows[device]
        try:
            window = parse_window(row.window.text())
            self.ctx.session.set_filter(device, window, row.fx.isChecked(), row.fy.isChecked())
        except ValueError as e:
            self._show_error(row, e)
            self._restore_boxes(row)
            return False
        self._show_error(row, None)
        self._say(f"{device}: {self._describe(device)}")
        return True

    def apply_all(self) -> bool:
        """Apply every row, or none of them if any window is refused."""
        windows = {}
        for dev, row in self.rows.items():
            try:
                windows[dev] = parse_window(row.window.text())
            except ValueError as e:
                self._show_error(row, e)
            else:
                self._show_error(row, None)
        if len(windows) != len(self.rows):
            self._say("not applied: fix the field marked in red")
            return False
        for dev, row in self.rows.items():
            self.ctx.session.set_filter(dev, windows[dev], row.fx.isChecked(), row.fy.isChecked())
        self._say("applied: " + "; ".join(f"{d}: {self._describe(d)}" for d in self.rows))
        return True

    def keyPressEvent(self, event) -> None:  # noqa: N802 - Qt API
        """Enter or Return never closes the dialog: in a window field it applies that row
        (its returnPressed), elsewhere it does nothing; Escape still closes."""
        if event.key() in (Qt.Key_Return, Qt.Key_Enter):
            event.accept()
            return
        super().keyPressEvent(event)

    def clear_filters(self) -> None:
        self.ctx.session.clear_filters()
        self.load_from_session()
        self._say("filters cleared (all off)")

    def done(self, result: int) -> None:
        """Closed: stop following the session (the dialog may outlive its window)."""
        for signal, slot in (
            (self.ctx.devices_known, self._build_rows),
            (self.ctx.session_reset, self.load_from_session),
        ):
            with suppress(RuntimeError, TypeError):
                signal.disconnect(slot)
        super().done(result)

    # -- helpers ----------------------------------------------------------------------------

    def _restore_boxes(self, row: _Row) -> None:
        """Put the check boxes back to what is in force after a refused apply."""
        f = self.ctx.session.filters.get(row.device)
        if f is None:
            return
        for box, on in ((row.fx, f.filter_x), (row.fy, f.filter_y)):
            box.blockSignals(True)
            box.setChecked(on)
            box.blockSignals(False)

    def _describe(self, device: str) -> str:
        f = self.ctx.session.filters[device]
        axes = [a for a, on in (("X", f.filter_x), ("Y", f.filter_y)) if on] or ["off"]
        return f"{'+'.join(axes)}, window {f.window}"

    def _say(self, text: str) -> None:
        self.status.setText(text)
        self.ctx.status_message.emit(f"median filter {text}")
