"""What the monitor remembers between runs: one ini file beside the calibration.

``$XDG_CONFIG_HOME/mouse-monitor/monitor.ini`` (default ``~/.config/...``), read
and written through :class:`QSettings` in ini format, so it is plain text a user
can read or delete. Keys are grouped: ``window/*`` (geometry, dock layout, tab),
``sampling/*``, ``pose/*`` and ``folders/<kind>`` (the last folder of each file
dialog). A missing or unreadable file means defaults; nothing here raises.
"""

from __future__ import annotations

import os
from pathlib import Path

from PySide6.QtCore import QSettings

__all__ = ["config_dir", "last_folder", "open_settings", "remember_folder", "settings_path"]


def config_dir() -> Path:
    """The monitor's configuration folder (calibration.yaml, monitor.ini)."""
    base = os.environ.get("XDG_CONFIG_HOME") or os.path.join(os.path.expanduser("~"), ".config")
    return Path(base) / "mouse-monitor"


def settings_path() -> Path:
    return config_dir() / "monitor.ini"


def open_settings() -> QSettings:
    """The settings file (created on the first write)."""
    return QSettings(str(settings_path()), QSettings.IniFormat)


def last_folder(kind: str) -> str:
    """The folder the ``kind`` dialog (e.g. "recording", "export") last used; else home.

    A remembered folder that no longer exists falls back to the home folder, never
    to the working directory (which is often the repository).
    """
    folder = open_settings().value(f"folders/{kind}", "")
    if isinstance(folder, str) and folder and Path(folder).is_dir():
        return folder
    return os.path.expanduser("~")


def remember_folder(kind: str, path: str | os.PathLike) -> None:
    """Remember the folder of ``path`` (a file just opened or saved) for the ``kind`` dialog."""
    if not path:
        return
    p = Path(path)
    folder = p if p.is_dir() else p.parent
    s = open_settings()
    s.setValue(f"folders/{kind}", str(folder))
    s.sync()
