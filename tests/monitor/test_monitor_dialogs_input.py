"""Bad input in every dialog and field the monitor opens, typed as a user would (issue 29
item 7): 0, 1000, -1, nan, text, empty, then Enter. The dialog stays open, the refusal says
why next to the field, and nothing changed (filters, CPI request, live map).

The geometry dialog and the wizard's distance page have their own tests
(test_monitor_layout_dialogs.py, test_monitor_dialogs.py). Offscreen Qt, no node.
"""

from __future__ import annotations

import pytest

pytest.importorskip("pytestqt")

import pyqtgraph as pg
from PySide6.QtCore import Qt
from PySide6.QtWidgets import QAbstractSpinBox, QLineEdit

from mm_pc.monitor.context import MonitorConfig, MonitorContext
from mm_pc.monitor.main_window import MainWindow
from mm_pc.monitor.model.session import MonitorSession
from mm_pc.monitor.model.sim_feed import DEFAULT_DEVICES
from mm_pc.monitor.widgets.debug_view import DebugView
from mm_pc.monitor.widgets.filter_dialog import FilterDialog
from mm_pc.monitor.widgets.log_dialog import LogDialog
from mm_pc.monitor.widgets.maps_view.view import MapsView
from mm_pc.monitor.widgets.registers_view import RegistersView
from mm_pc.monitor.widgets.resolution_panel import ResolutionPanel

D0, D1 = DEFAULT_DEVICES
WINDOW_RULE = "median window must be an integer number of samples in 1..999"
#: (typed, what the refusal says after the rule)
BAD_WINDOWS = [
    ("0", f"{WINDOW_RULE}, got 0"),
    ("1000", f"{WINDOW_RULE}, got 1000"),
    ("-1", f"{WINDOW_RULE}, got -1"),
    ("nan", f"{WINDOW_RULE}, got nan"),
    ("2.5", f"{WINDOW_RULE}, got 2.5"),
    ("seven", f"{WINDOW_RULE}, got 'seven'"),
    ("", "median window is empty: type an integer number of samples in 1..999"),
]
PLN = "(Philips PLN2033 allows 100..6400 in steps of 100)"
BAD_CPIS = [
    ("0", f"CPI 0 is out of range {PLN}"),
    ("-1", f"CPI -1 is out of range {PLN}"),
    ("6401", f"CPI 6401 is out of range {PLN}"),
    ("150", f"CPI 150 is not supported by the sensor's encoding {PLN}"),
    ("nan", f"CPI must be a whole number, got 'nan' {PLN}"),
    ("fast", f"CPI must be a whole number, got 'fast' {PLN}"),
    ("", f"the CPI field is empty: type a whole number {PLN}"),
]


@pytest.fixture
def window(qapp, feed, tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "config"))
    config = MonitorConfig(rate_hz=15.0, calibration_file=tmp_path / "cal.yaml")
    w = MainWindow(MonitorContext(MonitorSession(), None, config), None)
    feed(w.ctx, rate_hz=50.0, seconds=1.0)
    w.resize(1024, 700)
    w.show()
    yield w
    w.close()


def _filters(ctx) -> dict:
    return {d: (f.window, f.filter_x, f.filter_y) for d, f in ctx.session.filters.items()}


def _type(qtbot, edit: QLineEdit, text: str) -> None:
    """Select all, type ``text`` (or delete), press Enter: what a user does."""
    edit.setFocus()
    edit.selectAll()
    qtbot.keyClick(edit, Qt.Key_Delete)
    if text:
        qtbot.keyClicks(edit, text)
    qtbot.keyClick(edit, Qt.Key_Return)


@pytest.mark.parametrize(("typed", "why"), BAD_WINDOWS, ids=[t or "empty" for t, _ in BAD_WINDOWS])
def test_filter_dialog_from_the_menu_refuses_a_bad_window_on_enter(qtbot, window, typed, why):
    window.open_filter_dialog()
    dlg = window.findChild(FilterDialog)
    qtbot.waitExposed(dlg)
    before = _filters(window.ctx)
    row = dlg.rows[D1]
    row.fy.setChecked(True)  # applies D1 with its window in force (5): allowed
    after_tick = _filters(window.ctx)
    assert after_tick[D1][2] and after_tick[D0] == before[D0]
    row.fx.blockSignals(True)
    row.fx.setChecked(True)  # ticked but not applied yet: the refusal must put it back
    row.fx.blockSignals(False)
    _type(qtbot, row.window, typed)
    assert dlg.isVisible() and dlg.result() == 0
    assert row.error.isVisible() and row.error.text() == f"{D1}: {why}; nothing changed"
    assert _filters(window.ctx) == after_tick
    assert not row.fx.isChecked()  # the box shows what is in force
    assert dlg.rows[D0].error.isHidden()
    qtbot.mouseClick(dlg.apply_button, Qt.LeftButton)  # Apply: no row of it applied either
    assert dlg.status.text() == "not applied: fix the field marked in red"
    assert _filters(window.ctx) == after_tick
    _type(qtbot, row.window, "9")  # fixed: applied, the message goes, still open
    assert dlg.isVisible() and row.error.isHidden()
    assert window.ctx.session.filters[D1].window == 9
    dlg.reject()


