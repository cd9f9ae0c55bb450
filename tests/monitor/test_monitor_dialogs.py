"""The monitor's dialogs and debug/health views: median filters, robot geometry, health
(diagnostics, residual), debug (manual samples, 1 kHz polls). The calibration wizard's
tests: test_monitor_calibration_wizard.py.

Offline tests feed simulated replies through ``ctx.on_reply`` (the same path
live replies take) and emit a constructed-but-not-started RosBridge's real
signals. One ``ros`` test drives the debug view against a real mm-beagle sim
node.
"""

from __future__ import annotations

import math
import time
from dataclasses import replace

import numpy as np
import pytest

pytest.importorskip("pytestqt")
from PySide6.QtCore import SIGNAL, Qt
from PySide6.QtGui import QImage

from mm_pc.core.calibration import Calibration, SensorCalibration
from mm_pc.core.frames import counts_to_m
from mm_pc.core.geometry import DEFAULT_MOUNTS, SensorMount
from mm_pc.core.sensor_data import Reading, Reply
from mm_pc.monitor.context import MonitorConfig, MonitorContext
from mm_pc.monitor.model.session import MonitorSession
from mm_pc.monitor.model.sim_feed import DEFAULT_DEVICES, sim_replies
from mm_pc.monitor.ros_bridge import RosBridge
from mm_pc.monitor.widgets.calibration_panel import CalibrationPanel
from mm_pc.monitor.widgets.debug_view import DebugView
from mm_pc.monitor.widgets.filter_dialog import FilterDialog
from mm_pc.monitor.widgets.geometry_dialog import GeometryDialog
from mm_pc.monitor.widgets.health_view import LEVEL_COLOURS, HealthView

D0, D1 = DEFAULT_DEVICES
WINDOW_MSG = r"median window must be an integer number of samples in 1\.\.999"


@pytest.fixture
def ctx(tmp_path):
    config = MonitorConfig(calibration_file=tmp_path / "cfg" / "calibration.yaml")
    return MonitorContext(MonitorSession(), None, config)


def assert_shows_content(img: QImage, name: str, min_colours: int = 12) -> None:
    """A screenshot shows more than a blank frame."""
    assert img.width() > 300 and img.height() > 200
    colours = {
        img.pixel(x, y)
        for x in range(0, img.width(), 3)
        for y in range(0, img.height(), 3)
    }
    assert len(colours) > min_colours, f"{name}: only {len(colours)} colours"


def hand_reply(seq: int, totals: list[tuple[float, float]], devices=DEFAULT_DEVICES) -> Reply:
    """A reply with given totals (m) at 1 kHz poll ``seq``."""
    stamp = 1_700_000_000_000_000_000 + seq * 1_000_000
    return Reply(
        tuple(
            Reading(d, stamp, seq, x, y, cpi=1600, samples=10, interval=0.01)
            for d, (x, y) in zip(devices, totals, strict=True)
        )
    )


# -- median filter dialog --------------------------------------------------------------------


def filter_state(session):
    return {d: (f.window, f.filter_x, f.filter_y) for d, f in session.filters.items()}


def test_filter_dialog_refuses_bad_windows(qtbot, ctx):
    ctx.on_reply(next(sim_replies("straight", 50)))
    dlg = FilterDialog(ctx)
    qtbot.addWidget(dlg)
    before = filter_state(ctx.session)
    row = dlg.rows[D0]
    for bad in ("abc", "0", "1000", "2.5", "", "nan"):
        row.window.setText(bad)
        assert not dlg.apply_all()
        assert filter_state(ctx.session) == before, bad
        assert not row.error.isHidden()
        assert row.error.text().startswith(f"{D0}: median window "
                                           + ("is empty: type" if bad == "" else "must be"))
        assert "an integer number of samples in 1..999" in row.error.text()
        assert row.error.text().endswith("nothing changed")
        # live apply by a check box is refused too, and the box goes back
        row.fx.setChecked(True)
        assert not row.fx.isChecked()
        assert filter_state(ctx.session) == before
    assert "not applied" in dlg.status.text()
    # the wrapped message shows whole in a narrow dialog (it was cut off)
    dlg.resize(360, 200)
    dlg.show()
    qtbot.waitExposed(dlg)
    row.window.setText("abc")
    assert not dlg.apply_all()
    qtbot.wait(10)
    assert row.error.height() >= row.error.heightForWidth(row.error.width())
    assert row.error.geometry().bottom() <= dlg._grid_host.height()
    assert "apply at once" not in dlg.note.text() and "Apply applies every row" in dlg.note.text()
    with pytest.raises(ValueError, match=WINDOW_MSG):
        from mm_pc.monitor.widgets.filter_dialog import parse_window

        parse_window("1000")


