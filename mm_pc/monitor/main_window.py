"""The monitor's main window: tabs of views, a control dock, the status bar.

It only wires things together: views get the shared
:class:`~.context.MonitorContext`; a frame timer asks the visible views to
redraw (each skips the work when nothing changed); the status bar shows the
link state, round-trip time and achieved sample rate from the bridge.
"""

from __future__ import annotations

import time
from collections import deque

from PySide6.QtCore import Qt, QTimer
from PySide6.QtGui import QAction, QKeySequence
from PySide6.QtWidgets import (
    QComboBox,
    QDockWidget,
    QFormLayout,
    QGroupBox,
    QHBoxLayout,
    QLabel,
    QLineEdit,
    QMainWindow,
    QPushButton,
    QScrollArea,
    QTabWidget,
    QVBoxLayout,
    QWidget,
)

from mm_pc.core.odometry import METHODS
from mm_pc.monitor.context import MonitorContext
from mm_pc.monitor.ros_bridge import validate_rate

__all__ = ["FRAME_HZ", "MainWindow"]

FRAME_HZ = 30.0

STATE_TEXT = {
    "waiting": ("waiting for {beagle}", "#a66f00"),
    "connected": ("connected to {beagle}", "#1b7a1b"),
    "lost": ("lost {beagle} (retrying)", "#b00020"),
    "offline": ("offline (no node)", "#555555"),
    "replay": ("REPLAY {name}", "#6a1b9a"),
}


