"""The replay bar: replay as a mode of its own, shown only while a recording is on screen.

``REPLAY run.mcap 12.0/16.4 s`` (recorded seconds: the last fed reply's time
from the recording's first reply / the recording's length), a progress bar over
the recorded time that seeks (click or drag it to a time; focused, the arrow keys
go 5 s back or on, Home and End to the start and the end; after the end too, which
takes the replay up again, paused), Pause/Resume, the
speed (1x .. max, changeable while it runs) and Stop. When the replay has ended
or was stopped, the replayed path stays on screen and live data keeps waiting:
**Back to live** starts a new path for the live data (with no node: **Close**,
the path stays). The bar is a tool bar of the main window that can shrink (its
overflow goes into the tool bar's extension menu), so it never widens the window.
"""

from __future__ import annotations

from PySide6.QtCore import Qt, QTimer, Signal
from PySide6.QtWidgets import QComboBox, QLabel, QProgressBar, QPushButton, QToolBar

__all__ = ["ReplayBar", "SeekBar", "replay_text"]

#: label refresh while a replay runs (ms); the replayer itself feeds at its own pace
UPDATE_MS = 100
#: steps of the progress bar
STEPS = 1000


def replay_text(name: str, played_s: float, total_s: float, state: str = "") -> str:
    """``REPLAY run.mcap 12.0/16.4 s`` (+ `` paused`` / `` ended`` / `` stopped``)."""
    text = f"REPLAY {name} {played_s:.1f}/{total_s:.1f} s"
    return f"{text} {state}" if state else text


#: a Left/Right key moves the replay this far (recorded s)
KEY_STEP_S = 5.0


class SeekBar(QProgressBar):
    """The replay's progress that seeks: ``seek_to(fraction)`` (0..1 of the recording) on a
    click and at the end of a drag (while dragging, ``dragging(fraction)`` only: a seek
    backwards replays from the start); ``step(seconds)`` for the arrow keys, Home, End."""

    seek_to = Signal(float)
    dragging = Signal(float)
    step = Signal(float)

    def __init__(self, parent=None) -> None:
        super().__init__(parent)
        self.setFocusPolicy(Qt.FocusPolicy.StrongFocus)
        self.setCursor(Qt.CursorShape.PointingHandCursor)
        self._drag = False

    def fraction_at(self, x: float) -> float:
        return min(max(x / max(self.width(), 1), 0.0), 1.0)

    def mousePressEvent(self, ev) -> None:  # noqa: N802 - Qt API
        if ev.button() != Qt.MouseButton.LeftButton:
            return super().mousePressEvent(ev)
        self._drag = True
        self.setFocus()
        f = self.fraction_at(ev.position().x())
        self.setValue(round(f * self.maximum()))
        self.dragging.emit(f)
        ev.accept()

    def mouseMoveEvent(self, ev) -> None:  # noqa: N802 - Qt API
        if self._drag:
            f = self.fraction_at(ev.position().x())
            self.setValue(round(f * self.maximum()))
            self.dragging.emit(f)
        ev.accept()

    def mouseReleaseEvent(self, ev) -> None:  # noqa: N802 - Qt API
        if self._drag and ev.button() == Qt.MouseButton.LeftButton:
            self._drag = False
            self.seek_to.emit(self.fraction_at(ev.position().x()))
        ev.accept()

    def keyPressEvent(self, ev) -> None:  # noqa: N802 - Qt API
        key = ev.key()
        if key in (Qt.Key.Key_Left, Qt.Key.Key_Right):
            self.step.emit(KEY_STEP_S if key == Qt.Key.Key_Right else -KEY_STEP_S)
        elif key == Qt.Key.Key_Home:
            self.seek_to.emit(0.0)
        elif key == Qt.Key.Key_End:
            self.seek_to.emit(1.0)
        else:
            return super().keyPressEvent(ev)
        ev.accept()


LABEL_TIP = ("recorded seconds replayed / length of the recording; live data is not shown "
             "until you go back to live")