@pytest.mark.screenshot
def test_filter_dialog_applies_x_and_y_to_the_right_axes(qtbot, ctx, screenshot, feed):
    replies = list(sim_replies("figure_eight", 50, seconds=6))
    dlg = FilterDialog(ctx)  # opened before any data: rows come with the sensors
    qtbot.addWidget(dlg)
    assert dlg.rows == {} and not dlg.apply_button.isEnabled()
    ctx.on_reply(replies[0])
    assert set(dlg.rows) == {D0, D1}
    r0, r1 = dlg.rows[D0], dlg.rows[D1]
    r0.window.setText("7")
    r1.window.setText("3")
    r0.fx.setChecked(True)  # live: X box -> filter_x of sensor 0
    assert filter_state(ctx.session)[D0] == (7, True, False)
    r1.fy.setChecked(True)
    assert filter_state(ctx.session)[D1] == (3, False, True)
    r1.window.setText("9")
    assert dlg.apply_all()
    assert filter_state(ctx.session) == {D0: (7, True, False), D1: (9, False, True)}
    # the filters act on the named axis only
    feed(ctx, replies[1:])
    h = ctx.session.history
    assert np.array_equal(h.column("s0_dy"), h.column("s0_raw_dy"))
    assert not np.array_equal(h.column("s0_dx"), h.column("s0_raw_dx"))
    assert np.array_equal(h.column("s1_dx"), h.column("s1_raw_dx"))
    assert not np.array_equal(h.column("s1_dy"), h.column("s1_raw_dy"))
    assert_shows_content(screenshot(dlg, "filters.png"), "filters.png", min_colours=5)
    qtbot.mouseClick(dlg.clear_button, Qt.LeftButton)
    assert filter_state(ctx.session) == {D0: (7, False, False), D1: (9, False, False)}
    assert not r0.fx.isChecked() and not r1.fy.isChecked()


# -- geometry dialog -----------------------------------------------------------------------------


def test_geometry_dialog_refuses_bad_input_and_changes_nothing(qtbot, ctx):
    ctx.on_reply(next(sim_replies("straight", 50)))
    dlg = GeometryDialog(ctx)
    qtbot.addWidget(dlg)
    session = ctx.session
    before = (session.mounts, session.sensor, session.method, session.odometry)
    emitted = []
    ctx.odometry_changed.connect(lambda: emitted.append(1))
    cases = [
        (dlg.rows[0].x, "abc", rf"{D0} x \(cm\) must be a number, got 'abc'"),
        (dlg.rows[1].y, "nan", rf"{D1} y \(cm\) must be a finite number, got 'nan'"),
        (dlg.rows[0].yaw, "", rf"{D0} yaw \(deg\) must be a number, got ''"),
        (dlg.axis_edit, "0", r"axle length must be > 0 and <= 300 cm, got '0'"),
        (dlg.axis_edit, "301", r"axle length must be > 0 and <= 300 cm, got '301'"),
        (dlg.rows[1].y, "999", rf"{D1} y \(cm\) must be within ±100, got 999"),
        (dlg.rows[0].x, "-100.5", rf"{D0} x \(cm\) must be within ±100, got -100.5"),
        (dlg.rows[0].yaw, "361", rf"{D0} yaw \(deg\) must be within ±360, got 361"),
        (dlg.rows[0].x, "0", r"sensor 0 at base_link \(0.0 m, -0.0395 m\) lies on the axle line"),
    ]
    for edit, text, msg in cases:
        dlg.load_from_session()
        edit.setText(text)
        assert not dlg.apply()
        assert not dlg.error.isHidden()
        assert dlg.error.text().startswith("not applied: ")
        import re

        assert re.search(msg, dlg.error.text()), dlg.error.text()
        assert (session.mounts, session.sensor, session.method, session.odometry) == before
    assert emitted == []


