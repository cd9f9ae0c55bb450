"""Replay a recording into the monitor: a mode of its own, the same processing as live.

:func:`start_replay` / File > Replay read and check the whole file first (a bad
file changes nothing; the reason goes to a dialog, the status bar and the log:
logger ``mm_pc.monitor.replay``). A file cut short (a crash, a full disk) is replayed
up to its last whole message, with a warning saying how much was read (:func:`warn_cut`).
Nothing is asked before that; the speed is chosen on the replay bar
(:mod:`~.widgets.replay_bar`), also while it runs.
Entering replay mode prepares the window:

* a live bridge stops feeding the session: its polling is paused and its
  ``data_received`` is disconnected from the context (a reply still in
  flight must not land between recorded ones);
* the session is reset (path, graphs, pose back to the origin) and its
  baselines and time origin are forgotten, so the first recorded reply is a
  fresh baseline at t = 0 s: the Data list and CSV times run from 0 of the
  recording. When the recording names other sensors than the session, a new
  session with the same settings (method, mounts, calibration, filters, lift
  estimates) takes its place;
* the status bar's link state says ``REPLAY name`` (RTT and rate are hidden).

A :class:`Replayer` then feeds ``ctx.on_reply`` on a Qt timer, at the pace of
the readings' stamps times ``speed`` (``math.inf`` = as fast as the GUI allows,
in batches of ~20 ms so the window stays responsive). When it ends or is
stopped the replayed path stays on screen and live data is *not* added to it:
the window stays in replay mode until **Back to live** (:func:`leave_replay`),
which starts a new path (times from 0 again) and reconnects a live bridge,
resuming its polling if it was polling before the replay.
"""

from __future__ import annotations

import concurrent.futures
import logging
import math
import time
import warnings
from pathlib import Path

import numpy as np
from PySide6.QtCore import QObject, Qt, QTimer, Signal
from PySide6.QtWidgets import QFileDialog, QMessageBox, QProgressBar

from mm_pc.core.sensor_data import Reply
from mm_pc.monitor.io.mcap_reader import read_replies_up_to_cut
from mm_pc.monitor.model.session import MonitorSession
from mm_pc.monitor.settings import last_folder, open_settings, remember_folder

__all__ = [
    "SPEEDS", "Replayer", "leave_replay", "open_replay", "parse_speed", "pose_source",
    "speed_name", "start_replay",
]  # fmt: skip

log = logging.getLogger(__name__)

#: choices of the replay dialog
SPEEDS = ("1x", "2x", "5x", "10x", "max")
#: GUI time one timer tick may spend feeding replies (s)
BATCH_S = 0.02


def parse_speed(value) -> float:
    """``"2x"``, ``2``, ``"max"`` -> 2.0, 2.0, inf; ValueError unless > 0."""
    text = str(value).strip().lower()
    if text in ("max", "inf"):
        return math.inf
    try:
        speed = float(text.removesuffix("x"))
    except ValueError:
        raise ValueError(
            f"replay speed must be a positive factor (e.g. 1, 2x) or 'max', got {value!r}"
        ) from None
    if not speed > 0:  # also NaN
        raise ValueError(f"replay speed must be > 0 or 'max', got {value!r}")
    return speed


def speed_name(speed: float) -> str:
    """inf -> ``"max"``, 2.0 -> ``"2x"`` (the replay bar's names)."""
    return "max" if math.isinf(speed) else f"{speed:g}x"


def reply_times(replies: list[Reply]) -> np.ndarray:
    """Seconds from the first reply, from the readings' stamps (non-decreasing).

    A reply without readings takes its predecessor's time.
    """
    out = np.zeros(len(replies))
    t0 = last = None
    for i, r in enumerate(replies):
        if r.readings:
            t = r.readings[0].stamp_ns
            t0 = t if t0 is None else t0
            last = t if last is None else max(last, t)
        out[i] = 0.0 if last is None else (last - t0) / 1e9
    return out


#: replies fed together by a seek (the views are told once per chunk; ~130 us each)
SEEK_CHUNK = 100
#: a seek over at most this many replies is done at once (~65 ms), a longer one by the timer
SEEK_AT_ONCE = 500


