"""The log: one line per sensor per reply with the raw and the processed values.

Like the original's log window: what the node served (counts, displacement,
its speed, CPI, polls, lifts) beside what the monitor made of it (after the
median filter and the calibration). The dialog is non-modal and reads
``session.log`` on a 4 Hz timer (not per reply: at 500 Hz that would be
1000 lines a second of widget work), appending only the entries it has not
shown yet. Newest at the bottom.
"""

from __future__ import annotations

from PySide6.QtCore import Qt, QTimer
from PySide6.QtGui import QFont, QGuiApplication, QTextCursor
from PySide6.QtWidgets import (
    QCheckBox,
    QDialog,
    QFrame,
    QHBoxLayout,
    QLabel,
    QPlainTextEdit,
    QPushButton,
    QScrollArea,
    QVBoxLayout,
)

from mm_pc.monitor.model.session import LogEntry

__all__ = ["HEADER", "LogDialog", "format_entry"]

UPDATE_MS = 250
#: (title, width) of each column; the widths are those of format_entry's fields
_COLUMNS = (
    ("t s", 10), ("sensor", 16), ("cnt X", 7), ("cnt Y", 7),
    ("raw dX mm", 10), ("raw dY mm", 10), ("dX mm", 10), ("dY mm", 10),
    ("vX mm/s", 9), ("vY mm/s", 9), ("CPI", 5), ("polls", 5), ("lifts", 5),
)
HEADER = " ".join(
    f"{title:<{w}}" if title == "sensor" else f"{title:>{w}}" for title, w in _COLUMNS
)


def format_entry(e: LogEntry) -> str:
    """One log line: t (s), sensor, counts, raw and processed displacement (mm), node's speed
    (mm/s), CPI, polls in the interval, lift events."""
    return (
        f"{e.t:10.3f} {e.sensor:<16} {e.x_counts:7d} {e.y_counts:7d} "
        f"{e.raw_dx * 1e3:10.4f} {e.raw_dy * 1e3:10.4f} {e.dx * 1e3:10.4f} {e.dy * 1e3:10.4f} "
        f"{e.x_speed * 1e3:9.2f} {e.y_speed * 1e3:9.2f} {e.cpi:5d} {e.samples:5d} "
        f"{e.lift_events:5d}"
    )


class LogDialog(QDialog):
    """Non-modal log window with auto-scroll, pause, clear and copy all."""

    def __init__(self, ctx, parent=None) -> None:
        super().__init__(parent)
        self.ctx = ctx
        self.setWindowTitle("Log — raw and processed values")
        self.setModal(False)
        self.setAttribute(Qt.WA_DeleteOnClose)  # the window opens a new one per click
        self.resize(1000, 500)
        self._last: LogEntry | None = None  # the newest entry shown

        mono = QFont("monospace")
        mono.setStyleHint(QFont.Monospace)
        self.header = QLabel(HEADER)
        self.header.setFont(mono)
        self.text = QPlainTextEdit()
        self.text.setReadOnly(True)
        self.text.setFont(mono)
        self.text.setLineWrapMode(QPlainTextEdit.NoWrap)
        self.text.setMaximumBlockCount(max(ctx.session.log.maxlen or 5000, 100))
        self.text.setUndoRedoEnabled(False)
        # line the header up with the text: frame plus document margin
        self.header.setIndent(self.text.frameWidth() + int(self.text.document().documentMargin()))
        # the header scrolls sideways with the lines (its own width set the dialog's least
        # width, 926 px: more than an 800 px screen)
        self.header_area = QScrollArea()
        self.header_area.setWidget(self.header)
        self.header_area.setFrameShape(QFrame.NoFrame)
        self.header_area.setHorizontalScrollBarPolicy(Qt.ScrollBarAlwaysOff)
        self.header_area.setVerticalScrollBarPolicy(Qt.ScrollBarAlwaysOff)
        self.header_area.setFixedHeight(self.header.sizeHint().height())
        self.header.adjustSize()
        self.text.horizontalScrollBar().valueChanged.connect(
            self.header_area.horizontalScrollBar().setValue)

        self.auto_scroll = QCheckBox("Auto-scroll")
        self.auto_scroll.setChecked(True)
        self.pause_box = QCheckBox("Pause")
        self.pause_box.setToolTip("stop adding lines; resuming adds what came meanwhile")
        self.pause_box.toggled.connect(lambda on: None if on else self.poll())
        clear = QPushButton("Clear")
        clear.clicked.connect(self.clear)
        copy = QPushButton("Copy all")
        copy.clicked.connect(self.copy_all)
        for button in (clear, copy):  # Enter must not press one (it emptied the log)
            button.setAutoDefault(False)
        self.count = QLabel("")
        bar = QHBoxLayout()
        for w in (self.auto_scroll, self.pause_box, clear, copy):
            bar.addWidget(w)
        bar.addStretch(1)
        bar.addWidget(self.count)
        lay = QVBoxLayout(self)
        lay.addLayout(bar)
        lay.addWidget(self.header_area)
        lay.addWidget(self.text, 1)

        self.timer = QTimer(self)
        self.timer.setInterval(UPDATE_MS)
        self.timer.timeout.connect(self.poll)
        ctx.session_reset.connect(self._on_reset)
        self.poll()

    def showEvent(self, event) -> None:  # noqa: N802 - Qt API
        self.timer.start()
        self.poll()
        super().showEvent(event)

    def hideEvent(self, event) -> None:  # noqa: N802 - Qt API
        self.timer.stop()
        super().hideEvent(event)

    def _new_entries(self) -> tuple[list[LogEntry], bool]:
        """Entries after the newest one shown, oldest first; and whether some were missed."""
        log = self.ctx.session.log
        if not log or log[-1] is self._last:
            return [], False
        new: list[LogEntry] = []
        for e in reversed(log):
            if e is self._last:
                return new[::-1], False
            new.append(e)
        return new[::-1], self._last is not None

    def poll(self) -> int:
        """Append the entries not shown yet (nothing while paused); returns how many."""
        if self.pause_box.isChecked():
            return 0
        entries, gap = self._new_entries()
        if not entries:
            return 0
        self._last = entries[-1]
        lines = [format_entry(e) for e in entries]
        if gap:
            lines.insert(0, "… older entries left the log before they could be shown")
        bar = self.text.verticalScrollBar()
        keep = bar.value()
        self.text.appendPlainText("\n".join(lines))
        if self.auto_scroll.isChecked():
            self.text.moveCursor(QTextCursor.End)
            bar.setValue(bar.maximum())
        else:
            bar.setValue(keep)
        self.count.setText(f"{self.text.blockCount()} lines")
        return len(entries)

    def lines(self) -> list[str]:
        """The lines shown (without the header)."""
        text = self.text.toPlainText()
        return text.split("\n") if text else []

    def clear(self) -> None:
        """Empty the view; only entries from now on will appear (the session keeps its log)."""
        self.text.clear()
        log = self.ctx.session.log
        self._last = log[-1] if log else None
        self.count.setText("0 lines")

    def _on_reset(self) -> None:
        self.text.clear()
        self._last = None
        self.count.setText("")

    def copy_all(self) -> str:
        """Header and every line shown, to the clipboard; returns the text."""
        text = HEADER + "\n" + self.text.toPlainText() + "\n"
        QGuiApplication.clipboard().setText(text)
        return text
