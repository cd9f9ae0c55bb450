"""The monitor's main window: tabs of views, a control dock, the status bar.

It only wires things together: views get the shared
:class:`~.context.MonitorContext`; a frame timer asks the visible views to
redraw (each skips the work when nothing changed); the status bar shows the
link state, round-trip time and achieved sample rate from the bridge.
"""

from __future__ import annotations

import math
import time
from collections import deque

from PySide6.QtCore import QEvent, QObject, QSettings, Qt, QTimer
from PySide6.QtGui import QAction, QGuiApplication, QKeyEvent, QKeySequence
from PySide6.QtWidgets import (
    QApplication,
    QComboBox,
    QDialog,
    QDockWidget,
    QFormLayout,
    QGroupBox,
    QHBoxLayout,
    QLabel,
    QLineEdit,
    QMainWindow,
    QPushButton,
    QScrollArea,
    QStatusBar,
    QTabWidget,
    QVBoxLayout,
    QWidget,
)

from mm_pc.core.odometry import METHODS
from mm_pc.monitor.context import MonitorContext
from mm_pc.monitor.help import METHOD_LABELS, method_label, method_tooltip
from mm_pc.monitor.model.chips import chip_key, chip_title
from mm_pc.monitor.ros_bridge import validate_rate
from mm_pc.monitor.widgets.style import ERROR_STYLE

__all__ = ["ACHIEVED_OK", "DEFAULT_SIZE", "FRAME_HZ", "MainWindow", "RateEditor"]

FRAME_HZ = 30.0
#: the status bar's sample count is renewed at most this often (s)
ROWS_LABEL_PERIOD_S = 0.5
#: the Control dock's width (px); with the Direction dock and the tabs the window fits 1024 px
CONTROL_DOCK_WIDTH = 255
#: the window's size on a first start (clamped to the screen, title bar included)
DEFAULT_SIZE = (1280, 800)
#: the window manager's frame before the window is shown (left, top, right, bottom; px):
#: a title bar of about 30 px, thin borders
FRAME_GUESS = (4, 30, 4, 4)
#: narrower than this (px) the Direction dock goes under the Control dock (one column of
#: docks), so the map keeps most of the width
COMPACT_WIDTH = 960
#: below this share of the requested rate the achieved rate is shown in the warning colour
ACHIEVED_OK = 0.9
#: style of a figure that is below what was asked (orange: not an error, a warning)
WARNING_STYLE = "color: #b35900; font-weight: bold"
#: style of a figure that has no meaning now (paused, replaying): grey, not a warning
IDLE_STYLE = "color: #666666"
#: the status bar's RTT tooltip while it has a figure
RTT_TIP = "round-trip time of a data request, median of the last ones"

STATE_TEXT = {
    "waiting": ("waiting for {beagle}", "#a66f00"),
    "connected": ("connected to {beagle}", "#1b7a1b"),
    "lost": ("lost {beagle} (retrying)", "#b00020"),
    "offline": ("offline (no node)", "#555555"),
    "replay": ("REPLAY {name}", "#6a1b9a"),
}