class Replayer(QObject):
    """Feeds recorded replies to ``ctx.on_reply`` at ``speed`` times the recorded pace.

    ``finished`` is emitted once, when the last reply was fed or :meth:`stop`
    was called. ``on_end`` (optional) runs just before it.
    """

    finished = Signal()

    def __init__(self, ctx, replies: list[Reply], speed: float = 1.0, parent=None) -> None:
        super().__init__(parent)
        self.ctx = ctx
        self.replies = list(replies)
        self.speed = parse_speed(speed)
        self.times = reply_times(self.replies)
        self.position = 0
        self.on_end = None
        #: called before a seek backwards feeds the replies again from the first one: the
        #: session must start over (its path is integrated reply by reply)
        self.on_rewind = None
        #: called when a seek takes up a replay that had ended or was stopped
        self.on_reopen = None
        self._seek_to: int | None = None  # the reply index a seek feeds up to
        self._resume = False  # the replay ran when the seek began
        self._elapsed = 0.0  # recorded seconds already played before the last (re)start
        self._started: float | None = None
        self._done = False
        self.timer = QTimer(self)
        self.timer.setTimerType(Qt.PreciseTimer)
        self.timer.setInterval(0 if math.isinf(self.speed) else 5)
        self.timer.timeout.connect(self._tick)

    @property
    def running(self) -> bool:
        """Feeding at its pace (during a seek: whether it will once the seek is done)."""
        if self._seek_to is not None:
            return self._resume
        return self.timer.isActive()

    @property
    def done(self) -> bool:
        return self._done

    @property
    def total_s(self) -> float:
        """Length of the recording (s, from its first reply's stamps to its last)."""
        return float(self.times[-1]) if len(self.times) else 0.0

    @property
    def played_s(self) -> float:
        """Recorded time of the last reply fed (s from the first reply); 0 before any."""
        return float(self.times[self.position - 1]) if self.position else 0.0

    def set_speed(self, speed) -> None:
        """Go on at ``speed`` from the current position (running or paused); ValueError
        for a bad speed (nothing changes)."""
        new = parse_speed(speed)
        if self._seek_to is not None:  # the seek's target time stays; its end sets the timer
            self.speed = new
            return
        if math.isinf(self.speed):
            self._elapsed = self.played_s
        else:
            self._elapsed = self._played()
        self._started = time.perf_counter() if self._started is not None else None
        self.speed = new
        self.timer.setInterval(0 if math.isinf(new) else 5)

    def start(self) -> None:
        """Start, or resume after :meth:`pause`."""
        if self._done:
            return
        if self._seek_to is not None:
            self._resume = True  # once the seek is done
            return
        self._started = time.perf_counter()
        self.timer.start()

    def pause(self) -> None:
        if self._seek_to is not None:
            self._resume = False  # stays paused once the seek is done
            return
        if self.timer.isActive():
            self.timer.stop()
            self._elapsed = self._played()
            self._started = None

    def stop(self) -> None:
        """End now (the replies fed so far stay processed)."""
        self.timer.stop()
        self._finish()

    @property
    def seeking(self) -> bool:
        """A seek is feeding the replies up to its target (the window stays responsive)."""
        return self._seek_to is not None

    def seek(self, target_s: float) -> None:
        """Go to recorded time ``target_s`` (s from the first reply; clamped), running or
        paused as before. Forward, the replies up to it are fed; backward, the path starts
        over (:attr:`on_rewind`) and the replies up to it are fed again (the pose is
        integrated reply by reply: there is no other way back). Up to SEEK_AT_ONCE replies
        are fed at once; more are fed by the timer in slices of BATCH_S (a minute at
        500 Hz took ~4 s: the window would have frozen), :attr:`seeking` meanwhile.
        A replay that ended or was stopped is taken up again, paused (:attr:`on_reopen`)."""
        if not len(self.replies):
            return
        if self._done:
            self._done = False
            self._seek_to = None
            self._resume = False
            if self.on_reopen is not None:
                self.on_reopen()
        target = min(max(float(target_s), 0.0), self.total_s)
        i = int(np.searchsorted(self.times, target, side="right"))
        if self._seek_to is None:
            self._resume = self.running
        if i < self.position:
            if self.on_rewind is not None:
                self.on_rewind()
            self.position = 0
        self._elapsed = target
        self._started = None
        if i - self.position <= SEEK_AT_ONCE:
            self._feed_to(i, None)
            self._seek_to = None
            self._after_seek()
            return
        self._seek_to = i
        self.timer.setInterval(0)
        self.timer.start()

    def _feed_to(self, i: int, deadline: float | None) -> None:
        """Feed the replies up to index ``i`` (or until ``deadline``, perf_counter s)."""
        while self.position < i:
            end = min(self.position + SEEK_CHUNK, i)
            self.ctx.on_replies(self.replies[self.position:end])
            self.position = end
            if deadline is not None and time.perf_counter() > deadline:
                break

    def _after_seek(self) -> None:
        """Back to what the replay did before the seek (or the end reached)."""
        if self.position >= len(self.replies):
            self.timer.stop()
            self._finish()
            return
        self.timer.setInterval(0 if math.isinf(self.speed) else 5)
        if self._resume:
            self._started = time.perf_counter()
            self.timer.start()
        else:
            self.timer.stop()

    def _played(self) -> float:
        if math.isinf(self.speed):
            return math.inf if self._started is not None else self.played_s
        if self._started is None:
            return self._elapsed
        return self._elapsed + (time.perf_counter() - self._started) * self.speed

    def _tick(self) -> None:
        deadline = time.perf_counter() + BATCH_S
        if self._seek_to is not None:
            self._feed_to(self._seek_to, deadline)
            if self.position >= self._seek_to:
                self._seek_to = None
                self._after_seek()
            return
        target = self._played()
        n = len(self.replies)
        while self.position < n and self.times[self.position] <= target:
            self.ctx.on_reply(self.replies[self.position])
            self.position += 1
            if time.perf_counter() > deadline:
                break
        if self.position >= n:
            self.timer.stop()
            self._finish()

    def _finish(self) -> None:
        if self._done:
            return
        self._done = True
        if self.on_end is not None:
            self.on_end()
        self.finished.emit()