class RateEditor(QWidget):
    """The sample rate field: 1..500 Hz; 0 or junk is refused with a message beside it."""

    def __init__(self, ctx: MonitorContext, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.ctx = ctx
        self.edit = QLineEdit(f"{ctx.config.rate_hz:g}")
        self.edit.setToolTip("requests per second to the Beagle node, 1..500 Hz (Enter applies)")
        self.edit.setMaximumWidth(70)
        self.edit.returnPressed.connect(self.apply)
        self.error = QLabel("")
        self.error.setStyleSheet("color: #b00020")
        self.error.setWordWrap(True)
        row = QHBoxLayout()
        row.setContentsMargins(0, 0, 0, 0)
        row.addWidget(self.edit)
        row.addWidget(QLabel("Hz"))
        row.addStretch(1)
        lay = QVBoxLayout(self)
        lay.setContentsMargins(0, 0, 0, 0)
        lay.addLayout(row)
        lay.addWidget(self.error)
        self.error.hide()

    def apply(self) -> bool:
        """Apply the typed rate; False (rate unchanged, error shown) when it is refused."""
        try:
            hz = validate_rate(self.edit.text().strip())
        except ValueError as e:
            self.error.setText(str(e))
            self.error.show()
            return False
        self.error.hide()
        self.ctx.config.rate_hz = hz
        if self.ctx.bridge is not None:
            self.ctx.bridge.set_rate(hz)
        self.ctx.status_message.emit(f"sample rate {hz:g} Hz")
        return True


class MainWindow(QMainWindow):
    """Mouse Monitor main window."""

    def __init__(self, ctx: MonitorContext) -> None:
        super().__init__()
        self.ctx = ctx
        self.setWindowTitle(f"Mouse Monitor — {ctx.config.beagle}")
        self.resize(1280, 800)
        self.frame_ms: deque[float] = deque(maxlen=100_000)
        self.views: dict[str, QWidget] = {}
        self.tabs = QTabWidget()
        self.setCentralWidget(self.tabs)
        self._build_views()
        self._build_control_dock()
        self._build_direction_dock()
        self._build_menu()
        self._build_status_bar()
        ctx.status_message.connect(lambda m: self.statusBar().showMessage(m, 5000))
        if ctx.bridge is not None:
            ctx.bridge.data_received.connect(ctx.on_reply)
            ctx.bridge.connection_changed.connect(self._on_state)
            ctx.bridge.stats_updated.connect(self._on_stats)
            ctx.bridge.data_failed.connect(self._on_data_failed)
            ctx.bridge.polling_changed.connect(self._on_polling_changed)
            self._on_state(ctx.bridge.state)
        else:
            self._on_state("offline")
        self.frame_timer = QTimer(self)
        self.frame_timer.setInterval(int(1000 / FRAME_HZ))
        self.frame_timer.timeout.connect(self.frame)
        self.frame_timer.start()

    # -- construction -------------------------------------------------------------------

    def _build_views(self) -> None:
        from mm_pc.monitor.widgets.data_list import DataListView
        from mm_pc.monitor.widgets.debug_view import DebugView
        from mm_pc.monitor.widgets.graphs_view import GraphsView
        from mm_pc.monitor.widgets.health_view import HealthView
        from mm_pc.monitor.widgets.map_view import MapView
        from mm_pc.monitor.widgets.maps_view import MapsView
        from mm_pc.monitor.widgets.registers_view import RegistersView

        for title, cls in (
            ("Map", MapView),
            ("Graphs", GraphsView),
            ("Data", DataListView),
            ("Registers", RegistersView),
            ("Debug", DebugView),
            ("Health", HealthView),
            ("Maps", MapsView),
        ):
            view = cls(self.ctx, self)
            self.views[title] = view
            self.tabs.addTab(view, title)

    def _build_control_dock(self) -> None:
        from mm_pc.monitor.widgets.resolution_panel import ResolutionPanel

        panel = QWidget()
        lay = QVBoxLayout(panel)

        link = QGroupBox("Sampling")
        form = QFormLayout(link)
        self.rate_editor = RateEditor(self.ctx)
        form.addRow("Sample rate", self.rate_editor)
        self.pause_button = QPushButton("Pause polling")
        self.pause_button.setCheckable(True)
        self.pause_button.toggled.connect(self.set_paused)
        self.pause_button.setEnabled(self.ctx.bridge is not None)
        form.addRow(self.pause_button)
        reset = QPushButton("Reset path and values")
        reset.clicked.connect(self.ctx.reset)
        form.addRow(reset)
        lay.addWidget(link)

        pose = QGroupBox("Pose")
        pform = QFormLayout(pose)
        self.method_box = QComboBox()
        self.method_box.addItems(sorted(METHODS))
        self.method_box.setCurrentText(self.ctx.session.method)
        self.method_box.setToolTip(
            "exact: one sensor, no slip (default); two-sensor: least squares with residual; "
            "seed-approach1/2: the original's formulas, to compare"
        )
        self.method_box.currentTextChanged.connect(self.set_method)
        pform.addRow("Method", self.method_box)
        self.method_error = QLabel("")
        self.method_error.setStyleSheet("color: #b00020")
        self.method_error.setWordWrap(True)
        self.method_error.hide()
        pform.addRow(self.method_error)
        from mm_pc.monitor.widgets.calibration_panel import CalibrationPanel

        self.calibration_panel = CalibrationPanel(self.ctx, self)
        pform.addRow(self.calibration_panel)
        for text, slot in (
            ("Calibration wizard…", self.open_calibration_wizard),
            ("Median filters…", self.open_filter_dialog),
            ("Robot geometry…", self.open_geometry_dialog),
            ("Log…", self.open_log_dialog),
        ):
            b = QPushButton(text)
            b.clicked.connect(slot)
            pform.addRow(b)
        lay.addWidget(pose)

        self.resolution_panel = ResolutionPanel(self.ctx, self)
        lay.addWidget(self.resolution_panel)
        lay.addStretch(1)
        scroll = QScrollArea()
        scroll.setWidgetResizable(True)
        scroll.setWidget(panel)
        # wide enough for the CPI rows with their read-back (no horizontal scroll bar)
        scroll.setMinimumWidth(310)
        scroll.setHorizontalScrollBarPolicy(Qt.ScrollBarAlwaysOff)
        dock = QDockWidget("Control", self)
        dock.setObjectName("control_dock")
        dock.setWidget(scroll)
        dock.setFeatures(QDockWidget.DockWidgetMovable | QDockWidget.DockWidgetFloatable)
        self.addDockWidget(Qt.LeftDockWidgetArea, dock)

    def _build_direction_dock(self) -> None:
        from mm_pc.monitor.widgets.direction_widget import DirectionPanel

        self.direction_panel = DirectionPanel(self.ctx, self)
        dock = QDockWidget("Direction", self)
        dock.setObjectName("direction_dock")
        dock.setWidget(self.direction_panel)
        self.addDockWidget(Qt.RightDockWidgetArea, dock)

    def _build_menu(self) -> None:
        file_menu = self.menuBar().addMenu("&File")
        self.record_action = QAction("&Record…", self)
        self.record_action.setShortcut(QKeySequence("Ctrl+R"))
        self.record_action.triggered.connect(self.toggle_recording)
        file_menu.addAction(self.record_action)
        replay = QAction("Re&play…", self)
        replay.setToolTip("replay a recording (MCAP file or rosbag2 folder) as a mode of its own")
        replay.triggered.connect(self.open_replay)
        file_menu.addAction(replay)
        self.stop_replay_action = QAction("S&top replay", self)
        self.stop_replay_action.setEnabled(False)  # only while a replay runs or is paused
        self.stop_replay_action.triggered.connect(self.stop_replay)
        file_menu.addAction(self.stop_replay_action)
        self.live_action = QAction("Back to &live (new path)", self)
        self.live_action.setEnabled(False)  # only in replay mode
        self.live_action.triggered.connect(self.leave_replay)
        file_menu.addAction(self.live_action)
        export = QAction("&Export view as PNG…", self)
        export.setShortcut(QKeySequence("Ctrl+E"))
        export.triggered.connect(self.export_png)
        file_menu.addAction(export)
        file_menu.addSeparator()
        quit_action = QAction("&Quit", self)
        quit_action.setShortcut(QKeySequence.Quit)
        quit_action.triggered.connect(self.close)
        file_menu.addAction(quit_action)

    def _build_status_bar(self) -> None:
        self.state_label = QLabel()
        self.rtt_label = QLabel("RTT –")
        self.rate_label = QLabel("– Hz")
        self.rows_label = QLabel("")
        for w in (self.state_label, self.rtt_label, self.rate_label, self.rows_label):
            self.statusBar().addPermanentWidget(w)

    # -- periodic ---------------------------------------------------------------------------

    def frame(self) -> None:
        """Redraw the visible views (each does nothing when its data did not change)."""
        t0 = time.perf_counter()
        current = self.tabs.currentWidget()
        if current is not None and hasattr(current, "refresh"):
            current.refresh()
        self.direction_panel.refresh()
        hist = self.ctx.session.history
        if hist is not None:
            self.rows_label.setText(f"{len(hist)} samples")
        self.frame_ms.append((time.perf_counter() - t0) * 1e3)

    def _on_state(self, state: str) -> None:
        bar = getattr(self, "replay_bar", None)
        if state != "replay":
            self.link_state = state
            if bar is not None and bar.active:
                return  # replay mode: the link state shows again when it is left
        text, colour = STATE_TEXT.get(state, (state, "#000000"))
        name = bar.name if bar is not None else ""
        self.state_label.setText(text.format(beagle=self.ctx.config.beagle, name=name))
        self.state_label.setStyleSheet(f"color: {colour}; font-weight: bold")
        for label in (self.rtt_label, self.rate_label):  # the link's figures: not the replay's
            label.setVisible(state != "replay")

    def _on_stats(self, stats) -> None:
        if stats.rtt_p50_s == stats.rtt_p50_s:  # not NaN
            self.rtt_label.setText(f"RTT {stats.rtt_p50_s * 1e3:.1f} ms")
        self.rate_label.setText(f"{stats.rate_hz:.1f} Hz")

    def _on_data_failed(self, message: str) -> None:
        self.statusBar().showMessage(f"data request: {message}", 3000)

    # -- actions ------------------------------------------------------------------------------

    def _on_polling_changed(self, polling: bool) -> None:
        """Keep the pause button in step when another view (Debug) pauses polling."""
        self.pause_button.blockSignals(True)
        self.pause_button.setChecked(not polling)
        self.pause_button.blockSignals(False)
        self.pause_button.setText("Pause polling" if polling else "Resume polling")

    def set_paused(self, paused: bool) -> None:
        if self.ctx.bridge is not None:
            self.ctx.bridge.set_polling(not paused)
        self.pause_button.setText("Resume polling" if paused else "Pause polling")

    def set_method(self, method: str) -> None:
        try:
            self.ctx.session.configure_odometry(method=method)
        except ValueError as e:
            self.method_error.setText(str(e))
            self.method_error.show()
            self.method_box.blockSignals(True)
            self.method_box.setCurrentText(self.ctx.session.method)
            self.method_box.blockSignals(False)
            return
        self.method_error.hide()
        self.ctx.odometry_changed.emit()

    @staticmethod
    def _open_dialog(dialog) -> None:
        """Open window-modal; the dialog is deleted when closed (no stale connections)."""
        dialog.setAttribute(Qt.WA_DeleteOnClose)
        dialog.open()

    def open_calibration_wizard(self) -> None:
        from mm_pc.monitor.widgets.calibration_wizard import CalibrationWizard

        self._open_dialog(CalibrationWizard(self.ctx, self))

    def open_filter_dialog(self) -> None:
        from mm_pc.monitor.widgets.filter_dialog import FilterDialog

        self._open_dialog(FilterDialog(self.ctx, self))

    def open_geometry_dialog(self) -> None:
        from mm_pc.monitor.widgets.geometry_dialog import GeometryDialog

        self._open_dialog(GeometryDialog(self.ctx, self))

    def open_log_dialog(self) -> None:
        from mm_pc.monitor.widgets.log_dialog import LogDialog

        dialog = LogDialog(self.ctx, self)
        dialog.setAttribute(Qt.WA_DeleteOnClose)
        dialog.show()

    def toggle_recording(self) -> None:
        from mm_pc.monitor.recording import toggle_recording

        toggle_recording(self)

    def open_replay(self) -> None:
        from mm_pc.monitor.replay import open_replay

        open_replay(self)

    def stop_replay(self) -> None:
        """Stop a running or paused replay; its path stays, live data waits for Back to live."""
        bar = getattr(self, "replay_bar", None)
        if bar is None or not bar.replaying:
            self.statusBar().showMessage("no replay is running", 3000)
            return
        bar.stop()
        self.statusBar().showMessage(
            "replay stopped; File > Back to live starts a new path for the live data", 5000
        )

    def leave_replay(self) -> None:
        """Leave replay mode: live data starts a new path (see replay.leave_replay)."""
        from mm_pc.monitor.replay import leave_replay

        leave_replay(self)

    def export_png(self) -> None:
        from mm_pc.monitor.export import export_current_view

        export_current_view(self)

    def closeEvent(self, event) -> None:  # noqa: N802 - Qt API
        self.frame_timer.stop()
        if self.ctx.recorder is not None:
            self.ctx.recorder.close()
            self.ctx.recorder = None
        super().closeEvent(event)
