"""What the monitor tells a newcomer: plain names of the pose methods, the user guide,
the About text (version, ROS distribution, Python, the node watched).

No widgets here: the main window shows these strings in its combo box, menus and
message boxes.
"""

from __future__ import annotations

import os
import platform
from importlib import metadata
from pathlib import Path

__all__ = [
    "METHOD_LABELS",
    "about_text",
    "method_label",
    "method_tooltip",
    "open_user_guide",
    "ros_distribution",
    "user_guide_path",
    "version",
]

#: pose method key (mm_pc.core.odometry.METHODS) -> (plain name, one-sentence explanation)
METHOD_LABELS: dict[str, tuple[str, str]] = {
    "exact": (
        "Exact arc, 1 sensor",
        "Turns each interval into an arc from one sensor's forward and sideways counts; "
        "assumes the robot does not slip sideways. The default.",
    ),
    "two-sensor": (
        "Least squares, 2 sensors",
        "Fits the robot's motion to both sensors at once; also shows how well they agree "
        "(the residual in the Health tab).",
    ),
    "seed-approach1": (
        "Original formula 1",
        "The original monitor's first formula, kept to compare with; less accurate on curves.",
    ),
    "seed-approach2": (
        "Original formula 2",
        "The original monitor's second formula, kept to compare with.",
    ),
}


def method_label(key: str) -> str:
    """The plain name of pose method ``key`` (the key itself if it has none)."""
    return METHOD_LABELS.get(key, (key, ""))[0]


def method_tooltip(key: str | None = None) -> str:
    """Rich-text tooltip (Qt wraps it to a readable width) of one method, or of all."""
    keys = [key] if key is not None else list(METHOD_LABELS)
    items = "".join(
        f"<p><b>{method_label(k)}</b> (<code>{k}</code>): {METHOD_LABELS.get(k, ('', ''))[1]}</p>"
        for k in keys
    )
    if key is None:
        items = "<p>How the robot's pose is computed from the sensors:</p>" + items
    return items


def user_guide_path() -> Path:
    """docs/user-guide.md of this checkout."""
    return Path(__file__).resolve().parents[2] / "docs" / "user-guide.md"


def open_user_guide() -> tuple[bool, str]:
    """Open the user guide with the desktop's viewer: (opened, a line for the status bar)."""
    from PySide6.QtCore import QUrl
    from PySide6.QtGui import QDesktopServices

    path = user_guide_path()
    if not path.is_file():
        return False, f"user guide not found at {path} (docs/ is not installed)"
    if not QDesktopServices.openUrl(QUrl.fromLocalFile(str(path))):
        return False, f"no program opens {path}; read it in any text editor"
    return True, f"opened {path}"


def version() -> str:
    """The mouse-monitor package version ('unknown' when it is not installed)."""
    try:
        return metadata.version("mouse-monitor")
    except metadata.PackageNotFoundError:
        return "unknown (not installed)"


def ros_distribution() -> str:
    """The ROS 2 distribution in use: $ROS_DISTRO, else the PyPI wheel's rclpy."""
    if os.environ.get("ROS_DISTRO"):
        return os.environ["ROS_DISTRO"]
    try:
        return f"jazzy (PyPI wheels, rclpy {metadata.version('ros-jazzy-rclpy')})"
    except metadata.PackageNotFoundError:
        return "unknown (no ROS found)"


def about_text(beagle: str) -> str:
    """The About box: version, ROS distribution, Python, the node watched."""
    return "\n".join(
        (
            f"Mouse Monitor {version()}",
            "Two PLN2033 laser mouse sensors as robot odometry, watched over ROS 2.",
            f"ROS 2: {ros_distribution()}",
            f"Python: {platform.python_version()}",
            f"Node watched: {beagle}",
        )
    )