class ReplayBar(QToolBar):
    """The window's replay controls; :meth:`attach` a Replayer, :meth:`leave` to go live.

    ``active`` is True from :meth:`attach` until :meth:`leave`; the bar is
    visible exactly then (a restored window state cannot show it empty).
    ``left`` is emitted by :meth:`leave` (the window goes back to its link state).
    """

    left = Signal()
    speed_changed = Signal(float)

    def __init__(self, parent=None) -> None:
        super().__init__("Replay", parent)
        self.setObjectName("replay_bar")
        self.setMovable(False)
        self.toggleViewAction().setVisible(False)  # not in the dock/tool bar menu: a mode
        self.active = False
        self.replayer = None
        self.name = ""
        self.has_live = False
        self.label = QLabel("")
        self.label.setStyleSheet("color: #6a1b9a; font-weight: bold")
        self.label.setToolTip(LABEL_TIP)
        self.progress = SeekBar()
        self.progress.setToolTip("click or drag to a time of the recording; focused: Left/Right "
                                 f"{KEY_STEP_S:g} s back/on, Home/End start/end")
        self.progress.setRange(0, STEPS)
        self.progress.setTextVisible(False)
        self.progress.setMinimumWidth(60)
        self.progress.setMaximumWidth(240)
        self.pause_button = QPushButton("Pause")
        self.pause_button.setToolTip("pause the replay; Resume carries on where it stopped")
        self.pause_button.clicked.connect(self.toggle_pause)
        self.speed_box = QComboBox()
        self.speed_box.setToolTip(
            "replay speed: times the recorded pace; max = as fast as the window allows"
        )
        self.stop_button = QPushButton("Stop")
        self.stop_button.setToolTip("end the replay here; its path stays on screen")
        self.stop_button.clicked.connect(self.stop)
        self.live_button = QPushButton("Back to live")
        self.live_button.setToolTip(
            "leave the replay: the live data starts a new path (the replayed one is cleared)"
        )
        self.live_button.clicked.connect(self.leave)
        for w in (self.label, self.progress, self.pause_button, self.speed_box,
                  self.stop_button, self.live_button):  # fmt: skip
            self.addWidget(w)
        self.timer = QTimer(self)
        self.timer.setInterval(UPDATE_MS)
        self.timer.timeout.connect(self.update_view)
        self.speed_box.activated.connect(self._speed_chosen)
        self.progress.seek_to.connect(self._seek_fraction)
        self.progress.dragging.connect(self._show_drag)
        self.progress.step.connect(self._step)

    def setVisible(self, visible: bool) -> None:  # noqa: N802 - Qt API
        super().setVisible(bool(visible) and self.active)

    # -- mode ---------------------------------------------------------------------------------

    def attach(
        self, replayer, name: str, has_live: bool, speeds: tuple[str, ...], current: str
    ) -> None:
        """Show ``replayer`` (running) as the replay of ``name``; ``has_live``: a node to go
        back to (the last button reads Back to live, else Close); ``speeds``: the choices
        (``"2x"``, ``"max"``), ``current`` the one in force. (The replay module passes them:
        a widget never imports the recording code, which needs ROS message types.)"""
        self.replayer = replayer
        self.name = name
        self.has_live = has_live
        self.active = True
        self.speed_box.blockSignals(True)
        self.speed_box.clear()
        self.speed_box.addItems(list(speeds))
        if current not in speeds:  # e.g. 3x from the command line
            self.speed_box.addItem(current)
        self.speed_box.setCurrentText(current)
        self.speed_box.blockSignals(False)
        self.live_button.setText("Back to live" if has_live else "Close")
        total = getattr(replayer, "total_s", 0.0)
        widest = replay_text(name, total, total, "stopped")  # the label never jumps while it runs
        self.label.setMinimumWidth(min(self.label.fontMetrics().horizontalAdvance(widest) + 8, 360))
        self.label.setToolTip(f"{name}\n{LABEL_TIP}")
        replayer.finished.connect(self.update_view)
        self.show()
        self.timer.start()
        self.update_view()

    @property
    def replaying(self) -> bool:
        """A replay runs or is paused (not ended or stopped)."""
        return self.active and self.replayer is not None and not self.replayer.done

    def state(self) -> str:
        r = self.replayer
        if r is None or not self.active:
            return ""
        if r.done:
            return "ended" if r.position >= len(r.replies) else "stopped"
        if getattr(r, "seeking", False):
            return "seeking"
        return "" if r.running else "paused"

    def update_view(self) -> None:
        """Label, progress and buttons from the replayer's position."""
        r = self.replayer
        if r is None or not self.active or self.progress._drag:
            return
        played, total = r.played_s, r.total_s
        self._say(replay_text(self.name, played, total, self.state()))
        self.progress.setValue(int(STEPS * played / total) if total > 0 else STEPS * r.done)
        running = not r.done
        self.pause_button.setEnabled(running)
        self.pause_button.setText("Pause" if r.running or r.done else "Resume")
        self.speed_box.setEnabled(running)
        self.stop_button.setEnabled(running)
        self.live_button.setVisible(not running)
        if r.done:
            self.timer.stop()

    # -- controls -----------------------------------------------------------------------------

    def toggle_pause(self) -> None:
        r = self.replayer
        if r is None or r.done:
            return
        if r.running:
            r.pause()
        else:
            r.start()
        self.update_view()

    def seek(self, seconds: float) -> None:
        """Go to recorded time ``seconds`` (a replay that ended or was stopped is taken
        up again, paused there)."""
        if not self.active or self.replayer is None:
            return
        self.replayer.seek(seconds)
        if not self.timer.isActive():
            self.timer.start()
        self.update_view()

    def _seek_fraction(self, fraction: float) -> None:
        if self.replayer is not None:
            self.seek(fraction * self.replayer.total_s)

    def _step(self, seconds: float) -> None:
        if self.replayer is not None:
            self.seek(self.replayer.played_s + seconds)

    def _show_drag(self, fraction: float) -> None:
        r = self.replayer
        if r is not None and self.active:
            self._say(replay_text(self.name, fraction * r.total_s, r.total_s, "seek"))

    def _say(self, text: str) -> None:
        """The label's text, a long file name elided in the middle to the label's room
        (the whole name is in the tooltip): at 800 px the name was cut off."""
        room = self.label.minimumWidth() - 8
        fm = self.label.fontMetrics()
        if room > 0 and fm.horizontalAdvance(text) > room and self.name in text:
            rest = fm.horizontalAdvance(text.replace(self.name, ""))
            text = text.replace(self.name, fm.elidedText(self.name, Qt.ElideMiddle,
                                                          max(room - rest, 40)))
        self.label.setText(text)

    def _speed_chosen(self, _index: int) -> None:
        self.set_speed(self.speed_box.currentText())

    def set_speed(self, speed) -> None:
        """Change the speed of the running replay (its position is kept)."""
        if self.replayer is None or self.replayer.done:
            return
        self.replayer.set_speed(speed)
        self.speed_changed.emit(self.replayer.speed)
        self.update_view()

    def stop(self) -> None:
        """End the replay at its position (the path stays; the mode stays until leave)."""
        if self.replaying:
            self.replayer.stop()
        self.update_view()

    def leave(self) -> None:
        """Leave replay mode (stopping a replay still running); the window goes live."""
        if not self.active:
            return
        if self.replaying:
            self.replayer.stop()
        self.timer.stop()
        self.active = False
        self.hide()
        self.left.emit()