# -- session and bridge hand-over ---------------------------------------------------------------


def _session_like(old: MonitorSession) -> MonitorSession:
    new = MonitorSession(
        mounts=old.mounts,
        method=old.method,
        sensor=old.sensor,
        calibration=old.calibration,
        use_lift_estimates=old.use_lift_estimates,
        max_rows=old.max_rows,
        log_length=old.log.maxlen or 5000,
    )
    new.filters = dict(old.filters)
    for f in new.filters.values():
        f.reset()
    return new


def _prepare_session(ctx, devices: tuple[str, ...]) -> None:
    """Empty session for the recording: same sensors -> reset; others -> a new session."""
    if ctx.session.devices and tuple(ctx.session.devices) != devices:
        ctx.session = _session_like(ctx.session)
        ctx.session_reset.emit()
        return
    ctx.reset()
    ctx.session.forget_baselines(keep_t0=False)


def _detach_bridge(ctx) -> tuple[bool, bool]:
    """Pause and disconnect a live bridge; (was polling, was connected)."""
    bridge = ctx.bridge
    if bridge is None:
        return False, False
    polling = bridge.polling
    bridge.set_polling(False)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        try:
            connected = bool(bridge.data_received.disconnect(ctx.on_replies))
        except (RuntimeError, TypeError):
            connected = False
    return polling, connected


def _reattach_bridge(ctx, polling: bool, connected: bool) -> None:
    bridge = ctx.bridge
    if bridge is None:
        return
    if connected:
        bridge.data_received.connect(ctx.on_replies)
    if polling:
        bridge.set_polling(True)


def _new_live_path(ctx, devices_before: tuple[str, ...]) -> None:
    """A new path for the live data: times from 0 again, no delta against recorded totals.

    When the replay had put a session for other sensors in place (or the
    window had seen no live sensors yet), a session with the same settings that
    learns its sensors from the first live reply takes its place.
    """
    if devices_before and tuple(ctx.session.devices) == tuple(devices_before):
        ctx.reset()
        ctx.session.forget_baselines(keep_t0=False)
        return
    ctx.session = _session_like(ctx.session)
    ctx.session_reset.emit()


# -- the window's replay mode ---------------------------------------------------------------------


def pose_source(replies: list[Reply]) -> str:
    """How a replay makes the pose: from the recorded single polls, or per reply."""
    with_polls = sum(1 for r in replies if r.polls is not None)
    if with_polls == 0:
        return "pose per reply from the totals (the recording holds no single polls)"
    if with_polls == len(replies):
        return "pose per poll (the single polls are in the recording)"
    return (
        f"pose per poll for {with_polls} of {len(replies)} replies "
        "(the others have no single polls: per reply)"
    )


def load_recording(path: str | Path, speed=1.0) -> tuple[float, list, str]:
    """(speed, replies, warning) of a recording; ValueError saying what is wrong with either.

    A file cut short (a crash, a full disk) gives the replies of its whole messages and a
    warning saying how much was read; "" for a whole file."""
    speed = parse_speed(speed)
    replies, warning = read_replies_up_to_cut(Path(path))
    return speed, replies, warning


