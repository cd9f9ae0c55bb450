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

A :class:`~.replayer.Replayer` then feeds ``ctx.on_reply`` on a Qt timer, at the pace
of the readings' stamps times ``speed`` (``math.inf`` = as fast as the GUI allows, in
batches of ~20 ms so the window stays responsive); it seeks, backwards from keyframes
(:mod:`.replay_keyframes`). The file is read by :mod:`.replay_load`. When it ends or is
stopped the replayed path stays on screen and live data is *not* added to it:
the window stays in replay mode until **Back to live** (:func:`leave_replay`),
which starts a new path (times from 0 again) and reconnects a live bridge,
resuming its polling if it was polling before the replay.
"""

from __future__ import annotations

import logging
import math
import warnings
from pathlib import Path

from PySide6.QtCore import Qt
from PySide6.QtWidgets import QFileDialog, QMessageBox, QProgressBar

from mm_pc.core.sensor_data import Reply
from mm_pc.monitor.model.session import MonitorSession
from mm_pc.monitor.replay_load import SlicedRead, load_recording, load_recording_steps
from mm_pc.monitor.replayer import SEEK_AT_ONCE, Replayer, parse_speed, speed_name
from mm_pc.monitor.settings import last_folder, open_settings, remember_folder

__all__ = [
    "SEEK_AT_ONCE", "SPEEDS", "Replayer", "leave_replay", "load_in_background",
    "load_recording", "open_replay", "parse_speed", "pose_source", "speed_name",
    "start_replay",
]  # fmt: skip

log = logging.getLogger(__name__)

#: choices of the replay dialog
SPEEDS = ("1x", "2x", "5x", "10x", "max")


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
    replayer.on_restore = ctx.session_reset.emit  # the views draw the histories anew
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
    """Read the recording in slices on the GUI thread (:class:`~.replay_load.SlicedRead`),
    then start it; returns the read's :class:`concurrent.futures.Future`.

    An hour's recording takes tens of seconds to decode; the window stays
    responsive meanwhile (the status bar says the file is being read). A bad
    file is reported (see :func:`refuse`) and changes nothing.
    """
    path = Path(path)
    window.statusBar().showMessage(f"reading {path.name} …")
    busy = QProgressBar()  # a busy indicator while the file is read (it can take seconds)
    busy.setRange(0, 0)
    busy.setMaximumWidth(120)
    busy.setToolTip(f"reading and checking {path.name}")
    window.statusBar().addPermanentWidget(busy)
    window.replay_reading = busy

    def done(future) -> None:
        window.statusBar().removeWidget(busy)
        busy.deleteLater()
        window.replay_reading = None
        read.deleteLater()
        try:
            speed_, replies, warning = future.result()
        except ValueError as e:
            refuse(window, str(e), dialog)
            return
        begin_replay(window, path, replies, speed_, dialog, warning)

    read = SlicedRead(load_recording_steps(path, speed), done, parent=window)
    return read.future


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
