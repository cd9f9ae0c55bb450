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


# -- every dialog the monitor opens, at the two small screens ---------------------------------

#: (width, height) of the small screens; a window manager's title bar takes TITLE_BAR px
SCREENS = ((1024, 700), (800, 600))
TITLE_BAR = 30


def _on_screen(qapp, dialog, screen) -> list[str]:
    """Show ``dialog`` as a window manager would on ``screen`` (its own size, cut to the
    screen's) and list what does not fit: a minimum size larger than the screen, and
    every clipped text (test_monitor_layout.clipped_texts)."""
    from test_monitor_layout import clipped_texts

    w, h = screen[0], screen[1] - TITLE_BAR
    dialog.show()
    qapp.processEvents()
    dialog.resize(min(dialog.width(), w), min(dialog.height(), h))
    for _ in range(3):
        qapp.processEvents()
    problems = []
    least = dialog.minimumSizeHint().expandedTo(dialog.minimumSize())
    if least.width() > w or least.height() > h:
        problems.append(f"needs at least {least.width()}x{least.height()} px, the screen "
                        f"has {w}x{h}")
    if dialog.width() > w or dialog.height() > h:
        problems.append(f"is {dialog.width()}x{dialog.height()} px on a {w}x{h} screen")
    return problems + clipped_texts(dialog)


def _walk_dialogs(qtbot, qapp, window, screen) -> dict[str, list[str]]:
    """Open every dialog of the window (with its refusals shown) and measure each."""
    from test_monitor_calibration_wizard import guided_replies, record_guided

    from mm_pc.monitor.replay import refuse
    from mm_pc.monitor.widgets.calibration_wizard import CalibrationWizard
    from mm_pc.monitor.widgets.log_dialog import LogDialog

    ctx = window.ctx
    found: dict[str, list[str]] = {}

    def measure(name, dialog):
        found[name] = _on_screen(qapp, dialog, screen)
        dialog.close()

    window.open_filter_dialog()
    dlg = window.findChild(FilterDialog)
    for row in dlg.rows.values():
        row.window.setText("1000")
        dlg.apply_sensor(row.device)
    measure("median filters, both refused", dlg)
    window.open_geometry_dialog()
    dlg = window.findChild(GeometryDialog)
    dlg.rows[0].x.setText("far")
    dlg.apply()
    measure("robot geometry, refused", dlg)
    window.open_log_dialog()
    log = window.findChild(LogDialog)
    log.poll()
    measure("log", log)
    maps = window.views["Maps"]
    new_map = maps.open_new_map_dialog()
    for key in ("cell", "nx"):
        new_map.fields[key].edit.setText("wide")
    new_map.apply()
    measure("new map, refused", new_map)
    measure("keyboard shortcuts", window.show_shortcuts())
    measure("about", window.show_about())
    refuse(window, "run.mcap: not an MCAP file (its first bytes are b'junk')", dialog=True)
    measure("replay refused", window.replay_error)

    wiz = CalibrationWizard(ctx, window)
    measure("wizard intro", wiz)
    wiz = CalibrationWizard(ctx, window)
    wiz.show()
    wiz.next()
    replies = guided_replies()
    ctx.session.forget_baselines()
    ctx.on_reply(replies[0])
    record_guided(qtbot, ctx, _feed_all, wiz, replies)
    found["wizard drive, six steps"] = _on_screen(qapp, wiz, screen)
    wiz.next()
    wiz.distance_page.edit.setText("far")
    wiz.next()  # refused: the distance page with its error
    found["wizard distance, refused"] = _on_screen(qapp, wiz, screen)
    wiz.distance_page.edit.setText("")
    wiz.next()
    found["wizard results"] = _on_screen(qapp, wiz, screen)
    wiz.next()
    found["wizard save"] = _on_screen(qapp, wiz, screen)
    wiz.reject()
    return found


def _feed_all(ctx, replies):
    for r in replies:
        ctx.on_reply(r)


@pytest.fixture
def main_window(qapp, feed, tmp_path, monkeypatch):
    from mm_pc.monitor.main_window import MainWindow

    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "config"))
    config = MonitorConfig(rate_hz=15.0, calibration_file=tmp_path / "cfg" / "cal.yaml")
    w = MainWindow(MonitorContext(MonitorSession(), None, config), None)
    feed(w.ctx, rate_hz=50.0, seconds=1.0)
    w.show()
    yield w
    w.close()


@pytest.mark.parametrize("screen", SCREENS, ids=lambda s: f"{s[0]}x{s[1]}")
def test_every_dialog_fits_a_small_screen_and_cuts_no_text(qtbot, qapp, main_window, screen):
    main_window.resize(screen[0], screen[1] - TITLE_BAR)
    found = _walk_dialogs(qtbot, qapp, main_window, screen)
    assert len(found) == 12  # every dialog above was measured
    report = [f"{name}: {p}" for name, problems in found.items() for p in problems]
    print(f"{screen}: {len(report)} problems in {len(found)} dialogs")
    assert not report, "\n".join(report)
