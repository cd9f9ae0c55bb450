"""Robot geometry editor: where the sensors sit, the axle length, the one-sensor choice.

Shown in the units of the original (cm, degrees); kept in SI. Mount
positions are base_link (REP 103: x forward of the axle centre, y left);
yaw is the mounting error (CCW+, see :class:`mm_pc.core.geometry.SensorMount`).
"Apply" validates every field (numbers, finite, axle length > 0) and then
hands the mounts and sensor index to ``MonitorSession.configure_odometry``,
which refuses what the pose method cannot use (e.g. a one-sensor method
with its sensor on the axle line, x = 0). On any refusal the message is
shown in red and nothing changes; on success ``ctx.odometry_changed`` is
emitted and the pose carries on from where it is.

The pose math does not use the axle length (it is the wheel odometry's); it
is kept with the geometry in ``ctx.robot_geometry`` and in the YAML file::

    version: 1
    axis_length_m: 0.079
    sensor: 0
    mounts:
      - {x_m: 0.049, y_m: -0.0395, yaw_rad: 0.0}
"""

from __future__ import annotations

import math
from contextlib import suppress
from dataclasses import dataclass
from pathlib import Path

from PySide6.QtWidgets import (
    QComboBox,
    QDialog,
    QDialogButtonBox,
    QFileDialog,
    QFormLayout,
    QGridLayout,
    QHBoxLayout,
    QLabel,
    QLineEdit,
    QPushButton,
    QVBoxLayout,
    QWidget,
)

from mm_pc.core.geometry import DEFAULT_GEOMETRY, RobotGeometry, SensorMount
from mm_pc.monitor.context import MonitorContext
from mm_pc.monitor.model.geometry_file import geometry_from_yaml, geometry_to_yaml
from mm_pc.monitor.settings import last_folder, remember_folder
from mm_pc.monitor.widgets.style import ERROR_STYLE, parse_number

__all__ = ["GeometryDialog", "calibration_file_note", "parse_number"]

#: the settings key of the folder the Load… and Save… dialogs open in
FOLDER_KIND = "geometry"


def calibration_file_note(text: str) -> str:
    """'' or, when ``text`` is a calibration file (a mapping of ``sensors``, no ``mounts``),
    what to do with it instead of loading it as a geometry."""
    import yaml

    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError:
        return ""
    if isinstance(data, dict) and "sensors" in data and "mounts" not in data:
        return ("this is a calibration file (each sensor's angle and scales), not a robot "
                "geometry: load it with Load… under Calibration in the Pose panel (or "
                "mm-monitor --calibration FILE)")
    return ""

@dataclass
class _MountRow:
    x: QLineEdit
    y: QLineEdit
    yaw: QLineEdit


#: a sensor further from the axle centre than this is a typing error (the emulator's
#: --sim-mounts has the same 1 m bound); the axle likewise
MAX_MOUNT_CM = 100.0
MAX_AXLE_CM = 300.0


def _bounded(text: str, limit: float, what: str) -> float:
    """The number in ``text`` if |number| <= ``limit``; ValueError naming ``what``
    otherwise (not a number, not finite, out of bounds)."""
    value = parse_number(text, what)
    if abs(value) > limit:
        raise ValueError(f"{what} must be within ±{limit:g}, got {value:g}")
    return value