def warn_cut(window, warning: str, dialog: bool) -> None:
    """A recording cut short is replayed up to its last whole message: say so in the log and
    (with ``dialog``) a warning box (window-modal, not blocking; ``window.replay_warning``)."""
    log.warning("replay: %s", warning)
    if not dialog:
        return
    text = ("The recording is incomplete; it is replayed up to its last whole message."
            f"\n\n{warning}")
    box = QMessageBox(QMessageBox.Warning, "Replay", text, QMessageBox.Ok, window)
    box.setAttribute(Qt.WA_DeleteOnClose)
    window.replay_warning = box
    box.destroyed.connect(lambda *_: setattr(window, "replay_warning", None))
    box.open()


def refuse(window, message: str, dialog: bool) -> None:
    """A replay that cannot start: the reason in the status bar (``replay: ...``) and, with
    ``dialog`` (File > Replay), in a warning box (window-modal, not blocking;
    ``window.replay_error``) and the log (warning of logger ``mm_pc.monitor.replay``:
    stderr unless the application configures logging). Without ``dialog`` the caller
    reports it (``mm-monitor --replay`` prints one line and exits 2)."""
    window.statusBar().showMessage(f"replay: {message}", 15000)
    if not dialog:
        return
    log.warning("replay: %s", message)
    text = f"The recording cannot be replayed; nothing was changed.\n\n{message}"
    box = QMessageBox(QMessageBox.Warning, "Replay", text, QMessageBox.Ok, window)
    box.setAttribute(Qt.WA_DeleteOnClose)
    window.replay_error = box
    box.destroyed.connect(lambda *_: setattr(window, "replay_error", None))
    box.open()


def replay_bar(window):
    """The window's :class:`~.widgets.replay_bar.ReplayBar` (made at the first replay)."""
    bar = getattr(window, "replay_bar", None)
    if bar is None:
        from mm_pc.monitor.widgets.replay_bar import ReplayBar

        bar = ReplayBar(window)
        window.addToolBar(Qt.TopToolBarArea, bar)
        bar.left.connect(lambda: leave_replay(window))
        bar.speed_changed.connect(_remember_speed)
        window.replay_bar = bar
    return bar


def _remember_speed(speed: float) -> None:
    s = open_settings()
    s.setValue("replay/speed", speed_name(speed))
    s.sync()


def remembered_speed() -> float:
    """The speed last chosen on the replay bar (1x at first or when unreadable)."""
    try:
        return parse_speed(open_settings().value("replay/speed", "1x"))
    except ValueError:
        return 1.0


def _set_mode_controls(window, replaying: bool) -> None:
    """File > Stop replay enabled only while a replay runs or is paused, Back to live only
    in replay mode; Pause polling has no meaning in replay mode."""
    bar = getattr(window, "replay_bar", None)
    in_mode = bar is not None and bar.active
    for name, on in (("stop_replay_action", replaying), ("live_action", in_mode)):
        action = getattr(window, name, None)
        if action is not None:
            action.setEnabled(on)
    button = getattr(window, "pause_button", None)
    if button is not None:
        button.setEnabled(window.ctx.bridge is not None and not in_mode)


def _set_time_base(window, text: str, prefix: str) -> None:
    data = getattr(window, "views", {}).get("Data")
    if data is not None and hasattr(data, "set_time_base"):
        data.set_time_base(text, prefix)


def start_replay(window, path: str | Path, speed=1.0, dialog: bool = False) -> Replayer | None:
    """Replay ``path`` into ``window`` at ``speed`` (1.0 = recorded pace, ``"max"``/inf).

    Reads the file on the calling thread (the command line and tests);
    File > Replay reads it in the background instead (:func:`open_replay`).
    Returns the running :class:`Replayer`, or None when the file or the speed
    is bad: then the reason is in the status bar and the log (and a dialog with
    ``dialog``), and nothing changed.
    """
    try:
        speed, replies, warning = load_recording(path, speed)
    except ValueError as e:
        refuse(window, str(e), dialog)
        return None
    return begin_replay(window, Path(path), replies, speed, dialog, warning)


