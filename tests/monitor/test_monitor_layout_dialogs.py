"""Dialogs that refuse clearly: Enter in a median-filter field applies and never closes,
every refusal says why; the geometry dialog keeps its rows when it shows an error, opens
Load… in the last folder and names a calibration file for what it is.

Offscreen Qt, no node; replies from the simulated feed.
"""

from __future__ import annotations

import pytest

pytest.importorskip("pytestqt")

from PySide6.QtCore import Qt
from PySide6.QtWidgets import QFileDialog

from mm_pc.core.calibration import Calibration, SensorCalibration
from mm_pc.monitor.context import MonitorConfig, MonitorContext
from mm_pc.monitor.model.session import MonitorSession
from mm_pc.monitor.model.sim_feed import DEFAULT_DEVICES, sim_replies
from mm_pc.monitor.widgets.filter_dialog import FilterDialog
from mm_pc.monitor.widgets.geometry_dialog import GeometryDialog

D0 = DEFAULT_DEVICES[0]


@pytest.fixture
def ctx(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "config"))  # a private monitor.ini
    config = MonitorConfig(calibration_file=tmp_path / "cfg" / "calibration.yaml")
    c = MonitorContext(MonitorSession(), None, config)
    c.on_reply(next(sim_replies("straight", 50)))
    return c


@pytest.mark.parametrize(("typed", "why"), [
    ("0", "got 0"),
    ("1000", "got 1000"),
    ("abc", "got 'abc'"),
])
def test_enter_on_a_bad_median_window_keeps_the_dialog_open_and_says_why(qtbot, ctx, typed, why):
    dlg = FilterDialog(ctx)
    qtbot.addWidget(dlg)
    dlg.show()
    qtbot.waitExposed(dlg)
    before = ctx.session.filters[D0].window
    row = dlg.rows[D0]
    row.window.setFocus()
    row.window.setText(typed)
    qtbot.keyClick(row.window, Qt.Key_Return)
    assert dlg.isVisible() and dlg.result() == 0
    assert row.error.isVisible()
    assert row.error.text() == (f"{D0}: median window must be an integer number of samples "
                                f"in 1..999, {why}; nothing changed")
    assert ctx.session.filters[D0].window == before


def test_enter_on_a_good_median_window_applies_it_and_keeps_the_dialog_open(qtbot, ctx):
    dlg = FilterDialog(ctx)
    qtbot.addWidget(dlg)
    dlg.show()
    qtbot.waitExposed(dlg)
    row = dlg.rows[D0]
    row.fx.setChecked(True)
    row.window.setFocus()
    row.window.setText("7")
    for key in (Qt.Key_Return, Qt.Key_Enter):
        qtbot.keyClick(row.window, key)
        assert dlg.isVisible()
    assert ctx.session.filters[D0].window == 7 and ctx.session.filters[D0].filter_x
    assert dlg.status.text() == f"{D0}: X, window 7"
    assert row.error.isHidden()


def test_geometry_error_keeps_the_rows_whole(qtbot, ctx):
    dlg = GeometryDialog(ctx)
    qtbot.addWidget(dlg)
    dlg.resize(dlg.sizeHint())
    dlg.show()
    qtbot.waitExposed(dlg)
    heights = [e.height() for r in dlg.rows for e in (r.x, r.y, r.yaw)]
    dlg.rows[0].x.setText("far")
    assert not dlg.apply()
    qtbot.wait(10)
    assert dlg.error.text() == f"not applied: {D0} x (cm) must be a number, got 'far'"
    assert [e.height() for r in dlg.rows for e in (r.x, r.y, r.yaw)] == heights
    assert all(h >= dlg.rows[0].x.sizeHint().height() for h in heights)
    assert dlg.error.height() >= dlg.error.heightForWidth(dlg.error.width())
    assert dlg.axis_edit.height() >= dlg.axis_edit.sizeHint().height()


def test_geometry_load_opens_in_the_last_folder_and_remembers_it(qtbot, ctx, tmp_path,
                                                                 monkeypatch):
    from mm_pc.monitor.settings import last_folder, remember_folder

    asked = []
    folder = tmp_path / "robots"
    folder.mkdir()
    remember_folder("geometry", folder / "old.yaml")

    def fake_open(_parent, _title, start, _filter):
        asked.append(start)
        return str(tmp_path / "elsewhere" / "new.yaml"), ""

    (tmp_path / "elsewhere").mkdir()
    monkeypatch.setattr(QFileDialog, "getOpenFileName", staticmethod(fake_open))
    dlg = GeometryDialog(ctx)
    qtbot.addWidget(dlg)
    dlg._load_clicked()
    assert asked == [str(folder)]
    assert last_folder("geometry") == str(tmp_path / "elsewhere")
    assert "not loaded" in dlg.error.text()  # the file does not exist: said so


def test_geometry_load_names_a_calibration_file(qtbot, ctx, tmp_path):
    cal = Calibration({D0: SensorCalibration(angle_offset=0.1, scale=1.02)}, method="")
    path = tmp_path / "calibration.yaml"
    cal.save(path)
    dlg = GeometryDialog(ctx)
    qtbot.addWidget(dlg)
    assert not dlg.load(path)
    text = dlg.error.text()
    assert text.startswith("not loaded: calibration.yaml: this is a calibration file")
    assert "load it with Load… under Calibration in the Pose panel" in text
    assert "unsupported version" not in text
