"""The Pose panel's calibration: Load… (last folder, refusals with the reason, a geometry
file named for what it is) and Clear; the geometry dialog on a calibration file points
here (issue 29 item 9)."""

from __future__ import annotations

import pytest

pytest.importorskip("pytestqt")
from PySide6.QtWidgets import QFileDialog

from mm_pc.core.calibration import Calibration, SensorCalibration
from mm_pc.core.geometry import DEFAULT_GEOMETRY
from mm_pc.monitor.context import MonitorConfig, MonitorContext
from mm_pc.monitor.model.geometry_file import geometry_to_yaml
from mm_pc.monitor.model.session import MonitorSession
from mm_pc.monitor.model.sim_feed import DEFAULT_DEVICES, sim_replies
from mm_pc.monitor.widgets.calibration_panel import CalibrationPanel
from mm_pc.monitor.widgets.geometry_dialog import GeometryDialog

D0 = DEFAULT_DEVICES[0]


@pytest.fixture
def ctx(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "config"))  # a private monitor.ini
    config = MonitorConfig(calibration_file=tmp_path / "cfg" / "calibration.yaml")
    c = MonitorContext(MonitorSession(), None, config)
    c.on_reply(next(sim_replies("straight", 50)))
    return c


def test_load_puts_a_calibration_in_force_and_refuses_other_files(qtbot, ctx, tmp_path):
    panel = CalibrationPanel(ctx)
    qtbot.addWidget(panel)
    cal = Calibration({D0: SensorCalibration(angle_offset=0.1, scale=1.02)}, method="fit")
    good = tmp_path / "robot1.yaml"
    cal.save(good)
    geometry = tmp_path / "geometry.yaml"
    geometry.write_text(geometry_to_yaml(DEFAULT_GEOMETRY, 0))
    junk = tmp_path / "junk.yaml"
    junk.write_text("version: 7\n")
    for path, why in (
        (geometry, "calibration not loaded: geometry.yaml is a robot geometry file (where the "
                   "sensors sit): load it with Robot geometry… → Load…"),
        (junk, f"calibration not loaded: calibration file {junk}:"),
        (tmp_path / "missing.yaml", f"calibration not loaded: {tmp_path}/missing.yaml is not "
                                    "a file"),
    ):
        assert not panel.load(path)
        assert panel.error.text().startswith(why) and panel.error.isVisibleTo(panel)
        assert ctx.session.calibration.is_identity  # nothing changed
    assert panel.load(good)
    assert ctx.session.calibration == cal and panel.error.isHidden()
    assert "robot1.yaml" in panel.label.text() and panel.clear_button.isEnabled()


def test_load_opens_in_the_last_calibration_folder(qtbot, ctx, tmp_path, monkeypatch):
    from mm_pc.monitor.settings import last_folder, remember_folder

    folder = tmp_path / "cals"
    folder.mkdir()
    remember_folder("calibration", folder / "old.yaml")  # where the wizard saved last
    asked = []
    cal = Calibration({D0: SensorCalibration(angle_offset=0.05)})
    (tmp_path / "other").mkdir()
    cal.save(tmp_path / "other" / "new.yaml")

    def fake_open(_parent, _title, start, _filter):
        asked.append(start)
        return str(tmp_path / "other" / "new.yaml"), ""

    monkeypatch.setattr(QFileDialog, "getOpenFileName", staticmethod(fake_open))
    panel = CalibrationPanel(ctx)
    qtbot.addWidget(panel)
    panel._load_clicked()
    assert asked == [str(folder)]
    assert last_folder("calibration") == str(tmp_path / "other")
    assert ctx.session.calibration == cal


def test_the_geometry_dialog_sends_a_calibration_file_to_the_panel(qtbot, ctx, tmp_path):
    path = tmp_path / "calibration.yaml"
    Calibration({D0: SensorCalibration(angle_offset=0.1)}).save(path)
    dlg = GeometryDialog(ctx)
    qtbot.addWidget(dlg)
    dlg.show()
    rows = [r.x.height() for r in dlg.rows]
    assert not dlg.load(path)
    assert dlg.error.text() == (
        "not loaded: calibration.yaml: this is a calibration file (each sensor's angle and "
        "scales), not a robot geometry: load it with Load… under Calibration in the Pose panel "
        "(or mm-monitor --calibration FILE)"
    )
    qtbot.wait(10)
    assert [r.x.height() for r in dlg.rows] == rows  # the rows keep their height
    assert ctx.session.mounts == DEFAULT_GEOMETRY.mounts  # nothing changed
