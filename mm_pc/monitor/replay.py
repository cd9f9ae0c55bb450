"""Replay a recording into the monitor: the same processing as live, at 1x or faster.

:func:`start_replay` reads the whole file first (a bad file changes nothing),
then prepares the window:

* a live bridge stops feeding the session: its polling is paused and its
  ``data_received`` is disconnected from the context (a reply still in
  flight must not land between recorded ones);
* the session is reset (path, graphs, pose back to the origin) and its
  baselines are forgotten, so the first recorded reply is a fresh baseline
  and the map shows only the recording. When the recording names other
  sensors than the session, a new session with the same settings (method,
  mounts, calibration, filters, lift estimates) takes its place.

A :class:`Replayer` then feeds ``ctx.on_reply`` on a Qt timer, at the pace of
the readings' stamps times ``speed`` (``math.inf`` = as fast as the GUI allows,
in batches of ~20 ms so the window stays responsive). When it ends (or is
stopped), the baselines are forgotten again (the live node's totals are not
the recording's) and a live bridge is reconnected and resumes polling if it
was polling before; the replayed path stays on screen.
"""

from __future__ import annotations

import concurrent.futures
import math
import time
import warnings
from pathlib import Path

import numpy as np
from PySide6.QtCore import QObject, Qt, QTimer, Signal
from PySide6.QtWidgets import QFileDialog, QInputDialog

from mm_pc.monitor.model.readings import Reply
from mm_pc.monitor.model.session import MonitorSession
from mm_pc.monitor.recording import read_replies

__all__ = ["SPEEDS", "Replayer", "open_replay", "parse_speed", "pose_source", "start_replay"]

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
        self._elapsed = 0.0  # recorded seconds already played before the last (re)start
        self._started: float | None = None
        self._done = False
        self.timer = QTimer(self)
        self.timer.setTimerType(Qt.PreciseTimer)
        self.timer.setInterval(0 if math.isinf(self.speed) else 5)
        self.timer.timeout.connect(self._tick)

    @property
    def running(self) -> bool:
        return self.timer.isActive()

    @property
    def done(self) -> bool:
        return self._done

    def start(self) -> None:
        """Start, or resume after :meth:`pause`."""
        if self._done:
            return
        self._started = time.perf_counter()
        self.timer.start()

    def pause(self) -> None:
        if self.timer.isActive():
            self.timer.stop()
            self._elapsed = self._played()
            self._started = None

    def stop(self) -> None:
        """End now (the replies fed so far stay processed)."""
        self.timer.stop()
        self._finish()

    def _played(self) -> float:
        if math.isinf(self.speed):
            return math.inf
        if self._started is None:
            return self._elapsed
        return self._elapsed + (time.perf_counter() - self._started) * self.speed

    def _tick(self) -> None:
        deadline = time.perf_counter() + BATCH_S
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
            connected = bool(bridge.data_received.disconnect(ctx.on_reply))
        except (RuntimeError, TypeError):
            connected = False
    return polling, connected


def _reattach_bridge(ctx, polling: bool, connected: bool) -> None:
    bridge = ctx.bridge
    if bridge is None:
        return
    ctx.session.forget_baselines(keep_t0=True)
    if connected:
        bridge.data_received.connect(ctx.on_reply)
    if polling:
        bridge.set_polling(True)


# -- the window's File > Replay -----------------------------------------------------------------


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


def load_recording(path: str | Path, speed=1.0) -> tuple[float, list]:
    """(speed, replies) of a recording; ValueError saying what is wrong with either."""
    return parse_speed(speed), read_replies(Path(path))


def start_replay(window, path: str | Path, speed=1.0) -> Replayer | None:
    """Replay ``path`` into ``window`` at ``speed`` (1.0 = recorded pace, ``"max"``/inf).

    Reads the file on the calling thread (the command line and tests);
    File > Replay reads it in the background instead (:func:`open_replay`).
    Returns the running :class:`Replayer`, or None when the file or the speed
    is bad: then the reason is in the status bar and nothing changed.
    """
    try:
        speed, replies = load_recording(path, speed)
    except ValueError as e:
        window.statusBar().showMessage(f"replay: {e}", 15000)
        return None
    return begin_replay(window, Path(path), replies, speed)


def begin_replay(window, path: Path, replies: list, speed: float) -> Replayer | None:
    """Start replaying ``replies`` (read from ``path``); None (status bar says why) if unfit."""
    devices = next((tuple(r.id for r in rep.readings) for rep in replies if rep.readings), ())
    if not devices:
        window.statusBar().showMessage(f"replay: {path} holds no sensor readings", 15000)
        return None
    ctx = window.ctx
    try:
        MonitorSession(devices=devices, mounts=ctx.session.mounts)  # can the geometry take them?
    except ValueError as e:
        window.statusBar().showMessage(f"replay: {path} cannot be shown: {e}", 15000)
        return None
    old = getattr(window, "replayer", None)
    if old is not None and not old.done:
        old.stop()
    polling, connected = _detach_bridge(ctx)
    _prepare_session(ctx, devices)
    replayer = Replayer(ctx, replies, speed, parent=window)
    pace = "max speed" if math.isinf(speed) else f"{speed:g}x"
    seconds = float(replayer.times[-1]) if len(replayer.times) else 0.0

    def ended() -> None:
        _reattach_bridge(ctx, polling, connected)
        st = ctx.session.stats
        window.statusBar().showMessage(
            f"replay of {path.name} ended: {replayer.position} of {len(replies)} replies; "
            f"pose from {st.polls} single polls, {st.per_reply} replies per reply, "
            f"{st.gaps} gap(s)",
            10000,
        )

    replayer.on_end = ended
    window.replayer = replayer
    window.statusBar().showMessage(
        f"replaying {path.name}: {len(replies)} replies, {seconds:.1f} s at {pace}; "
        + pose_source(replies)
    )
    replayer.start()
    return replayer


def load_in_background(window, path: str | Path, speed) -> concurrent.futures.Future:
    """Read the recording on a worker thread, then start it on the GUI thread.

    An hour's recording takes tens of seconds to decode; the window stays
    responsive meanwhile (the status bar says the file is being read).
    """
    path = Path(path)
    pool = concurrent.futures.ThreadPoolExecutor(1, thread_name_prefix="mm-replay-load")
    future = pool.submit(load_recording, path, speed)
    pool.shutdown(wait=False)
    window.statusBar().showMessage(f"reading {path.name} …")
    timer = QTimer(window)

    def check() -> None:
        if not future.done():
            return
        timer.stop()
        timer.deleteLater()
        try:
            speed_, replies = future.result()
        except ValueError as e:
            window.statusBar().showMessage(f"replay: {e}", 15000)
            return
        begin_replay(window, path, replies, speed_)

    timer.timeout.connect(check)
    timer.start(100)
    return future


def open_replay(window) -> None:
    """File > Replay: choose a recording (an MCAP file, or a rosbag2 folder's metadata.yaml)
    and a speed (1x, 2x, 5x, 10x, max), then replay (the file is read in the background)."""
    name, _ = QFileDialog.getOpenFileName(
        window, "Replay a recording", "",
        "Recordings (*.mcap metadata.yaml);;MCAP recordings (*.mcap);;All files (*)",
    )
    if not name:
        return None
    choice, ok = QInputDialog.getItem(window, "Replay speed", "Speed", list(SPEEDS), 0, False)
    if not ok:
        return None
    load_in_background(window, name, choice)
    return None
