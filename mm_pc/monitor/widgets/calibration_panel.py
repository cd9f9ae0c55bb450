"""The calibration in force, in the Pose panel: what, from where, Load… and Clear.

Shows the method and date of the calibration the session applies (and the
file it came from), one line per sensor (yaw in degrees, scales, fitted
position in cm), a Load… button that puts a calibration file in force (opened
in the folder the last calibration went to or came from; a refused file is
said in red and changes nothing; a robot-geometry file is named for what it
is), and a Clear button that puts the identity calibration in force (the file
stays; the status line says so).
"""

from __future__ import annotations

from pathlib import Path

from PySide6.QtWidgets import QFileDialog, QHBoxLayout, QLabel, QPushButton, QVBoxLayout, QWidget

from mm_pc.monitor.context import MonitorContext
from mm_pc.monitor.settings import last_folder, remember_folder
from mm_pc.monitor.widgets.style import ERROR_STYLE

__all__ = ["FOLDER_KIND", "CalibrationPanel", "describe_calibration", "geometry_file_note"]

#: the settings key of the folder Load… opens in (the wizard's Save remembers the same)
FOLDER_KIND = "calibration"


def describe_calibration(cal, source: str = "") -> str:
    """Plain text of a calibration for the panel ("none (identity)" when it changes nothing)."""
    if cal.is_identity:
        return "Calibration: none (identity)"
    head = f"Calibration: {cal.method or 'hand-made'}"
    if cal.date:
        head += f", {cal.date}"
    if source:
        head += f"\nfrom {source}"
    lines = [head]
    for dev in cal:
        c = cal[dev]
        line = f"{dev}: yaw {c.angle_offset_deg:.3f} deg, scale {c.scale_x:.4f}/{c.scale_y:.4f}"
        if c.position is not None:
            line += f", at ({c.x * 100:.2f}, {c.y * 100:.2f}) cm"
        lines.append(line)
    return "\n".join(lines)


def geometry_file_note(path: Path) -> str:
    """'' or, when ``path`` is a robot-geometry file (``mounts``, no ``sensors``), what to
    do with it instead of loading it as a calibration."""
    import yaml

    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, yaml.YAMLError):
        return ""
    if isinstance(data, dict) and "mounts" in data and "sensors" not in data:
        return (f"calibration not loaded: {path.name} is a robot geometry file (where the "
                "sensors sit): load it with Robot geometry… → Load…")
    return ""


class CalibrationPanel(QWidget):
    """Label + Load… + Clear; follows ``MonitorContext.calibration_changed``."""

    def __init__(self, ctx: MonitorContext, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.ctx = ctx
        self.label = QLabel("")
        self.label.setWordWrap(True)
        self.load_button = QPushButton("Load…")
        self.load_button.setToolTip("put a calibration file (YAML, saved by the wizard) in "
                                    "force")
        self.load_button.clicked.connect(self._load_clicked)
        self.clear_button = QPushButton("Clear calibration")
        self.clear_button.setToolTip("use no calibration (identity); the file is not changed")
        self.clear_button.clicked.connect(self.clear)
        self.error = QLabel("")
        self.error.setStyleSheet(ERROR_STYLE)
        self.error.setWordWrap(True)
        self.error.hide()
        buttons = QHBoxLayout()
        buttons.setContentsMargins(0, 0, 0, 0)
        buttons.addWidget(self.load_button)
        buttons.addWidget(self.clear_button)
        lay = QVBoxLayout(self)
        lay.setContentsMargins(0, 0, 0, 0)
        lay.addWidget(self.label)
        lay.addLayout(buttons)
        lay.addWidget(self.error)
        ctx.calibration_changed.connect(self.refresh)
        self.refresh()

    def refresh(self) -> None:
        cal = self.ctx.session.calibration
        source = self.ctx.calibration_source
        # the file's name only (a path does not wrap in the narrow dock); all of it in the tip
        self.label.setText(describe_calibration(cal, Path(source).name if source else ""))
        self.label.setToolTip(describe_calibration(cal, source))
        self.clear_button.setEnabled(not cal.is_identity)
        self._fit_label()

    def _fit_label(self) -> None:
        """The label's wrapped height as its minimum: the Pose panel's form layout kept the
        height of the previous text when a calibration came in after the window was shown
        (in a real X window the new lines were cut off at top and bottom)."""
        width = self.label.width()
        if width > 0:
            self.label.setMinimumHeight(0)  # heightForWidth is never below the minimum
            self.label.setMinimumHeight(self.label.heightForWidth(width))

    def resizeEvent(self, event) -> None:  # noqa: N802 - Qt API
        super().resizeEvent(event)
        self._fit_label()

    def load(self, path: str | Path) -> bool:
        """Put the calibration file ``path`` in force; False (the reason in red, nothing
        changed) if it cannot be."""
        path = Path(path)
        why = geometry_file_note(path)
        if not why and not path.is_file():
            why = f"calibration not loaded: {path} is not a file"
        if not why and not self.ctx.load_calibration(path):
            why = self.ctx.calibration_error or f"calibration not loaded from {path}"
        if why:
            self.error.setText(why)
            self.error.setToolTip(why)
            self.error.show()
            return False
        self.error.hide()
        return True

    def _load_clicked(self) -> None:
        path, _ = QFileDialog.getOpenFileName(self, "Load calibration", last_folder(FOLDER_KIND),
                                              "YAML (*.yaml *.yml)")
        if path:
            remember_folder(FOLDER_KIND, path)
            self.load(path)

    def clear(self) -> None:
        self.ctx.clear_calibration()
        self.error.hide()