def test_geometry_dialog_applies_good_input_and_round_trips_yaml(qtbot, ctx, tmp_path):
    ctx.on_reply(next(sim_replies("straight", 50)))
    dlg = GeometryDialog(ctx)
    qtbot.addWidget(dlg)
    dlg.rows[0].x.setText("6")
    dlg.rows[0].y.setText("-4")
    dlg.rows[0].yaw.setText("1.5")
    dlg.axis_edit.setText("10")
    dlg.sensor_box.setCurrentIndex(1)
    with qtbot.waitSignal(ctx.odometry_changed, timeout=1000):
        assert dlg.apply()
    assert ctx.session.mounts == (SensorMount(0.06, -0.04, math.radians(1.5)), DEFAULT_MOUNTS[1])
    assert ctx.session.sensor == 1
    assert ctx.session.odometry.mounts == ctx.session.mounts
    assert ctx.robot_geometry.axis_length == pytest.approx(0.10)
    path = tmp_path / "geometry.yaml"
    assert dlg.save(path)
    dlg2 = GeometryDialog(ctx)
    qtbot.addWidget(dlg2)
    dlg2.rows[0].x.setText("1")  # overwritten by the load
    assert dlg2.load(path)
    assert dlg2.read_geometry() == dlg.read_geometry()
    path.write_text("version: 1\nmounts: []\n")
    assert not dlg2.load(path)
    assert "'mounts' must be a non-empty list" in dlg2.error.text()


# -- health view -----------------------------------------------------------------------------------


def diag(level: int, late: int, state: str = "up") -> dict:
    return {
        "level": level, "message": "up" if level == 0 else "SPI errors", "state": state,
        "polls": "5000", "achieved_rate_hz": "999.8", "period_p50_us": "1000",
        "period_p99_us": "1210", "late_polls": str(late), "overruns": "0",
        "spi_errors": str(3 * level), "lift_events": "2", "overflows": "0", "cpi": "1600",
        "reinits": "0", "poller_cpu_percent": "4.2", "last_error": "" if level == 0 else "CRC",
    }


@pytest.mark.screenshot
def test_health_view_shows_diagnostics_residual_and_counters(qtbot, ctx, screenshot, feed):
    bridge = RosBridge()  # constructed, never started: its real signals, no ROS
    ctx.bridge = bridge
    # the monitor believes sensor 1 sits 1 cm further forward than it does: a residual
    # while turning (with the right geometry the simulated counts fit exactly)
    wrong = (DEFAULT_MOUNTS[0], SensorMount(0.059, 0.0395))
    ctx.session = MonitorSession(mounts=wrong, method="two-sensor")
    view = HealthView(ctx)
    qtbot.addWidget(view)
    view.resize(1000, 700)
    bridge.diagnostics_received.emit({D0: diag(0, 4), D1: diag(1, 9)})
    t = view.table
    assert t.columnCount() == 2
    assert [t.horizontalHeaderItem(c).text() for c in range(2)] == [D0, D1]
    names = [t.verticalHeaderItem(r).text() for r in range(t.rowCount())]
    col1 = dict(zip(names, (t.item(r, 1).text() for r in range(t.rowCount())), strict=True))
    assert col1["Status"] == "WARN" and col1["Late polls"] == "9" and col1["Bus errors"] == "3"
    assert col1["Worst gap (µs)"] == "1210" and col1["Last error"] == "CRC"
    for r in range(t.rowCount()):  # every quantity explains itself in plain words
        assert len(t.verticalHeaderItem(r).toolTip()) > 20
        assert t.verticalHeaderItem(r).toolTip() in t.item(r, 1).toolTip()
    assert "CRC" in t.item(names.index("Last error"), 1).toolTip()
    assert t.item(0, 0).background().color().name() == LEVEL_COLOURS[0][1]
    assert t.item(5, 1).background().color().name() == LEVEL_COLOURS[1][1]
    bridge.diagnostics_received.emit({D0: diag(2, 5, state="down")})  # one sensor updates
    assert t.item(1, 0).text() == "down" and t.item(0, 0).text() == "ERROR"
    # the table fits a narrow view: the sensors' columns share the width, none runs off
    view.resize(420, 700)
    view.show()
    qtbot.waitExposed(view)
    assert t.horizontalHeader().length() <= t.viewport().width() + 1
    assert t.horizontalScrollBar().maximum() == 0

    replies = list(sim_replies("figure_eight", 50, seconds=8))
    # the simulated node reports no lifts: mark a few polls of sensor 1 as lifted
    replies = [
        Reply((r.readings[0], replace(r.readings[1], lift_events=3)), r.received_s, r.rtt_s)
        if i % 37 == 36 else r
        for i, r in enumerate(replies)
    ]
    feed(ctx, replies)
    ctx.on_reply(Reply(replies[-1].readings[:1]))  # incomplete
    view.refresh()
    h = ctx.session.history
    x, y = view.residual_data()
    assert np.array_equal(x, h.column("t"))
    np.testing.assert_allclose(y, h.column("residual"), rtol=1e-12)
    assert np.all(np.isfinite(y)) and 1e-5 < y.max() < 1e-2  # 0.01..10 mm
    assert "two sensors disagree" in view.residual_note.text()
    _, ly = view.lift_curves[1].getOriginalDataset()
    assert np.array_equal(ly, h.column("s1_lifts")) and ly.sum() == 3 * 10
    s = ctx.session.stats
    assert f"{s.replies} replies received, {s.used} used for the pose" in view.session_label.text()
    assert "1 missing a sensor" in view.session_label.text()
    assert "baselines" not in view.session_label.text()
    bridge.stats_updated.emit(bridge.stats())
    assert "0 requests unanswered in time, 0 requests not sent" in view.bridge_label.text()
    assert "skipped" not in view.bridge_label.text()
    assert "still unanswered" in view.bridge_label.toolTip()
    # one unit per quantity: the residual is drawn in mm and the axis says mm, no SI prefix
    _, drawn = view.residual_curve.getOriginalDataset()
    assert np.array_equal(drawn, h.column("residual") * 1e3)
    axis = view.residual_plot.getAxis("left")
    assert axis.labelText == "residual (mm)" and axis.labelString().count("(") == 1
    assert view.lift_plot.legend is None and D1 in view.lift_plot.titleLabel.text
    lift_axis = view.lift_plot.getAxis("left")
    assert lift_axis.autoSIPrefixScale == 1.0 and "x0.001" not in lift_axis.labelString()
    assert view.lift_plot.viewRange()[1][0] == pytest.approx(-0.05 * 3, abs=0.2)
    # the picture at a width the tab has (at 420 px, outside the window's scrolling page,
    # the labels were drawn over the table)
    view.resize(1000, 760)
    qtbot.wait(10)
    assert_shows_content(screenshot(view, "health.png"), "health.png")

    ctx.session.configure_odometry(method="exact")
    ctx.odometry_changed.emit()
    feed(ctx, sim_replies("figure_eight", 50, seconds=1, start_ns=1_800_000_000_000_000_000))
    view.refresh()
    assert "only computed by the two-sensor method" in view.residual_note.text()
    assert np.isnan(view.residual_data()[1][-1])
    version = h.version
    view.refresh()  # nothing changed: nothing redrawn
    assert h.version == version