def begin_replay(
    window, path: Path, replies: list, speed: float, dialog: bool = False, warning: str = ""
) -> Replayer | None:
    """Enter replay mode with ``replies`` (read from ``path``); None (and why, see
    :func:`refuse`) if they cannot be shown. ``warning``: the file was cut short (see
    :func:`warn_cut`); it leads the status bar's messages of this replay."""
    devices = next((tuple(r.id for r in rep.readings) for rep in replies if rep.readings), ())
    if not devices:
        refuse(window, f"{path} holds no sensor readings", dialog)
        return None
    ctx = window.ctx
    try:
        MonitorSession(devices=devices, mounts=ctx.session.mounts)  # can the geometry take them?
    except ValueError as e:
        refuse(window, f"{path} cannot be shown: {e}", dialog)
        return None
    bar = replay_bar(window)
    old = getattr(window, "replayer", None)
    if old is not None and not old.done:
        old.stop()
    if not bar.active:  # from live: detach; from another replay: the live state is kept
        polling, connected = _detach_bridge(ctx)
        window.replay_live = (polling, connected, tuple(ctx.session.devices))
    _prepare_session(ctx, devices)
    replayer = Replayer(ctx, replies, speed, parent=window)

    cut = f"{warning}; " if warning else ""

    def ended() -> None:
        st = ctx.session.stats
        window.statusBar().showMessage(
            f"{cut}replay of {path.name} ended: {replayer.position} of {len(replies)} replies; "
            f"pose from {st.polls} single polls, {st.per_reply} replies per reply, "
            f"{st.gaps} gap(s); live data waits for Back to live",
            10000,
        )
        _set_mode_controls(window, False)

    def rewind() -> None:
        ctx.reset()
        ctx.session.forget_baselines(keep_t0=False)

    replayer.on_end = ended
    replayer.on_rewind = rewind
    replayer.on_reopen = lambda: _set_mode_controls(window, True)
    window.replayer = replayer
    bar.attach(replayer, path.name, ctx.bridge is not None, SPEEDS, speed_name(speed))
    window._on_state("replay")
    _set_mode_controls(window, True)
    _set_time_base(window, f"t: seconds from the first reply of the recording {path.name}",
                   path.stem)  # fmt: skip
    window.replay_cut_warning = warning
    if warning:
        warn_cut(window, warning, dialog)
    window.statusBar().showMessage(
        f"{cut}replaying {path.name}: {len(replies)} replies, {replayer.total_s:.1f} s at "
        f"{'max speed' if math.isinf(speed) else speed_name(speed)}; " + pose_source(replies)
    )
    replayer.start()
    return replayer


def leave_replay(window) -> None:
    """Leave replay mode: live data starts a new path; the bridge feeds and polls again."""
    bar = getattr(window, "replay_bar", None)
    if bar is not None and bar.active:
        bar.leave()  # emits left, which calls this again with the bar inactive
        return
    live = getattr(window, "replay_live", None)
    if live is None:
        return
    window.replay_live = None
    ctx = window.ctx
    polling, connected, devices_before = live
    if ctx.bridge is not None:
        _new_live_path(ctx, devices_before)
        _reattach_bridge(ctx, polling, connected)
        window.statusBar().showMessage("back to live: the live data starts a new path", 8000)
        _set_time_base(window, "t: seconds from the first live reply of this path", "")
    state = ctx.bridge.state if ctx.bridge is not None else "offline"
    window._on_state(getattr(window, "link_state", None) or state)
    _set_mode_controls(window, False)


def load_in_background(window, path: str | Path, speed, dialog: bool = True):
    """Read the recording on a worker thread, then start it on the GUI thread.

    An hour's recording takes tens of seconds to decode; the window stays
    responsive meanwhile (the status bar says the file is being read). A bad
    file is reported (see :func:`refuse`) and changes nothing.
    """
    path = Path(path)
    pool = concurrent.futures.ThreadPoolExecutor(1, thread_name_prefix="mm-replay-load")
    future = pool.submit(load_recording, path, speed)
    pool.shutdown(wait=False)
    window.statusBar().showMessage(f"reading {path.name} …")
    busy = QProgressBar()  # a busy indicator while the file is read (it can take seconds)
    busy.setRange(0, 0)
    busy.setMaximumWidth(120)
    busy.setToolTip(f"reading and checking {path.name}")
    window.statusBar().addPermanentWidget(busy)
    window.replay_reading = busy
    timer = QTimer(window)

    def check() -> None:
        if not future.done():
            return
        timer.stop()
        timer.deleteLater()
        window.statusBar().removeWidget(busy)
        busy.deleteLater()
        window.replay_reading = None
        try:
            speed_, replies, warning = future.result()
        except ValueError as e:
            refuse(window, str(e), dialog)
            return
        begin_replay(window, path, replies, speed_, dialog, warning)

    timer.timeout.connect(check)
    timer.start(100)
    return future


def open_replay(window) -> None:
    """File > Replay: choose a recording (an MCAP file, or a rosbag2 folder's metadata.yaml);
    it is read and checked in the background, then replayed at the speed last chosen on the
    replay bar (no other question)."""
    name, _ = QFileDialog.getOpenFileName(
        window, "Replay a recording", last_folder("recording"),
        "Recordings (*.mcap metadata.yaml);;MCAP recordings (*.mcap);;All files (*)",
    )  # fmt: skip
    if not name:
        return None
    remember_folder("recording", name)
    load_in_background(window, name, remembered_speed())
    return None