class RateEditor(QWidget):
    """The sample rate field: 1..500 Hz; 0 or junk is refused with a message beside it.

    Under the field: the rate in force and the rate achieved (replies per second, from
    the bridge's stats), e.g. "now: 500 Hz (achieved 250 Hz)", in the warning colour
    when fewer than ``ACHIEVED_OK`` of the requests are answered in time.
    """

    def __init__(self, ctx: MonitorContext, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.ctx = ctx
        self.edit = QLineEdit(f"{ctx.config.rate_hz:g}")
        self.edit.setToolTip(
            "<p>How often the monitor asks the Beagle node for the sensors' sums, 1..500 "
            "requests per second (Enter applies). The pose uses every 1 kHz poll whatever "
            "the rate: a higher rate only makes the map and graphs move more often.</p>"
        )
        self.edit.setMaximumWidth(70)
        self.edit.returnPressed.connect(self.apply)
        self.error = QLabel("")
        self.error.setStyleSheet(ERROR_STYLE)
        self.error.setWordWrap(True)
        self.now = QLabel("")
        self.now.setWordWrap(True)
        self.now.setToolTip(
            "<p>The rate in force and the replies per second that actually arrived in the "
            "last 2 s; orange when fewer than 90 % arrive (a slow link or a busy PC).</p>"
        )
        row = QHBoxLayout()
        row.setContentsMargins(0, 0, 0, 0)
        row.addWidget(self.edit)
        row.addWidget(QLabel("Hz"))
        row.addStretch(1)
        lay = QVBoxLayout(self)
        lay.setContentsMargins(0, 0, 0, 0)
        lay.addLayout(row)
        lay.addWidget(self.now)
        lay.addWidget(self.error)
        self.error.hide()
        self.achieved_hz: float | None = None
        self.show_achieved(None)

    def apply(self) -> bool:
        """Apply the typed rate; False when it is refused: the error is shown and the field
        shows the rate still in force again."""
        typed = self.edit.text().strip()
        try:
            hz = validate_rate(typed)
        except ValueError as e:
            self.error.setText(f"{e}; still {self.ctx.config.rate_hz:g} Hz")
            self.error.show()
            self.edit.setText(f"{self.ctx.config.rate_hz:g}")
            return False
        self.error.hide()
        self.ctx.config.rate_hz = hz
        self.edit.setText(f"{hz:g}")
        if self.ctx.bridge is not None:
            self.ctx.bridge.set_rate(hz)
        self.ctx.status_message.emit(f"sample rate {hz:g} Hz")
        self.show_achieved(self.achieved_hz)
        return True

    def show_achieved(self, achieved_hz: float | None) -> bool:
        """Show the rate in force and ``achieved_hz`` (None: not known, e.g. offline).

        True when the achieved rate is below ``ACHIEVED_OK`` of the requested one (the
        warning colour is on).
        """
        self.achieved_hz = achieved_hz
        wanted = self.ctx.config.rate_hz
        state = self.ctx.data_state
        if state in ("paused", "replay", "lost"):  # no live rate to achieve: say why
            text, style = {
                "paused": (f"paused: no requests ({wanted:g} Hz when resumed)", IDLE_STYLE),
                "replay": (f"replaying a recording (live {wanted:g} Hz after Back to live)"
                           if self.ctx.bridge is not None else
                           "replaying a recording (offline: no node to poll after it)",
                           IDLE_STYLE),
                "lost": (f"{wanted:g} Hz asked; link lost, {self.ctx.no_data_since()}",
                         WARNING_STYLE),
            }[state]
            self.now.setText(text)
            self.now.setStyleSheet(style)
            self.achieved_hz = None  # a rate of these times is no figure for after them
            return False
        if achieved_hz is None:
            self.now.setText(f"now: {wanted:g} Hz")
            self.now.setStyleSheet("")
            return False
        low = achieved_hz < ACHIEVED_OK * wanted
        self.now.setText(f"now: {wanted:g} Hz (achieved {achieved_hz:.0f} Hz)")
        self.now.setStyleSheet(WARNING_STYLE if low else "")
        return low


def first_size(avail, frame=FRAME_GUESS) -> tuple[int, int]:
    """The inner size of a first start on a screen whose free area is ``avail`` (a QRect):
    DEFAULT_SIZE, or less so that the window with its ``frame`` (left, top, right, bottom)
    fits the free area."""
    left, top, right, bottom = frame
    return (min(DEFAULT_SIZE[0], avail.width() - left - right),
            min(DEFAULT_SIZE[1], avail.height() - top - bottom))


class ElidingStatusBar(QStatusBar):
    """A status bar whose message never runs off its edge: too long, it ends in "…" and
    the whole text is the tooltip; ``currentMessage()`` is the whole text."""

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self._full = ""
        self.messageChanged.connect(self._on_changed)

    def showMessage(self, message: str, timeout: int = 0) -> None:  # noqa: N802 - Qt API
        self._full = message
        super().showMessage(self._elided(message), timeout)
        self.setToolTip(message if message != self._elided(message) else "")

    def currentMessage(self) -> str:  # noqa: N802 - Qt API
        return self._full if super().currentMessage() else ""

    def message_room(self) -> int:
        """The width (px) left to the message beside the permanent widgets."""
        used = sum(w.width() + 4 for w in self.findChildren(QLabel)
                   if w.isVisible() and w.parentWidget() is self)
        return max(0, self.width() - used - 16)

    def _elided(self, message: str) -> str:
        return self.fontMetrics().elidedText(message, Qt.ElideRight, self.message_room())

    def _on_changed(self, shown: str) -> None:
        if not shown:  # timed out or cleared
            self._full = ""
            self.setToolTip("")

    def resizeEvent(self, event) -> None:  # noqa: N802 - Qt API
        super().resizeEvent(event)
        if self._full and super().currentMessage():
            text = self._elided(self._full)
            if text != super().currentMessage():
                self.blockSignals(True)
                super().showMessage(text)  # the timer keeps running: clearMessage ends it
                self.blockSignals(False)
                self.setToolTip(self._full if text != self._full else "")


class _DockScroll(QScrollArea):
    """A dock's scroll area: scrolls up and down, never sideways; as wide as its content
    needs with the vertical scroll bar shown (at least ``min_width``), so no text in it is
    cut when the content grows (a sensor's CPI row arrives with the first reply)."""

    def __init__(self, content: QWidget, min_width: int = 0) -> None:
        super().__init__()
        self.min_width = min_width
        self.setWidgetResizable(True)
        self.setWidget(content)
        self.setHorizontalScrollBarPolicy(Qt.ScrollBarAlwaysOff)
        content.installEventFilter(self)

    def minimumSizeHint(self):  # noqa: N802 - Qt API
        hint = super().minimumSizeHint()
        content = self.widget()
        if content is not None:
            need = (content.minimumSizeHint().width() + 2 * self.frameWidth()
                    + self.verticalScrollBar().sizeHint().width())
            hint.setWidth(max(self.min_width, need))
        return hint

    def eventFilter(self, obj, event) -> bool:  # noqa: N802 - Qt API
        if obj is self.widget() and event.type() == QEvent.LayoutRequest:
            self.updateGeometry()
        return super().eventFilter(obj, event)


class _ExportShortcut(QObject):
    """Lets the window's Ctrl+E through while a text field has the focus.

    A QLineEdit claims Ctrl+E (move to the end of the line, on X11) through a
    ShortcutOverride event, so the menu's shortcut would never fire there. The filter
    goes on each of the window's text fields as it takes the focus: one on the whole
    application would run Python for every event (a frame's paints, each reply).
    """

    def __init__(self, window: MainWindow) -> None:
        super().__init__(window)
        self._main = window

    def on_focus(self, _old, new) -> None:
        if isinstance(new, QLineEdit) and new.window() is self._main:
            new.installEventFilter(self)  # again for the same field: still one filter

    def eventFilter(self, obj, event) -> bool:  # noqa: N802 - Qt API
        if (
            event.type() == QEvent.ShortcutOverride
            and isinstance(event, QKeyEvent)
            and isinstance(obj, QLineEdit)
            and obj.window() is self._main
        ):
            keys = QKeySequence(event.keyCombination())
            if keys.matches(self._main.export_action.shortcut()) == QKeySequence.ExactMatch:
                event.ignore()  # not the field's: the shortcut map takes it
                return True
        return False


class MainWindow(QMainWindow):
    """Mouse Monitor main window."""

    def __init__(self, ctx: MonitorContext, settings: QSettings | None = None) -> None:
        """``settings``: where geometry, dock layout, tab, rate, method are remembered
        (``settings.open_settings()`` in mm-monitor); None remembers nothing (tests)."""
        super().__init__()
        self.ctx = ctx
        self.settings = settings
        self.setWindowTitle(f"Mouse Monitor — {ctx.config.beagle}")
        self.setStatusBar(ElidingStatusBar(self))
        self.resize(*self.default_size())
        self.compact = False
        self.frame_ms: deque[float] = deque(maxlen=100_000)
        self.views: dict[str, QWidget] = {}
        self.tabs = QTabWidget()
        self.setCentralWidget(self.tabs)
        self._build_views()
        self._build_control_dock()
        self._build_direction_dock()
        self._build_menu()
        self._build_status_bar()
        self._default_state = self.saveState()
        self._export_filter = _ExportShortcut(self)
        app = QApplication.instance()
        if app is not None:
            app.focusChanged.connect(self._export_filter.on_focus)
        ctx.status_message.connect(lambda m: self.statusBar().showMessage(m, 5000))
        if ctx.bridge is not None:
            ctx.bridge.data_received.connect(ctx.on_replies)
            ctx.bridge.connection_changed.connect(self._on_state)
            ctx.bridge.stats_updated.connect(self._on_stats)
            ctx.bridge.data_failed.connect(self._on_data_failed)
            ctx.bridge.polling_changed.connect(self._on_polling_changed)
            self._on_state(ctx.bridge.state)
        else:
            self._on_state("offline")
        self._refreshed_at: dict[int, float] = {}  # id(view) -> its last refresh (_due)
        self.frame_timer = QTimer(self)
        self.frame_timer.setInterval(int(1000 / FRAME_HZ))
        self.frame_timer.timeout.connect(self.frame)
        self.frame_timer.start()
        self.restore_layout()

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
            # a view wider or taller than the space left scrolls: it never widens the window
            scroll = QScrollArea()
            scroll.setWidgetResizable(True)
            scroll.setFrameShape(QScrollArea.NoFrame)
            scroll.setWidget(view)
            self.tabs.addTab(scroll, title)

    def current_view(self) -> QWidget | None:
        """The view of the tab shown (inside its scroll area)."""
        return self.views.get(self.tabs.tabText(self.tabs.currentIndex()))

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
        self.pause_button.setToolTip("stop (or resume) the periodic requests; the node keeps "
                                     "counting, nothing is lost")
        form.addRow(self.pause_button)
        reset = QPushButton("Reset path and values")
        reset.setToolTip("clear the paths, graphs and the pose (back to the origin); "
                         "counting goes on")
        reset.clicked.connect(self.ctx.reset)
        form.addRow(reset)
        lay.addWidget(link)

        pose = QGroupBox("Pose")
        pform = QFormLayout(pose)
        self.method_box = QComboBox()
        for key in METHOD_LABELS:
            if key in METHODS:
                self.method_box.addItem(method_label(key), key)
                self.method_box.setItemData(self.method_box.count() - 1, method_tooltip(key),
                                            Qt.ToolTipRole)
        self.method_box.setCurrentIndex(self.method_box.findData(self.ctx.session.method))
        self.method_box.setToolTip(method_tooltip())
        self.method_box.setSizeAdjustPolicy(QComboBox.AdjustToMinimumContentsLengthWithIcon)
        self.method_box.setMinimumContentsLength(12)
        self.method_box.currentIndexChanged.connect(
            lambda i: self.set_method(self.method_box.itemData(i))
        )
        # the box on a row of its own: the longest name ("Least squares, 2 sensors") fits
        pform.addRow(QLabel("Method"))
        pform.addRow(self.method_box)
        self.method_error = QLabel("")
        self.method_error.setStyleSheet(ERROR_STYLE)
        self.method_error.setWordWrap(True)
        self.method_error.hide()
        pform.addRow(self.method_error)
        from mm_pc.monitor.widgets.calibration_panel import CalibrationPanel

        self.calibration_panel = CalibrationPanel(self.ctx, self)
        pform.addRow(self.calibration_panel)
        for text, slot, tip in (
            ("Calibration wizard…", self.open_calibration_wizard,
             "fit every sensor's mounting angle, scales and position from a guided run"),
            ("Median filters…", self.open_filter_dialog,
             "per sensor and axis, a median filter over 1..999 samples"),
            ("Robot geometry…", self.open_geometry_dialog,
             "where the sensors sit on the robot, the axle length, the sensor in use"),
            ("Log…", self.open_log_dialog, "the raw and processed values of every reply"),
        ):
            b = QPushButton(text)
            b.setToolTip(tip)
            b.clicked.connect(slot)
            pform.addRow(b)
        lay.addWidget(pose)

        self.resolution_panel = ResolutionPanel(self.ctx, self)
        lay.addWidget(self.resolution_panel)
        lay.addStretch(1)
        # wide enough for the CPI rows (labels wrap; no horizontal scroll bar)
        scroll = _DockScroll(panel, CONTROL_DOCK_WIDTH)
        dock = QDockWidget("Control", self)
        dock.setObjectName("control_dock")
        dock.setWidget(scroll)
        self.control_dock = dock
        self.addDockWidget(Qt.LeftDockWidgetArea, dock)

    def _build_direction_dock(self) -> None:
        from mm_pc.monitor.widgets.direction_widget import DirectionPanel

        self.direction_panel = DirectionPanel(self.ctx, self)
        scroll = _DockScroll(self.direction_panel)
        dock = QDockWidget("Direction", self)
        dock.setObjectName("direction_dock")
        dock.setWidget(scroll)
        self.direction_dock = dock
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
        export.setShortcutContext(Qt.WindowShortcut)
        export.triggered.connect(self.export_png)
        file_menu.addAction(export)
        self.export_action = export
        file_menu.addSeparator()
        quit_action = QAction("&Quit", self)
        quit_action.setShortcut(QKeySequence.Quit)
        quit_action.triggered.connect(self.close)
        file_menu.addAction(quit_action)
        self.quit_action = quit_action

        view_menu = self.menuBar().addMenu("&View")
        for dock in (self.control_dock, self.direction_dock):
            view_menu.addAction(dock.toggleViewAction())
        view_menu.addSeparator()
        for i in range(self.tabs.count()):
            act = QAction(self.tabs.tabText(i), self)
            act.setShortcut(QKeySequence(f"Ctrl+{i + 1}"))
            act.triggered.connect(lambda _c=False, k=i: self.tabs.setCurrentIndex(k))
            view_menu.addAction(act)
        view_menu.addSeparator()
        self.reset_layout_action = QAction("&Reset layout", self)
        self.reset_layout_action.setToolTip("default window size, both docks back in place")
        self.reset_layout_action.triggered.connect(self.reset_layout)
        view_menu.addAction(self.reset_layout_action)

        help_menu = self.menuBar().addMenu("&Help")
        guide = QAction("&User guide", self)
        guide.setShortcut(QKeySequence.HelpContents)
        guide.triggered.connect(self.open_user_guide)
        help_menu.addAction(guide)
        keys = QAction("&Keyboard shortcuts", self)
        keys.triggered.connect(self.show_shortcuts)
        help_menu.addAction(keys)
        about = QAction("&About Mouse Monitor", self)
        about.triggered.connect(self.show_about)
        help_menu.addAction(about)

    def _build_status_bar(self) -> None:
        self.state_label = QLabel()
        self.rtt_label = QLabel("RTT –")
        self.rate_label = QLabel("– Hz")
        self.rows_label = QLabel("")
        self._rows_shown_at = -math.inf  # time.perf_counter() of its last text
        self.rtt_label.setToolTip(RTT_TIP)
        self.rate_label.setToolTip("replies per second achieved (the last 2 s)")
        self.chips_label = QLabel("")
        self._chips_shown: tuple = ()
        for w in (self.state_label, self.chips_label, self.rtt_label, self.rate_label,
                  self.rows_label):
            self.statusBar().addPermanentWidget(w)

    # -- periodic ---------------------------------------------------------------------------

    def frame(self) -> None:
        """Redraw the visible views (each does nothing when its data did not change)."""
        t0 = time.perf_counter()
        current = self.current_view()
        if current is not None and hasattr(current, "refresh") and self._due(current, t0):
            current.refresh()
        self.direction_panel.refresh()
        hist = self.ctx.session.history
        if hist is not None and t0 >= self._rows_shown_at + ROWS_LABEL_PERIOD_S:
            # a new text re-lays the status bar out and repaints all of it: not every frame
            self._rows_shown_at = t0
            self.rows_label.setText(f"{len(hist)} samples")
        self._show_chips()
        self.frame_ms.append((time.perf_counter() - t0) * 1e3)

    def _due(self, view, now: float) -> bool:
        """Whether ``view`` is refreshed in the frame at ``now`` (perf_counter s): a view with
        a ``refresh_period_s`` (the Data tables) at most that often, the others every frame."""
        period = getattr(view, "refresh_period_s", 0.0)
        if period <= 0.0:
            return True
        if now < self._refreshed_at.get(id(view), -math.inf) + period:
            return False
        self._refreshed_at[id(view)] = now
        return True

    def _show_chips(self) -> None:
        """The sensors' chips in the status bar ("PMW3360 + PMW3389"), each named in the
        tooltip; cheap when they did not change."""
        session = self.ctx.session
        shown = tuple((d, session.chip(d)) for d in session.devices)
        if shown == self._chips_shown:
            return
        self._chips_shown = shown
        self.chips_label.setText(" + ".join(chip_key(c).upper() for _d, c in shown))
        self.chips_label.setToolTip("sensor chips: " + "; ".join(
            f"{d}: {chip_title(c)}" + ("" if c else " (the node names none)")
            for d, c in shown))

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
        self._update_data_state(state == "replay")

    def _update_data_state(self, replaying: bool = False) -> None:
        """Tell the views where the values come from (live, lost, paused, replay, ...)."""
        bar = getattr(self, "replay_bar", None)
        bridge = self.ctx.bridge
        link = getattr(self, "link_state", "offline")
        if replaying or (bar is not None and bar.active):
            state = "replay"
        elif bridge is None:
            state = "offline"
        elif link == "lost":
            state = "lost"
        elif not getattr(bridge, "polling", True):
            state = "paused"
        else:
            state = "live" if link == "connected" else "waiting"
        self.ctx.set_data_state(state)
        self._show_rtt(getattr(self, "_rtt_s", math.nan))
        editor = getattr(self, "rate_editor", None)
        if editor is not None:
            editor.show_achieved(editor.achieved_hz)
            if state != "live":
                self.rate_label.setStyleSheet("")

    def _on_stats(self, stats) -> None:
        if stats.rtt_p50_s == stats.rtt_p50_s:  # not NaN
            self._rtt_s = stats.rtt_p50_s
        self._show_rtt(getattr(self, "_rtt_s", math.nan))
        self.rate_label.setText(f"{stats.rate_hz:.1f} Hz")
        low = self.rate_editor.show_achieved(stats.rate_hz if stats.replies else None)
        self.rate_label.setStyleSheet(WARNING_STYLE if low else "")

    def _show_rtt(self, rtt_s: float) -> None:
        """The median round trip (s) in the status bar; "RTT –" while the link is lost or
        polling paused: the bridge's median is of replies before then, no figure for now."""
        label = getattr(self, "rtt_label", None)
        if label is None:
            return
        if self.ctx.stale or rtt_s != rtt_s:
            why = {"lost": "the link is lost", "paused": "polling is paused"}.get(
                self.ctx.data_state, "no reply yet")
            label.setText("RTT –")
            label.setToolTip(f"round-trip time of a data request: none while {why} "
                             f"({self.ctx.no_data_since()})" if self.ctx.stale else RTT_TIP)
        else:
            label.setText(f"RTT {rtt_s * 1e3:.1f} ms")
            label.setToolTip(RTT_TIP)

    def _on_data_failed(self, message: str) -> None:
        self.statusBar().showMessage(f"data request: {message}", 3000)

    # -- actions ------------------------------------------------------------------------------

    def _on_polling_changed(self, polling: bool) -> None:
        """Keep the pause button in step when another view (Debug) pauses polling."""
        self.pause_button.blockSignals(True)
        self.pause_button.setChecked(not polling)
        self.pause_button.blockSignals(False)
        self.pause_button.setText("Pause polling" if polling else "Resume polling")
        self._update_data_state()

    def set_paused(self, paused: bool) -> None:
        if self.ctx.bridge is not None:
            self.ctx.bridge.set_polling(not paused)
        self.pause_button.setText("Resume polling" if paused else "Pause polling")

    def set_method(self, method: str) -> bool:
        """Use pose method ``method`` (a key of METHODS); False (message shown, the box
        back on the method in force) when the session refuses it."""
        try:
            self.ctx.session.configure_odometry(method=method)
        except ValueError as e:
            self.method_error.setText(str(e))
            self.method_error.show()
            self._show_method(self.ctx.session.method)
            return False
        self.method_error.hide()
        self._show_method(method)
        self.ctx.config.method = method
        self.ctx.odometry_changed.emit()
        return True

    def _show_method(self, method: str) -> None:
        self.method_box.blockSignals(True)
        self.method_box.setCurrentIndex(self.method_box.findData(method))
        self.method_box.blockSignals(False)

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

    # -- help -------------------------------------------------------------------------------

    def open_user_guide(self) -> bool:
        """Open docs/user-guide.md with the desktop's viewer; False (message) if it cannot."""
        from mm_pc.monitor.help import open_user_guide

        ok, message = open_user_guide()
        self.statusBar().showMessage(message, 8000)
        return ok

    def shortcuts_text(self) -> str:
        """The window's keyboard shortcuts, one "keys: what" per line (from the menus)."""
        lines = []
        for menu_action in self.menuBar().actions():
            for act in menu_action.menu().actions():
                keys = act.shortcut().toString(QKeySequence.NativeText)
                if keys:
                    lines.append(f"{keys}: {act.text().replace('&', '').rstrip('…')}")
        lines += ["Ctrl+C (Data tab): copy the selected rows", "Enter (a field): apply it"]
        return "\n".join(lines)

    def show_shortcuts(self):
        from PySide6.QtWidgets import QMessageBox

        box = QMessageBox(QMessageBox.Information, "Keyboard shortcuts", self.shortcuts_text(),
                          QMessageBox.Close, self)
        self._open_dialog(box)
        return box

    def show_about(self):
        from PySide6.QtWidgets import QMessageBox

        from mm_pc.monitor.help import about_text

        box = QMessageBox(QMessageBox.Information, "About Mouse Monitor",
                          about_text(self.ctx.config.beagle), QMessageBox.Close, self)
        self._open_dialog(box)
        return box

    # -- remembered layout and values ------------------------------------------------------------

    def default_size(self) -> tuple[int, int]:
        """DEFAULT_SIZE, or less so that the window with its title bar fits the screen."""
        screen = QGuiApplication.primaryScreen()
        if screen is None:
            return DEFAULT_SIZE
        return first_size(screen.availableGeometry())

    def screen_too_small(self) -> bool:
        """The screen's free area cannot hold DEFAULT_SIZE and a title bar."""
        return self.default_size() != DEFAULT_SIZE

    def resizeEvent(self, event) -> None:  # noqa: N802 - Qt API
        super().resizeEvent(event)
        self.set_compact(self.width() < COMPACT_WIDTH)

    def set_compact(self, compact: bool) -> None:
        """Compact (narrow window): the Direction dock goes under Control, so the docks
        take one column (both scroll); wide again, it goes back to the right."""
        if compact == self.compact:
            return
        self.compact = compact
        docked = [d for d in (self.control_dock, self.direction_dock) if not d.isFloating()]
        if len(docked) < 2:
            return  # a floating dock takes no room from the map
        if compact:
            self.splitDockWidget(self.control_dock, self.direction_dock, Qt.Vertical)
        else:
            self.addDockWidget(Qt.RightDockWidgetArea, self.direction_dock)

    def restore_layout(self) -> None:
        """Geometry, dock layout and tab from the settings (nothing without settings)."""
        s = self.settings
        if s is None:
            return
        geometry = s.value("window/geometry")
        if geometry is not None:
            self.restoreGeometry(geometry)
        elif self.screen_too_small():
            # first start on a small screen: the window manager fits it, title bar and all
            self.setWindowState(self.windowState() | Qt.WindowMaximized)
        state = s.value("window/state")
        if state is not None:
            self.restoreState(state)
        tab = s.value("window/tab", "")
        for i in range(self.tabs.count()):
            if self.tabs.tabText(i) == tab:
                self.tabs.setCurrentIndex(i)

    def save_settings(self) -> None:
        """Remember geometry, dock layout, tab, sample rate and pose method."""
        s = self.settings
        if s is None:
            return
        s.setValue("window/geometry", self.saveGeometry())
        s.setValue("window/state", self.saveState())
        s.setValue("window/tab", self.tabs.tabText(self.tabs.currentIndex()))
        s.setValue("sampling/rate_hz", float(self.ctx.config.rate_hz))
        s.setValue("pose/method", self.ctx.session.method)
        s.sync()

    def reset_layout(self) -> None:
        """Default size, both docks shown where they start, the Map tab; forgotten in the
        settings too (rate, method and folders stay)."""
        self.showNormal()
        self.restoreState(self._default_state)
        self.compact = False  # the default state: the docks side by side
        for dock in (self.control_dock, self.direction_dock):
            dock.setFloating(False)
            dock.show()
        self.resize(*self.default_size())
        self.set_compact(self.width() < COMPACT_WIDTH)
        self.tabs.setCurrentIndex(0)
        if self.settings is not None:
            self.settings.remove("window")
            self.settings.sync()
        self.statusBar().showMessage("layout reset", 3000)

    def closeEvent(self, event) -> None:  # noqa: N802 - Qt API
        self.frame_timer.stop()
        self.save_settings()
        if self.ctx.recorder is not None:
            self.ctx.recorder.close()
            self.ctx.recorder = None
        # its modeless windows (the log) close with it rather than stay on screen
        for child in self.findChildren(QDialog):
            if child.isWindow() and child.isVisible() and not child.isModal():
                child.close()
        super().closeEvent(event)
