"""The replay's player: recorded replies fed to the window at their recorded pace, seeks.

A :class:`Replayer` feeds ``ctx.on_reply`` on a Qt timer, at the pace of the readings'
stamps times ``speed`` (``math.inf`` = as fast as the GUI allows, in batches of ~20 ms so
the window stays responsive). A seek forward feeds the replies up to its target; a seek
backward restores the newest keyframe before it (:mod:`.replay_keyframes`, every
KEYFRAME_S of recorded time) and feeds from there, so it costs at most one interval.
The window's replay mode around it: :mod:`.replay`.
"""

from __future__ import annotations

import math
import time

import numpy as np
from PySide6.QtCore import QObject, Qt, QTimer, Signal

from mm_pc.core.sensor_data import Reply
from mm_pc.monitor.replay_keyframes import Keyframes

__all__ = [
    "BATCH_S", "SEEK_AT_ONCE", "SEEK_CHUNK", "Replayer", "parse_speed", "reply_times",
    "speed_name",
]  # fmt: skip

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
        #: called before a seek backwards feeds the replies again from the first one (no
        #: keyframe before its target): the session must start over
        self.on_rewind = None
        #: called after a seek backwards put the session back to a keyframe (the views
        #: must draw its histories anew)
        self.on_restore = None
        #: the session's state every KEYFRAME_S of recorded time (a ctx without a session,
        #: in tests, gets none)
        self.keyframes = Keyframes()
        self._next_key_s = 0.0
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
        paused as before. Forward, the replies up to it are fed; backward, the session goes
        back to the newest keyframe at or before it (:attr:`on_restore`) and the replies
        from there are fed (the pose is integrated reply by reply); without one the path
        starts over (:attr:`on_rewind`) from the first reply. Up to SEEK_AT_ONCE replies
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
            self._go_back(i)
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

    def _go_back(self, i: int) -> None:
        """Put the session back to the newest keyframe at or before ``i`` replies (or to
        the start without one)."""
        session = getattr(self.ctx, "session", None)
        frame = self.keyframes.before(i, session) if session is not None else None
        if frame is None:
            self.keyframes.clear()
            if self.on_rewind is not None:
                self.on_rewind()
            self.position = 0
            self._next_key_s = 0.0
            return
        self.keyframes.restore(session, frame)
        self.position = frame.position
        self._next_key_s = frame.t_s + self.keyframes.interval_s
        if self.on_restore is not None:
            self.on_restore()

    def _fed(self) -> None:
        """After replies were fed: keep a keyframe when one is due."""
        if not self.position or self.times[self.position - 1] < self._next_key_s:
            return
        session = getattr(self.ctx, "session", None)
        if session is None:
            return
        t = float(self.times[self.position - 1])
        self.keyframes.take(session, self.position, t)
        if session.history is not None:  # else: at the next reply (the sensors unknown yet)
            self._next_key_s = t + self.keyframes.interval_s

    def _feed_to(self, i: int, deadline: float | None) -> None:
        """Feed the replies up to index ``i`` (or until ``deadline``, perf_counter s), in
        chunks of SEEK_CHUNK that end at the keyframes' times."""
        while self.position < i:
            end = min(self.position + SEEK_CHUNK, i)
            if self.position == 0:
                end = 1  # the first reply alone: the first keyframe is right after it
            else:  # a chunk ends where a keyframe is due
                due = int(np.searchsorted(self.times, self._next_key_s, side="left")) + 1
                if self.position < due < end:
                    end = due
            self.ctx.on_replies(self.replies[self.position:end])
            self.position = end
            self._fed()
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
            self._fed()
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