class GeometryDialog(QDialog):
    """Edit the sensor mounts (cm, deg), the axle length (cm; key axis_length), the one sensor."""

    def __init__(self, ctx: MonitorContext, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.ctx = ctx
        self.setWindowTitle("Robot geometry")
        self.rows: list[_MountRow] = []
        self._grid_host = QWidget()
        self.grid = QGridLayout(self._grid_host)
        self.axis_edit = QLineEdit()
        self.axis_edit.setToolTip("distance between the wheels, cm (> 0)")
        self.sensor_box = QComboBox()
        self.sensor_box.setToolTip("the sensor that exact, seed-approach1 and seed-approach2 use")
        self.method_label = QLabel()
        form = QFormLayout()
        form.addRow("Axle length (cm)", self.axis_edit)
        form.addRow("Sensor for one-sensor methods", self.sensor_box)
        form.addRow("Pose method", self.method_label)
        self.error = QLabel("")
        self.error.setStyleSheet(ERROR_STYLE)
        self.error.setWordWrap(True)
        self.error.hide()
        self.status = QLabel("")
        self.status.setWordWrap(True)
        note = QLabel(
            "Positions in base_link: x forward of the axle centre, y to the left (cm). "
            "Yaw: the sensor's mounting error, CCW positive (deg); leave 0 when the "
            "calibration corrects it."
        )
        note.setWordWrap(True)
        self.apply_button = QPushButton("Apply")
        self.apply_button.clicked.connect(self.apply)
        save = QPushButton("Save…")
        save.clicked.connect(self._save_clicked)
        load = QPushButton("Load…")
        load.clicked.connect(self._load_clicked)
        file_row = QHBoxLayout()
        file_row.addWidget(load)
        file_row.addWidget(save)
        file_row.addStretch(1)
        buttons = QDialogButtonBox(QDialogButtonBox.Ok | QDialogButtonBox.Close)
        buttons.addButton(self.apply_button, QDialogButtonBox.ApplyRole)
        buttons.accepted.connect(self._ok)
        buttons.rejected.connect(self.reject)
        lay = QVBoxLayout(self)
        lay.addWidget(note)
        lay.addWidget(self._grid_host)
        lay.addLayout(form)
        lay.addLayout(file_row)
        lay.addWidget(self.error)
        lay.addWidget(self.status)
        lay.addWidget(buttons)
        self.load_from_session()
        ctx.devices_known.connect(self.load_from_session)
        ctx.odometry_changed.connect(self._show_method)

    # -- fields <-> values ---------------------------------------------------------------------

    def _names(self, n: int) -> list[str]:
        devices = self.ctx.session.devices
        return [devices[k] if k < len(devices) else f"sensor {k}" for k in range(n)]

    def load_from_session(self, *_args) -> None:
        """Fill the fields from the session's mounts and sensor (nothing applied)."""
        geometry = getattr(self.ctx, "robot_geometry", None)
        axis = geometry.axis_length if geometry is not None else DEFAULT_GEOMETRY.axis_length
        self.show_geometry(RobotGeometry(self.ctx.session.mounts, axis), self.ctx.session.sensor)
        self.error.hide()

    def show_geometry(self, geometry: RobotGeometry, sensor: int) -> None:
        """Put a geometry into the fields (cm, deg)."""
        self._build_rows(len(geometry.mounts))
        for row, m in zip(self.rows, geometry.mounts, strict=True):
            row.x.setText(f"{m.x * 100:.4g}")
            row.y.setText(f"{m.y * 100:.4g}")
            row.yaw.setText(f"{math.degrees(m.yaw):.4g}")
        self.axis_edit.setText(f"{geometry.axis_length * 100:.4g}")
        self.sensor_box.clear()
        self.sensor_box.addItems([f"{k}: {n}" for k, n in enumerate(self._names(len(self.rows)))])
        self.sensor_box.setCurrentIndex(min(max(sensor, 0), len(self.rows) - 1))
        self._show_method()

    def _build_rows(self, n: int) -> None:
        if len(self.rows) == n:
            return
        while self.grid.count():
            w = self.grid.takeAt(0).widget()
            if w is not None:
                w.deleteLater()
        self.rows = []
        for c, title in enumerate(("Sensor", "x (cm, forward)", "y (cm, left)", "yaw (deg)")):
            self.grid.addWidget(QLabel(f"<b>{title}</b>"), 0, c)
        for k, name in enumerate(self._names(n)):
            row = _MountRow(QLineEdit(), QLineEdit(), QLineEdit())
            self.grid.addWidget(QLabel(name), k + 1, 0)
            for c, edit in enumerate((row.x, row.y, row.yaw), start=1):
                edit.setMaximumWidth(90)
                self.grid.addWidget(edit, k + 1, c)
            self.rows.append(row)

    def _show_method(self) -> None:
        self.method_label.setText(self.ctx.session.method)

    def read_geometry(self) -> tuple[RobotGeometry, int]:
        """The geometry in the fields (SI); ValueError naming the field when refused."""
        names = self._names(len(self.rows))
        mounts = []
        for row, name in zip(self.rows, names, strict=True):
            x = _bounded(row.x.text(), MAX_MOUNT_CM, f"{name} x (cm)") / 100
            y = _bounded(row.y.text(), MAX_MOUNT_CM, f"{name} y (cm)") / 100
            yaw = _bounded(row.yaw.text(), 360.0, f"{name} yaw (deg)")
            mounts.append(SensorMount(x, y, math.radians(yaw)))
        axis = parse_number(self.axis_edit.text(), "axle length (cm)") / 100
        if not 0 < axis <= MAX_AXLE_CM / 100:
            raise ValueError(f"axle length must be > 0 and <= {MAX_AXLE_CM:g} cm, "
                             f"got {self.axis_edit.text().strip()!r}")  # fmt: skip
        return RobotGeometry(tuple(mounts), axis), max(self.sensor_box.currentIndex(), 0)

    # -- actions -------------------------------------------------------------------------------

    def apply(self) -> bool:
        """Validate and apply; False (nothing changed, message shown) when refused."""
        try:
            geometry, sensor = self.read_geometry()
            self.ctx.session.configure_odometry(mounts=geometry.mounts, sensor=sensor)
        except ValueError as e:
            self._fail(f"not applied: {e}")
            return False
        self.ctx.robot_geometry = geometry
        self.error.hide()
        self.status.setText("applied; the pose carries on from where it is")
        self.ctx.odometry_changed.emit()
        self.ctx.status_message.emit("robot geometry applied")
        return True

    def _ok(self) -> None:
        if self.apply():
            self.accept()

    def save(self, path: str | Path) -> bool:
        """Write the fields (validated, not applied) as YAML; False and a message on error."""
        try:
            geometry, sensor = self.read_geometry()
            Path(path).write_text(geometry_to_yaml(geometry, sensor), encoding="utf-8")
        except (OSError, ValueError) as e:
            self._fail(f"not saved: {e}")
            return False
        self.error.hide()
        self.status.setText(f"saved to {path}")
        return True

    def load(self, path: str | Path) -> bool:
        """Fill the fields from a YAML file (Apply uses it); False and a message on error."""
        try:
            text = Path(path).read_text(encoding="utf-8")
            note = calibration_file_note(text)
            if note:
                raise ValueError(f"{Path(path).name}: {note}")
            geometry, sensor = geometry_from_yaml(text)
        except (OSError, ValueError) as e:
            self._fail(f"not loaded: {e}")
            return False
        if self.ctx.session.devices and len(geometry.mounts) != len(self.ctx.session.devices):
            self._fail(
                f"not loaded: {path} has {len(geometry.mounts)} mounts, the robot has "
                f"{len(self.ctx.session.devices)} sensors"
            )
            return False
        self.show_geometry(geometry, sensor)
        self.error.hide()
        self.status.setText(f"loaded from {path}; press Apply to use it")
        return True

    def done(self, result: int) -> None:
        """Closed: stop following the session (the dialog may outlive its window)."""
        for signal, slot in (
            (self.ctx.devices_known, self.load_from_session),
            (self.ctx.odometry_changed, self._show_method),
        ):
            with suppress(RuntimeError, TypeError):
                signal.disconnect(slot)
        super().done(result)

    def _save_clicked(self) -> None:
        path, _ = QFileDialog.getSaveFileName(self, "Save geometry", last_folder(FOLDER_KIND),
                                              "YAML (*.yaml *.yml)")
        if path:
            remember_folder(FOLDER_KIND, path)
            self.save(path)

    def _load_clicked(self) -> None:
        path, _ = QFileDialog.getOpenFileName(self, "Load geometry", last_folder(FOLDER_KIND),
                                              "YAML (*.yaml *.yml)")
        if path:
            remember_folder(FOLDER_KIND, path)
            self.load(path)

    def _fail(self, text: str) -> None:
        self.error.setText(text)
        self.error.setToolTip(text)
        self.error.show()
        self.status.setText("")
        self._fit_height()

    def _fit_height(self) -> None:
        """Grow the dialog by what the shown error needs, so the rows above keep their
        height (they were squashed when the dialog kept its size)."""
        lay = self.layout()
        lay.activate()
        need = max(lay.totalHeightForWidth(self.width()), lay.totalMinimumSize().height())
        if need > self.height():
            self.resize(self.width(), need)
