"""The calibration in force, in the Pose panel: what, from where, and Clear.

Shows the method and date of the calibration the session applies (and the
file it came from), one line per sensor (yaw in degrees, scales, fitted
position in cm), and a Clear button that puts the identity calibration in
force (the file stays; the status line says so).
"""

from __future__ import annotations

from pathlib import Path

from PySide6.QtWidgets import QLabel, QPushButton, QVBoxLayout, QWidget

from mm_pc.monitor.context import MonitorContext

__all__ = ["CalibrationPanel", "describe_calibration"]


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


class CalibrationPanel(QWidget):
    """Label + Clear; follows ``MonitorContext.calibration_changed``."""

    def __init__(self, ctx: MonitorContext, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.ctx = ctx
        self.label = QLabel("")
        self.label.setWordWrap(True)
        self.clear_button = QPushButton("Clear calibration")
        self.clear_button.setToolTip("use no calibration (identity); the file is not changed")
        self.clear_button.clicked.connect(self.clear)
        lay = QVBoxLayout(self)
        lay.setContentsMargins(0, 0, 0, 0)
        lay.addWidget(self.label)
        lay.addWidget(self.clear_button)
        ctx.calibration_changed.connect(self.refresh)
        self.refresh()

    def refresh(self) -> None:
        cal = self.ctx.session.calibration
        source = self.ctx.calibration_source
        # the file's name only (a path does not wrap in the narrow dock); all of it in the tip
        self.label.setText(describe_calibration(cal, Path(source).name if source else ""))
        self.label.setToolTip(describe_calibration(cal, source))
        self.clear_button.setEnabled(not cal.is_identity)

    def clear(self) -> None:
        self.ctx.clear_calibration()
