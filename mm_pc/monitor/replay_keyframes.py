"""Keyframes of a replay: the session's state every KEYFRAME_S of recorded time.

The pose is integrated reply by reply, so a seek backwards used to feed every reply
again from the first one (an hour at 500 Hz: minutes). A :class:`Keyframes` keeps the
session's state as it was after the reply at each keyframe; a seek backwards restores
the newest one at or before its target and feeds at most one interval (at 500 Hz
2500 replies, ~0.3 s on the timer).

A keyframe is a deep copy of the session's attributes except:

* ``history`` and ``map_history``: a replay only appends to them, so the keyframe
  keeps their lengths and :meth:`Keyframes.restore` cuts them back
  (:meth:`~mm_pc.monitor.model.history.History.truncate`);
* the deques of immutable entries (``log``, ``gaps``, ``cpi_changes``,
  ``stats.events``): shallow copies;
* the calibration in force (immutable): shared; the wizard's open run: never copied,
  a restore keeps the one open now.

A keyframe is used only while it still describes this session: the same session and
history objects, no rows let go since (``dropped_rows``), and the same settings
(pose method, mounts, sensor, calibration, lift estimates, filters). Otherwise the
replay starts over from the first reply, as before.
"""

from __future__ import annotations

import copy
from collections import deque
from dataclasses import dataclass

__all__ = ["KEYFRAME_S", "Keyframe", "Keyframes"]

#: recorded seconds between two keyframes (a seek backwards feeds at most this much)
KEYFRAME_S = 5.0
#: session attributes that are deques of immutable entries (shallow-copied)
_SHALLOW = ("log", "gaps", "cpi_changes")
#: session attributes a keyframe neither copies nor restores
_KEEP = ("_cal_run",)


@dataclass
class Keyframe:
    """The session after ``position`` replies (at recorded time ``t_s``, s)."""

    position: int
    t_s: float
    session: object
    state: dict
    rows: int
    map_rows: int
    dropped: tuple[int, int]
    settings: tuple


def _settings(session) -> tuple:
    """What the processing depends on besides the replies (changed: keyframes are void)."""
    filters = tuple(
        (d, f.window, f.filter_x, f.filter_y) for d, f in sorted(session.filters.items())
    )
    return (session.method, session.mounts, session.sensor, id(session.calibration),
            session.use_lift_estimates, filters)  # fmt: skip


def _memo(session_dict: dict) -> dict:
    """deepcopy's memo: the shared and shallow-copied objects of a session's attributes."""
    memo: dict = {}
    for name in ("history", "map_history", "_calibration"):
        obj = session_dict.get(name)
        if obj is not None:
            memo[id(obj)] = obj
    for name in _SHALLOW:
        obj = session_dict.get(name)
        if isinstance(obj, deque):
            memo[id(obj)] = deque(obj, maxlen=obj.maxlen)
    events = getattr(session_dict.get("stats"), "events", None)
    if isinstance(events, deque):
        memo[id(events)] = deque(events, maxlen=events.maxlen)
    return memo


def _copy_state(session_dict: dict) -> dict:
    state = {k: v for k, v in session_dict.items() if k not in _KEEP}
    return copy.deepcopy(state, _memo(state))


def _dropped(session) -> tuple[int, int]:
    return tuple(h.dropped_rows if h is not None else -1
                 for h in (session.history, session.map_history))  # fmt: skip


class Keyframes:
    """The keyframes of one replay, oldest first (see the module doc)."""

    def __init__(self, interval_s: float = KEYFRAME_S) -> None:
        if not interval_s > 0:
            raise ValueError(f"keyframe interval must be > 0 s, got {interval_s!r}")
        self.interval_s = float(interval_s)
        self.frames: list[Keyframe] = []

    def __len__(self) -> int:
        return len(self.frames)

    def due(self, t_s: float) -> bool:
        """Is a keyframe owed at recorded time ``t_s`` (none yet, or an interval since the
        newest)?"""
        return not self.frames or t_s >= self.frames[-1].t_s + self.interval_s

    def take(self, session, position: int, t_s: float) -> Keyframe | None:
        """Keep the session's state after ``position`` replies (recorded time ``t_s``);
        None before the session knows its sensors (no histories yet)."""
        if session.history is None or session.map_history is None:
            return None
        if self.frames and position <= self.frames[-1].position:
            return None  # fed again after a restore: it is kept already
        frame = Keyframe(
            position=position, t_s=float(t_s), session=session,
            state=_copy_state(vars(session)), rows=len(session.history),
            map_rows=len(session.map_history), dropped=_dropped(session),
            settings=_settings(session),
        )  # fmt: skip
        self.frames.append(frame)
        return frame

    def usable(self, frame: Keyframe, session) -> bool:
        """Does ``frame`` still describe ``session`` (see the module doc)?"""
        return (
            frame.session is session
            and frame.state.get("history") is session.history
            and frame.state.get("map_history") is session.map_history
            and session.history is not None
            and len(session.history) >= frame.rows
            and len(session.map_history) >= frame.map_rows
            and _dropped(session) == frame.dropped
            and _settings(session) == frame.settings
        )

    def before(self, position: int, session) -> Keyframe | None:
        """The newest usable keyframe at or before ``position`` replies; None: none (start
        over). Keyframes made void are dropped."""
        self.frames = [f for f in self.frames if self.usable(f, session)]
        best = None
        for f in self.frames:
            if f.position <= position:
                best = f
        return best

    def restore(self, session, frame: Keyframe) -> None:
        """Put ``session`` back to ``frame`` (histories cut back to its rows); the newer
        keyframes are dropped (they are taken again as the replay passes them)."""
        state = _copy_state(frame.state)  # the keyframe stays as it is for the next seek
        for name in [k for k in vars(session) if k not in state and k not in _KEEP]:
            delattr(session, name)
        vars(session).update(state)
        session.history.truncate(frame.rows)
        session.map_history.truncate(frame.map_rows)
        self.frames = [f for f in self.frames if f.position <= frame.position]

    def clear(self) -> None:
        self.frames.clear()
