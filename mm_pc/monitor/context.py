"""What every view of the monitor shares: the session, the bridge and a few signals.

Views get one :class:`MonitorContext` and never talk to each other directly.
Replies (live from the bridge in batches, or one by one from a replay) enter
through :meth:`MonitorContext.on_replies`, which runs the session's processing, hands
the raw reply to a recorder if one is attached, and announces it.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from PySide6.QtCore import QObject, Signal

from mm_pc.core.calibration import Calibration
from mm_pc.core.geometry import DEFAULT_GEOMETRY, RobotGeometry
from mm_pc.core.sensor_data import Reply
from mm_pc.monitor.model.session import MonitorSession
from mm_pc.monitor.settings import config_dir

__all__ = ["DATA_STATES", "STALE_STATES", "MonitorConfig", "MonitorContext",
           "default_calibration_path"]

#: where the values on screen come from: the link's state, or the window's mode
DATA_STATES = ("live", "waiting", "lost", "paused", "replay", "offline")
#: states in which the newest values are old: views grey them and say since when
STALE_STATES = ("lost", "paused")


def default_calibration_path() -> Path:
    """Where the wizard saves and the monitor loads the calibration by default."""
    return config_dir() / "calibration.yaml"


@dataclass
class MonitorConfig:
    """Start-up options of the monitor (the command line of mm-monitor)."""

    beagle: str = "/mm_beagle"
    rate_hz: float = 15.0
    calibration_file: Path = field(default_factory=default_calibration_path)
    method: str = "exact"
    #: --sim's trajectory (None: not a sim) and where its sensors are mounted (None: unknown)
    sim: str | None = None
    sim_mounts: tuple | None = None


class MonitorContext(QObject):
    """Shared state of one monitor window.

    ``bridge`` is a :class:`~.ros_bridge.RosBridge` or None (offline: replay,
    tests); views must check ``bridge is not None`` before asking the node.
    """

    reply_processed = Signal(object)  # the newest Reply, after the session took a batch
    devices_known = Signal(tuple)  # sensor ids, once the first reply named them
    session_reset = Signal()  # paths, graphs and pose cleared
    calibration_changed = Signal()  # a new calibration is in force
    odometry_changed = Signal()  # pose method, geometry or sensor changed
    status_message = Signal(str)  # a line for the status bar
    data_state_changed = Signal(str)  # one of DATA_STATES

    def __init__(
        self, session: MonitorSession, bridge=None, config: MonitorConfig | None = None
    ) -> None:
        super().__init__()
        self.session = session
        self.bridge = bridge
        self.config = config or MonitorConfig()
        #: object with ``write_reply(reply)``; set by the recorder while recording
        self.recorder = None
        self.calibration_error = ""
        #: where the calibration in force came from (a file path, the wizard), "" = none
        self.calibration_source = ""
        #: the robot's mounts and axis length as edited in the geometry dialog
        self.robot_geometry: RobotGeometry = DEFAULT_GEOMETRY
        #: one of DATA_STATES, set by the window from the link state, pause and replay
        self.data_state = "offline" if bridge is None else "waiting"
        #: wall-clock time (time.time(), s) the newest reply was processed; None before
        self.last_data_time: float | None = None

    def set_data_state(self, state: str) -> None:
        """Say where the values come from now (one of DATA_STATES); the views are told
        when it changes."""
        if state not in DATA_STATES:
            raise ValueError(f"data state must be one of {DATA_STATES}, got {state!r}")
        if state != self.data_state:
            self.data_state = state
            self.data_state_changed.emit(state)

    @property
    def stale(self) -> bool:
        """True when the values on screen are old (link lost, polling paused)."""
        return self.data_state in STALE_STATES

    def no_data_since(self) -> str:
        """"no data since HH:MM:SS" (local time of the newest reply), or "no data yet"."""
        if self.last_data_time is None:
            return "no data yet"
        return "no data since " + time.strftime("%H:%M:%S", time.localtime(self.last_data_time))

    def on_reply(self, reply: Reply) -> None:
        """Process one reply (GUI thread) and tell the views."""
        self.on_replies((reply,))

    def on_replies(self, replies: Sequence[Reply]) -> None:
        """Process replies delivered together, oldest first (GUI thread: the bridge's
        ``data_received``); the views are told once, with the newest."""
        if not replies:
            return
        known = bool(self.session.devices)
        self.last_data_time = time.time()
        self.session.process_batch(replies)
        for reply in replies:
            if self.recorder is None:
                break  # it detached itself (a write failed)
            self.recorder.write_reply(reply)
        if not known and self.session.devices:
            self.devices_known.emit(self.session.devices)
        self.reply_processed.emit(replies[-1])

    def reset(self) -> None:
        """Reset path and values (pose to the origin); counting carries on."""
        self.session.reset()
        self.session_reset.emit()

    def load_calibration(self, path: Path | None = None) -> bool:
        """Load the calibration file (default: the config's); False and a message if it fails.

        A missing default file is normal (never calibrated) and not an error.
        """
        path = Path(path or self.config.calibration_file)
        if not path.exists():
            self.calibration_error = ""
            return False
        try:
            cal = Calibration.load(path)
        except (OSError, ValueError) as e:
            self.calibration_error = f"calibration not loaded: {e}"  # e names the file
            self.status_message.emit(self.calibration_error)
            return False
        self.set_calibration(cal, str(path))
        self.status_message.emit(f"calibration loaded from {path}")
        return True

    def set_calibration(self, cal: Calibration, source: str = "") -> None:
        """Put ``cal`` in force; ``source``: where it came from (shown in the Pose panel)."""
        self.session.calibration = cal
        self.calibration_source = source
        self.calibration_changed.emit()

    def clear_calibration(self) -> str:
        """Back to the identity calibration (files are not touched); the status line said."""
        was = self.calibration_source
        self.set_calibration(Calibration(), "")
        msg = "calibration cleared: identity in force" + (
            f" ({was} is unchanged; it loads again at the next start)" if was else ""
        )
        self.status_message.emit(msg)
        return msg