def test_health_view_thins_a_long_history(qtbot, ctx, feed):
    ctx.session.configure_odometry(method="two-sensor")
    feed(ctx, sim_replies("figure_eight", 100, seconds=1))
    h = ctx.session.history
    rows = np.resize(h.tail(len(h)), (100_000, len(h.columns)))
    rows[:, h.index["t"]] = 1.0 + np.arange(1, 100_001) / 100  # 1000 s more at 100 Hz
    rows[:, h.index["s0_lifts"]] = 0
    rows[54_321, h.index["s0_lifts"]] = 5  # at t = 544.22 s
    h.extend(rows)
    view = HealthView(ctx)
    qtbot.addWidget(view)
    view.refresh()
    x, y = view.lift_curves[0].getOriginalDataset()
    assert len(x) <= 2001 and y.max() == 5  # the single lift survives the thinning
    cache = view._caches["s0_lifts"]
    assert cache.rows_read == len(h)  # the first draw reads every row
    for _ in range(10):
        h.append(rows[-1])
        view._last_plot = 0.0
        view.refresh()
        assert cache.rows_read <= 2 * cache.size  # the new row and its partial bucket only
    view.residual_plot.setXRange(544.0, 545.0, padding=0)  # zoom in: every row again
    view._last_plot = 0.0
    view.refresh()
    x, y = view.lift_curves[0].getOriginalDataset()
    assert x[0] <= 544.0 and x[-1] >= 545.0 and len(x) < 105 and np.allclose(np.diff(x), 0.01)
    assert y[np.argmin(abs(x - 544.22))] == 5 and y.sum() == 5


# -- debug view ---------------------------------------------------------------------------------


def fake_polls(n: int, first_seq: int):
    from mm_interfaces.srv import GetSamples

    k = np.arange(n)
    return GetSamples.Response(
        success=True, first_seq=first_seq, next_seq=first_seq + n, dropped=0, cpi=1600,
        stamp_ns=(1_700_000_000_000_000_000 + (first_seq + k) * 1_000_000).tolist(),
        dx=(np.round(3 * np.sin(k / 40))).astype(int).tolist(),
        dy=(12 + (k % 3)).tolist(), status=[0x80] * n,
        flags=[2] * (n - 3) + [34, 34, 3], quality=[90] * (n - 3) + [4, 4, 0],
    )


