"""The plain data list: one table per sensor, newest reply first, copyable and exportable.

The table model reads the history's columns in place (no per-frame copy):
row ``r`` of the table is history row ``len - 1 - r``. At most
:data:`MAX_ROWS` of the newest rows are listed; the CSV export writes all
rows the history holds. New replies are announced to the view as rows
inserted at the top, so a selection stays on the rows it was made on.
"""

from __future__ import annotations

import math
import time
from pathlib import Path

from PySide6.QtCore import QAbstractTableModel, QEvent, QModelIndex, QSize, Qt, QTimer, Signal
from PySide6.QtGui import QGuiApplication, QKeySequence
from PySide6.QtWidgets import (
    QAbstractItemView,
    QFileDialog,
    QHBoxLayout,
    QHeaderView,
    QLabel,
    QPushButton,
    QTableView,
    QTabWidget,
    QVBoxLayout,
    QWidget,
)

from mm_pc.monitor.model.chips import chip_title
from mm_pc.monitor.model.csv_export import (
    COLUMNS,
    column_name,
    export_csv,
    history_csv_chunks,
)
from mm_pc.monitor.settings import last_folder, remember_folder
from mm_pc.monitor.widgets.style import ERROR_STYLE

__all__ = ["MAX_ROWS", "REFRESH_PERIOD_S", "DataListView", "HistoryTableModel"]

#: Rows listed per sensor (the newest); the CSV export has them all.
MAX_ROWS = 100_000
#: the window's frames announce new rows to the table at most this often (s): a repaint of
#: the table asks the model for every visible cell's roles (~2000 Python calls, 40 ms on a
#: slow PC), and numbers that change 30 times a second cannot be read anyway
REFRESH_PERIOD_S = 0.1
#: a CSV export's progress beside its button is renewed at most this often (s)
PROGRESS_PERIOD_S = 0.25

_DISPLAY = Qt.ItemDataRole.DisplayRole
_ALIGNMENT_ROLE = Qt.ItemDataRole.TextAlignmentRole
_RIGHT = Qt.AlignmentFlag.AlignRight | Qt.AlignmentFlag.AlignVCenter
_HORIZONTAL = Qt.Orientation.Horizontal


def _cell(fmt: str, value: float) -> str:
    """A cell's text; a NaN (no quality figure, no value yet) shows as a dash."""
    return "\u2013" if math.isnan(value) else fmt.format(value)


#: the widest text a column of each format shows (a sign, 4-5 digits before the point)
_WIDEST = {"{:.3f}": "99999.999", "{:.4f}": "-9999.9999", "{:.2f}": "-99999.99",
           "{:.0f}": "999999"}


def fit_columns(table: QTableView) -> None:
    """Each column as wide as its header and its widest value (font metrics), never less:
    a narrow window scrolls the table sideways instead of cutting the numbers ("144…")."""
    header = table.horizontalHeader()
    header.setSectionResizeMode(QHeaderView.Interactive)
    header.setStretchLastSection(True)
    style = table.style()
    cell_pad = 2 * (style.pixelMetric(style.PixelMetric.PM_FocusFrameHMargin) + 1) + 6
    head_pad = 2 * style.pixelMetric(style.PixelMetric.PM_HeaderMargin) + 6
    fm, hfm = table.fontMetrics(), header.fontMetrics()
    for col, (title, _field, _scale, fmt) in enumerate(COLUMNS):
        widest = _WIDEST.get(fmt, "-99999.9999")
        table.setColumnWidth(col, max(hfm.horizontalAdvance(title) + head_pad,
                                      fm.horizontalAdvance(widest) + cell_pad))


class _NumberHeader(QHeaderView):
    """The tables' vertical header (the reply numbers, newest first, so section 0 holds the
    widest). Qt's own size hint is the widest of ~200 sections' labels, asked again from the
    model every time rows are inserted (~1000 Python calls a frame); this one measures
    section 0 once per number of digits, and again when its font or style changes."""

    def __init__(self, parent=None) -> None:
        super().__init__(Qt.Orientation.Vertical, parent)
        self._hint: tuple[int, QSize] | None = None

    def changeEvent(self, event) -> None:  # noqa: N802 - Qt API
        if event.type() in (QEvent.Type.FontChange, QEvent.Type.StyleChange):
            self._hint = None
        super().changeEvent(event)

    def sizeHint(self) -> QSize:  # noqa: N802 - Qt API
        model = self.model()
        if model is None or model.rowCount() == 0:
            return super().sizeHint()
        digits = len(str(model.headerData(0, Qt.Orientation.Vertical)))
        if self._hint is None or self._hint[0] != digits:
            self._hint = (digits, self.sectionSizeFromContents(0))
        return self._hint[1]