def test_filter_dialog_height_shows_the_whole_refusal(qtbot, window):
    window.open_filter_dialog()
    dlg = window.findChild(FilterDialog)
    qtbot.waitExposed(dlg)
    for row in dlg.rows.values():
        _type(qtbot, row.window, "1000")
    qtbot.wait(20)
    for row in dlg.rows.values():
        assert row.error.height() >= row.error.heightForWidth(row.error.width())
        bottom = row.error.mapTo(dlg, row.error.rect().bottomLeft()).y()
        assert bottom <= dlg.height()
    dlg.reject()


@pytest.mark.parametrize(("typed", "why"), BAD_CPIS, ids=[t or "empty" for t, _ in BAD_CPIS])
def test_cpi_field_refuses_bad_input_on_enter_and_sends_nothing(qtbot, feed, fake_bridge,
                                                               typed, why):
    ctx = MonitorContext(MonitorSession(), bridge=fake_bridge)
    panel = ResolutionPanel(ctx)
    qtbot.addWidget(panel)
    feed(ctx, seconds=1.0)
    panel.show()
    qtbot.waitExposed(panel)
    row = panel.rows[D0]
    _type(qtbot, row.edit, typed)
    assert fake_bridge.calls == []
    assert row.error.text() == why
    assert row.edit.text() == "1600"  # the field shows the CPI in force again
    assert panel.rows[D1].error.text() == ""
    _type(qtbot, row.edit, "1000")  # 1000 is a PLN2033 CPI: sent, the refusal goes
    assert fake_bridge.calls == [("resolution", D0, 1000)]
    assert row.error.text() == ""


@pytest.mark.parametrize(("field", "typed", "why"), [
    ("cell", "0", "cell size (m) must be > 0, got 0"),
    ("cell", "-1", "cell size (m) must be > 0, got -1"),
    ("cell", "nan", "cell size (m) must be a finite number, got 'nan'"),
    ("cell", "", "cell size (m) must be a number, got ''"),
    ("ny", "0", "rows ny must be 1..4000 cells, got 0"),
    ("nx", "1000000", "columns nx must be 1..4000 cells, got 1000000"),
    ("nx", "wide", "columns nx must be a whole number of cells, got 'wide'"),
    ("x0", "west", "origin x0 (m) must be a number, got 'west'"),
])
def test_new_map_dialog_refuses_bad_input_on_enter_and_keeps_the_map(qtbot, feed, field,
                                                                     typed, why):
    ctx = MonitorContext(MonitorSession(), None)
    view = MapsView(ctx)
    qtbot.addWidget(view)
    view.show()
    before = (view.live_map, view.live_settings)
    dlg = view.open_new_map_dialog()
    qtbot.waitExposed(dlg)
    _type(qtbot, dlg.fields[field].edit, typed)
    assert dlg.isVisible() and dlg.result() == 0
    assert dlg.fields[field].error.isVisible()
    assert dlg.fields[field].error.text() == why
    assert (view.live_map, view.live_settings) == before and dlg.map is None
    dlg.reject()


def test_registers_and_log_take_no_typed_input_and_enter_changes_nothing(qtbot, window,
                                                                        fake_bridge):
    """The registers view and the log have nothing to type in (so nothing to refuse);
    Enter in the log neither closes it nor presses Clear."""
    regs = RegistersView(MonitorContext(MonitorSession(), bridge=fake_bridge))
    qtbot.addWidget(regs)

    def editable(w):
        return w.findChildren(QLineEdit) + w.findChildren(QAbstractSpinBox)

    assert not editable(regs)
    window.open_log_dialog()
    log = window.findChild(LogDialog)
    qtbot.waitExposed(log)
    log.poll()
    lines = log.lines()
    assert lines and not editable(log)
    for target in (log.text, log):
        target.setFocus()
        qtbot.keyClick(target, Qt.Key_Return)
        assert log.isVisible() and log.lines()[: len(lines)] == lines


def test_debug_legends_sit_outside_the_plotted_data(qtbot, feed):
    ctx = MonitorContext(MonitorSession(), None)
    view = DebugView(ctx)
    qtbot.addWidget(view)
    view.resize(1024, 700)
    view.show()
    qtbot.waitExposed(view)
    from mm_pc.monitor.model.sim_feed import sim_replies

    for r in list(sim_replies("figure_eight", 20, seconds=1))[:5]:
        view.add_manual_reply(r)
    view.refresh()
    qtbot.wait(20)
    legend = view.request_legend
    assert [label.text for _sample, label in legend.items] == [
        f"{d.rsplit('/', 1)[-1]} {a}" for d in (D0, D1) for a in ("dX", "dY")
    ]
    for lg, plot in ((view.request_legend, view.request_plot),
                     (view.poll_legend, view.poll_plot)):
        data = plot.getViewBox().sceneBoundingRect()
        assert not lg.sceneBoundingRect().intersects(data), (lg.sceneBoundingRect(), data)
    assert isinstance(legend, pg.LegendItem)