def test_debug_view_without_bridge_is_disabled(qtbot, ctx):
    view = DebugView(ctx)
    qtbot.addWidget(view)
    assert not view.pause_button.isEnabled() and not view.request_button.isEnabled()
    assert "offline" in view.state.text()
    view.request_sample()  # nothing to ask: nothing happens
    assert view.table.rowCount() == 0


def test_debug_view_listens_to_replies_only_while_a_manual_request_waits(qtbot, ctx):
    """No slot per reply at 500 Hz: the debug view connects to the bridge's data signals
    when a manual request goes out and disconnects with its reply (or its failure)."""
    pytest.importorskip("mm_interfaces")
    bridge = RosBridge()  # not started
    ctx.bridge = bridge
    view = DebugView(ctx)
    qtbot.addWidget(view)
    data, failed = SIGNAL("data_received(PyObject)"), SIGNAL("data_failed(QString)")
    assert bridge.receivers(data) == bridge.receivers(failed) == 0
    replies = list(sim_replies("figure_eight", 20, seconds=1))
    view.request_sample()
    view.request_sample()  # pressed twice before the reply: still one listener
    assert bridge.receivers(data) == bridge.receivers(failed) == 1
    bridge.data_received.emit([replies[0]])
    assert view.table.rowCount() == 1
    assert bridge.receivers(data) == bridge.receivers(failed) == 0
    bridge.data_received.emit([replies[1]])  # a periodic reply: not a row
    assert view.table.rowCount() == 1
    view.request_sample()
    bridge.data_failed.emit("no reply within 2 s")
    assert "manual request failed: no reply within 2 s" in view.error.text()
    assert bridge.receivers(data) == bridge.receivers(failed) == 0


@pytest.mark.screenshot
def test_debug_view_lists_manual_replies_and_single_polls(qtbot, ctx, screenshot):
    pytest.importorskip("mm_interfaces")
    bridge = RosBridge()  # not started
    ctx.bridge = bridge
    bridge.data_received.connect(ctx.on_replies)  # as the main window does
    asked = []
    bridge.request_samples = lambda dev, since_seq=0, max_samples=0: asked.append(
        (dev, since_seq, max_samples)
    )
    view = DebugView(ctx)
    qtbot.addWidget(view)
    view.resize(1100, 750)
    replies = list(sim_replies("figure_eight", 20, seconds=3))
    bridge.data_received.emit([replies[0]])  # periodic: not a row
    assert view.fetch_buttons.keys() == {D0, D1}
    qtbot.mouseClick(view.pause_button, Qt.LeftButton)
    assert bridge.polling is False and view.pause_button.text() == "Resume polling"
    manual = []
    for r in replies[1:]:
        if len(manual) < 12 and r is not replies[-1]:
            qtbot.mouseClick(view.request_button, Qt.LeftButton)
            manual.append(r)
        bridge.data_received.emit([r])
    assert view.table.rowCount() == len(manual) == 12
    assert len(ctx.session.history) == len(replies) - 1  # every reply processed
    r = manual[3].by_id()
    cells = [view.table.item(3, c).text() for c in range(1, 7)]
    assert cells == [
        str(r[D0].x_counts), str(r[D0].y_counts),
        f"{counts_to_m(r[D0].x_counts, 1600) * 1e3:.3f}",
        f"{counts_to_m(r[D0].y_counts, 1600) * 1e3:.3f}",
        str(r[D0].samples), f"{r[D0].interval * 1e3:.1f}",
    ]
    view.refresh()
    x, y = view.request_data(D1, "dY")
    assert np.array_equal(x, np.arange(1, 13))
    assert np.array_equal(y, [m.by_id()[D1].y_counts for m in manual])

    qtbot.mouseClick(view.fetch_buttons[D0], Qt.LeftButton)
    assert asked == [(D0, 0, 2000)]
    bridge.samples_received.emit(D0, fake_polls(300, 4000))
    px, py = view.poll_curves[(D0, "dY")].getOriginalDataset()
    assert len(py) == 300 and py[0] == 12 and px[1] == pytest.approx(0.001)
    assert "300 polls (seq 4000..4299)" in view.polls_label.text()
    assert "1 lifted" in view.polls_label.text()
    assert "2 below the chip's quality threshold" in view.polls_label.text()
    qtbot.mouseClick(view.fetch_buttons[D0], Qt.LeftButton)
    assert asked[-1] == (D0, 4300, 2000)  # goes on after the polls already shown
    bridge.samples_received.emit(D1, fake_polls(250, 4100))
    bridge.samples_failed.emit(D1, "no such sensor")
    assert "no such sensor" in view.error.text()
    view.error.hide()
    assert_shows_content(screenshot(view, "debug.png"), "debug.png")
    bridge.set_polling(True)  # resumed elsewhere: the button follows
    view.refresh()
    assert not view.pause_button.isChecked()