class HistoryTableModel(QAbstractTableModel):
    """One sensor's history rows, newest first, read in place from the session's History."""

    def __init__(
        self, session, sensor_index: int, max_rows: int = MAX_ROWS, parent=None, ctx=None
    ) -> None:
        super().__init__(parent)
        self._session = session
        #: with a context, the model follows ``ctx.session`` (a replay may put a new one in place)
        self.ctx = ctx
        self.sensor_index = sensor_index
        self.max_rows = max_rows
        self._names = [column_name(sensor_index, f) for _h, f, _s, _f in COLUMNS]
        self._rows = 0  # rows announced to the views
        self._len = 0  # history length at the last sync
        self._dropped = 0
        self._history = None
        self._version = -1
        self._cols: list = []  # column views of the history, taken at the last sync
        self._cache: dict[int, tuple[str, ...]] = {}

    @property
    def session(self):
        return self.ctx.session if self.ctx is not None else self._session

    def rowCount(self, parent=QModelIndex()) -> int:  # noqa: B008, N802 - Qt API
        return 0 if parent.isValid() else self._rows

    def columnCount(self, parent=QModelIndex()) -> int:  # noqa: B008, N802 - Qt API
        return 0 if parent.isValid() else len(COLUMNS)

    def headerData(self, section, orientation, role=_DISPLAY):  # noqa: N802 - Qt API
        if role != _DISPLAY:
            return None
        if orientation == _HORIZONTAL:
            return COLUMNS[section][0] if 0 <= section < len(COLUMNS) else None
        return str(self._len - section)  # the reply's number, 1 = first

    def value(self, row: int, column: int) -> float:
        """The value shown at (row, column), in display units (mm, mm/s, s)."""
        hist = self._history
        return float(hist.column(self._names[column])[self._len - 1 - row]) * COLUMNS[column][2]

    def text(self, row: int, column: int) -> str:
        return self._row_texts(row)[column]

    def _row_texts(self, row: int) -> tuple[str, ...]:
        # a repaint asks for every visible cell several times; rows never change once written
        i = self._len - 1 - row
        texts = self._cache.get(i)
        if texts is None:
            if len(self._cache) > 4096:
                self._cache.clear()
            texts = tuple(
                _cell(fmt, float(hist_col[i]) * scale)
                for hist_col, (_h, _f, scale, fmt) in zip(self._cols, COLUMNS, strict=True)
            )
            self._cache[i] = texts
        return texts

    def data(self, index, role=_DISPLAY):
        if role == _DISPLAY:
            row = index.row()
            return self._row_texts(row)[index.column()] if 0 <= row < self._rows else None
        if role == _ALIGNMENT_ROLE:
            return _RIGHT
        return None

    def sync(self) -> None:
        """Catch up with the history: rows inserted at the top when replies were appended,
        a model reset when it was cleared or trimmed."""
        hist = self.session.history
        if hist is None:
            if self._rows:
                self.reset()
            return
        if hist is self._history and hist.version == self._version:
            return
        n = len(hist)
        appended = (
            hist is self._history and hist.dropped_rows == self._dropped and n >= self._len
        )
        if not appended:
            self.reset()
            return
        added = n - self._len
        shown = min(n, self.max_rows)
        overflow = self._rows + added - shown  # old rows that leave the bottom
        if overflow > 0:
            keep = max(0, self._rows - overflow)
            if keep < self._rows:
                self.beginRemoveRows(QModelIndex(), keep, self._rows - 1)
                self._rows = keep
                self.endRemoveRows()
        new = shown - self._rows
        self._version = hist.version
        self._cols = [hist.column(n) for n in self._names]  # the buffer may have moved
        if new > 0:
            self.beginInsertRows(QModelIndex(), 0, new - 1)
            self._len, self._rows = n, shown
            self.endInsertRows()
        else:
            self._len = n
        # no headerDataChanged: a row's number (len - section) moves with the row

    def reset(self) -> None:
        """Re-read everything (after a clear or when the history dropped old rows)."""
        self.beginResetModel()
        hist = self.session.history
        self._history = hist
        self._len = len(hist) if hist is not None else 0
        self._rows = min(self._len, self.max_rows)
        self._dropped = hist.dropped_rows if hist is not None else 0
        self._version = hist.version if hist is not None else -1
        self._cols = [hist.column(n) for n in self._names] if hist is not None else []
        self._cache.clear()
        self.endResetModel()

    def rows_text(self, rows: list[int]) -> str:
        """Tab-separated text of the given rows (display order) with a header line."""
        lines = ["\t".join(h for h, _f, _s, _fmt in COLUMNS)]
        for r in sorted(rows):
            lines.append("\t".join(self.text(r, c) for c in range(len(COLUMNS))))
        return "\n".join(lines) + "\n"


class _CopyTableView(QTableView):
    """A table view whose Ctrl+C copies whole selected rows (Qt's own copies one cell)."""

    copy_requested = Signal()

    def event(self, event) -> bool:
        if event.type() == QEvent.ShortcutOverride and event.matches(QKeySequence.Copy):
            event.accept()  # ours, before any window-wide Ctrl+C shortcut
            return True
        return super().event(event)

    def keyPressEvent(self, event) -> None:  # noqa: N802 - Qt API
        if event.matches(QKeySequence.Copy):
            self.copy_requested.emit()
            event.accept()
            return
        super().keyPressEvent(event)


class SensorTable(QWidget):
    """One sensor's table with Copy and Export CSV… and the export's error label."""

    def __init__(self, ctx, sensor_index: int, parent=None) -> None:
        super().__init__(parent)
        self.ctx = ctx
        self.sensor_index = sensor_index
        self.model = HistoryTableModel(ctx.session, sensor_index, parent=self, ctx=ctx)
        #: the CSV file name's prefix (the replayed recording's name; "" = live)
        self.csv_prefix = ""
        self.table = _CopyTableView()
        self.table.setVerticalHeader(_NumberHeader(self.table))
        self.table.setModel(self.model)
        self.table.setSelectionBehavior(QAbstractItemView.SelectRows)
        self.table.setSelectionMode(QAbstractItemView.ExtendedSelection)
        self.table.setAlternatingRowColors(True)
        vh = self.table.verticalHeader()
        vh.setSectionResizeMode(QHeaderView.Fixed)
        vh.setDefaultSectionSize(20)
        fit_columns(self.table)
        self.table.copy_requested.connect(self.copy_selection)

        self.copy_button = QPushButton("Copy")
        self.copy_button.setToolTip("copy the selected rows as tab-separated text (Ctrl+C)")
        self.copy_button.clicked.connect(self.copy_selection)
        self.export_button = QPushButton("Export CSV…")
        self.export_button.setToolTip("every row of this sensor, oldest first, units in the header")
        self.export_button.clicked.connect(self.choose_export)
        self.message = QLabel("")
        self.message.setWordWrap(True)
        bar = QHBoxLayout()
        bar.addWidget(self.copy_button)
        bar.addWidget(self.export_button)
        bar.addWidget(self.message, 1)
        lay = QVBoxLayout(self)
        lay.setContentsMargins(0, 0, 0, 0)
        lay.addLayout(bar)
        lay.addWidget(self.table, 1)

    def selected_rows(self) -> list[int]:
        sel = self.table.selectionModel()
        return sorted({i.row() for i in sel.selectedIndexes()}) if sel else []

    def copy_selection(self) -> str:
        """Put the selected rows on the clipboard (header line first); returns the text."""
        rows = self.selected_rows()
        if not rows:
            return ""
        text = self.model.rows_text(rows)
        QGuiApplication.clipboard().setText(text)
        return text

    def choose_export(self) -> None:
        dev = self.ctx.session.devices[self.sensor_index].strip("/").replace("/", "_")
        name = f"{self.csv_prefix}_{dev}.csv" if self.csv_prefix else f"{dev}.csv"
        path, _ = QFileDialog.getSaveFileName(
            self, "Export CSV", str(Path(last_folder("csv")) / name),
            "CSV files (*.csv);;All files (*)",
        )  # fmt: skip
        if path:
            remember_folder("csv", path)
            self.export_in_background(path)

    def export_to(self, path: str | Path) -> bool:
        """Export this sensor's rows now; the result or the error is shown beside the button."""
        try:
            n = export_csv(self.ctx.session.history, self.sensor_index, path)
        except (OSError, ValueError) as e:
            return self._exported(path, e)
        return self._exported(path, n)

    def export_in_background(self, path: str | Path) -> bool:
        """Export this sensor's rows without holding the window: the rows held now are copied
        and written 2500 a timer tick (``csv_export.history_csv_chunks``; an hour of 100 Hz
        rows took ~0.6 s in one go: a freeze). No worker thread: a
        Python thread can run the garbage collector and destroy Qt objects off the GUI
        thread. The button is disabled meanwhile and the share written so far is shown beside
        it (every :data:`PROGRESS_PERIOD_S`), the result when done;
        ``export_done`` holds True/False then. False (the error shown) when there is no
        data."""
        history = self.ctx.session.history
        try:
            steps = history_csv_chunks(history, self.sensor_index, path)
        except ValueError as e:
            return self._exported(path, e)
        rows = len(history)
        self.export_done = None
        self.export_button.setEnabled(False)
        self.message.setStyleSheet("")
        self.message.setText(f"writing {rows} rows to {path} …")
        timer = QTimer(self)
        shown_at = [time.perf_counter()]

        def step() -> None:
            try:
                written = next(steps, None)
            except (OSError, ValueError) as e:
                written = e
            if written is not None and not isinstance(written, Exception):
                now = time.perf_counter()
                if now >= shown_at[0] + PROGRESS_PERIOD_S:  # a new text re-lays the row out
                    shown_at[0] = now
                    self.message.setText(f"writing {rows} rows to {path} … "
                                         f"{100 * written // max(rows, 1)} %")
                return
            timer.stop()
            timer.deleteLater()
            self.export_button.setEnabled(True)
            self.export_done = self._exported(path, written or rows)

        timer.timeout.connect(step)
        timer.start(0)
        return True

    def _exported(self, path, result: int | Exception) -> bool:
        """Show the export's row count or error beside the button; True if written."""
        if isinstance(result, Exception):
            self.message.setStyleSheet(ERROR_STYLE)
            self.message.setText(f"export failed: {result}")
            return False
        self.message.setStyleSheet("")
        self.message.setText(f"{result} rows written to {path}")
        return True

    #: the last background export: None while it runs, then whether it was written
    export_done: bool | None = None