# -- against the real node -------------------------------------------------------------------------


#: the module-wide mm-beagle of tests/monitor/conftest.py
BEAGLE_PARAMS = {"backend": "sim", "sim_trajectory": "straight", "diagnostics_period": 0.2}


@pytest.mark.ros
def test_manual_request_against_the_node_loses_no_counts(qtbot, beagle_node, tmp_path):
    bridge = RosBridge(rate_hz=50.0)
    ctx = MonitorContext(MonitorSession(), bridge, MonitorConfig(calibration_file=tmp_path / "c"))
    replies: list[Reply] = []
    bridge.data_received.connect(replies.extend)
    bridge.data_received.connect(ctx.on_replies)
    view = DebugView(ctx)
    health = HealthView(ctx)
    qtbot.addWidget(view)
    qtbot.addWidget(health)
    bridge.start()
    try:
        qtbot.waitUntil(
            lambda: ctx.session.history is not None and len(ctx.session.history) >= 10,
            timeout=20000,
        )
        qtbot.waitUntil(lambda: health.table.columnCount() == 2, timeout=5000)
        qtbot.mouseClick(view.pause_button, Qt.LeftButton)
        assert not bridge.polling
        qtbot.wait(300)  # a request in flight lands
        n_replies, x_before = len(replies), ctx.session.pose.x
        qtbot.wait(300)
        assert len(replies) == n_replies  # paused: nobody asks
        qtbot.mouseClick(view.request_button, Qt.LeftButton)
        qtbot.waitUntil(lambda: view.table.rowCount() == 1, timeout=5000)
        assert len(replies) == n_replies + 1
        last = replies[-1].by_id()
        # the row is the manual reply: it covers the whole pause (>= 0.3 s of 1 kHz polls)
        assert view.table.item(0, 1).text() == str(last[ctx.session.devices[0]].x_counts)
        assert int(view.table.item(0, 5).text()) >= 300
        assert ctx.session.pose.x > x_before  # the map moved
        first = replies[0].by_id()
        h = ctx.session.history
        for k, dev in enumerate(ctx.session.devices):
            monitor_y = float(np.sum(h.column(f"s{k}_raw_dy")))
            monitor_x = float(np.sum(h.column(f"s{k}_raw_dx")))
            assert monitor_y == pytest.approx(last[dev].y_total - first[dev].y_total, abs=1e-9)
            assert monitor_x == pytest.approx(last[dev].x_total - first[dev].x_total, abs=1e-9)
            assert monitor_y > 0.05
        dev0 = ctx.session.devices[0]
        qtbot.mouseClick(view.fetch_buttons[dev0], Qt.LeftButton)
        qtbot.waitUntil(lambda: dev0 in view.polls, timeout=5000)
        res = view.polls[dev0]
        assert 0 < len(res.dy) <= 2000 and view.next_seq[dev0] == res.next_seq
        assert health.diagnostics[dev0]["state"] == "up"
    finally:
        bridge.stop()
        time.sleep(0.05)


def test_a_bad_calibration_file_is_one_message_naming_it_and_changes_nothing(qtbot, ctx, tmp_path):
    old = Calibration({D0: SensorCalibration(0.01, 0.5, 1.0)})
    ctx.set_calibration(old, "before.yaml")
    panel = CalibrationPanel(ctx)
    qtbot.addWidget(panel)
    shown = panel.label.text()
    bad = tmp_path / "bad.yaml"
    bad.write_text("version: 2\nsensors: {/dev/spidev1.0: {angle_offset_rad: x}}\n")
    assert not ctx.load_calibration(bad)
    assert ctx.calibration_error.startswith(f"calibration not loaded: calibration file {bad}: ")
    assert ctx.calibration_error.count(str(bad)) == 1
    assert ctx.session.calibration is old and ctx.calibration_source == "before.yaml"
    assert panel.label.text() == shown and "before.yaml" in shown