class DataListView(QWidget):
    """Tabs with one :class:`SensorTable` per sensor."""

    #: the window's frames refresh this view at most this often (s)
    refresh_period_s = REFRESH_PERIOD_S

    def __init__(self, ctx, parent=None) -> None:
        super().__init__(parent)
        self.ctx = ctx
        self.tables: list[SensorTable] = []
        self.tabs = QTabWidget()
        self.tabs.currentChanged.connect(lambda _i: self.refresh())
        self.note = QLabel(
            f"newest first; the newest {MAX_ROWS:,} rows are listed, the CSV export has all. "
            "dX/dY: filtered and calibrated; raw: as the node served them (sensor frame)."
        )
        self.note.setWordWrap(True)
        self.time_base = QLabel("t: seconds from the first live reply of this path")
        self.time_base.setWordWrap(True)
        self.time_base.setToolTip(
            "a replay's times run from 0 at the recording's first reply; back to live, a new "
            "path starts at 0 again (live and recorded rows are never mixed)"
        )
        self.csv_prefix = ""
        self._built_for: tuple[str, ...] = ()
        self._chips: tuple[str, ...] = ()
        self.waiting = QLabel("waiting for the first reply")
        lay = QVBoxLayout(self)
        lay.addWidget(self.note)
        lay.addWidget(self.time_base)
        lay.addWidget(self.waiting)
        lay.addWidget(self.tabs, 1)
        ctx.devices_known.connect(self._build)
        ctx.session_reset.connect(self._on_reset)
        if ctx.session.devices:
            self._build(ctx.session.devices)

    def _build(self, devices: tuple[str, ...]) -> None:
        if len(self.tables) == len(devices) and self._built_for == tuple(devices):
            return
        self.tabs.clear()
        self.tables = []
        self._built_for = tuple(devices)
        self._chips: tuple[str, ...] = ()
        for k, dev in enumerate(devices):
            table = SensorTable(self.ctx, k, self)
            table.csv_prefix = self.csv_prefix
            self.tables.append(table)
            self.tabs.addTab(table, dev)
        self._show_chips()
        self.waiting.hide()

    def _show_chips(self) -> None:
        """Each sensor's tab names its chip once a reply said which it is."""
        chips = tuple(self.ctx.session.chip(d) for d in self._built_for)
        if chips == self._chips or self.tabs.count() != len(chips):  # (tabs being added)
            return
        self._chips = chips
        for k, (dev, chip) in enumerate(zip(self._built_for, chips, strict=True)):
            title = chip_title(chip) if chip else ""
            self.tabs.setTabText(k, f"{dev} ({title})" if title else dev)
            self.tabs.setTabToolTip(
                k, f"sensor {k + 1}: {dev}, chip {title}" if title else
                f"sensor {k + 1}: {dev} (the node names no chip: a PLN2033 or an old node)")

    def set_time_base(self, text: str, csv_prefix: str = "") -> None:
        """Say what the t column counts from; ``csv_prefix`` starts the CSV file names (the
        replayed recording's name, "" for live data)."""
        self.time_base.setText(text)
        self.csv_prefix = csv_prefix
        for t in self.tables:
            t.csv_prefix = csv_prefix

    def _on_reset(self) -> None:
        if self.ctx.session.devices:  # a replay of other sensors: their tabs
            self._build(self.ctx.session.devices)
        for t in self.tables:
            t.model.reset()

    def refresh(self) -> None:
        """Announce new rows to the visible table (nothing to do when nothing changed)."""
        if not self.tables:
            if not self.ctx.session.devices:
                return
            self._build(self.ctx.session.devices)
        self._show_chips()
        table = self.tables[self.tabs.currentIndex()] if self.tables else None
        if table is not None:
            table.model.sync()
