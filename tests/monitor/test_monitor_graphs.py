"""The Graphs tab never misleads (issue 29 items 4 and 5): a flat speed at 500 Hz, outages
as breaks, one colour per sensor, and the plot habits (wheel zooms time, a modifier the
value axis, double-click resets, a hover readout, linked time axes).

Offscreen Qt, the real GraphsView fed the simulated replies through the real session.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

pytest.importorskip("PySide6")

from mm_pc.monitor.context import MonitorContext
from mm_pc.monitor.model.session import SPEED_WINDOW_S, MonitorSession
from mm_pc.monitor.model.sim_feed import sim_replies
from mm_pc.monitor.widgets.graphs_view import GraphsView

SPEED = 0.22  # m/s, what the report drove


def jittered(replies, jitter_ns: int, seed: int = 1):
    """The replies with each sensor's stamp moved by up to +-``jitter_ns`` (uniform, each
    sensor its own) from the time its totals were read: what a real node's reply at 500 Hz
    looks like to one reply's dx/dt (the sensors' newest polls a poll apart: the second
    sensor's dx/dt swung 0..606 mm/s at 200 in a recording of the sim node)."""
    rng = np.random.default_rng(seed)
    first = True
    for r in replies:
        if first:  # the baseline
            first = False
            yield r
            continue
        yield dataclasses.replace(r, readings=tuple(
            dataclasses.replace(x, stamp_ns=x.stamp_ns + int(rng.integers(-jitter_ns,
                                                                          jitter_ns + 1)))
            for x in r.readings))


def graphs(qtbot, ctx) -> GraphsView:
    view = GraphsView(ctx)
    qtbot.addWidget(view)
    view.resize(1000, 600)
    view.show()
    return view


def test_the_speed_at_500_hz_stays_flat_with_jittered_stamps(qtbot, fake_bridge, feed):
    ctx = MonitorContext(MonitorSession(), fake_bridge)
    replies = list(jittered(sim_replies("straight", 500.0, 2.0, speed=SPEED), 500_000))
    t = np.array([r.readings[0].stamp_ns for r in replies[1:]], float)
    d = np.diff([r.readings[0].stamp_ns for r in replies]) / 1e6
    assert d.min() <= 1.2 and d.max() >= 2.8  # a reply's stamps: 1..3 ms apart, not 2
    feed(ctx, replies)
    view = graphs(qtbot, ctx)
    view.window_box.setValue(3)
    view.refresh()
    for k in range(2):
        vx = view.curves[(k, "speed", "x")].getData()[1]
        vy = view.curves[(k, "speed", "y")].getData()[1]
        assert len(vy) == len(t)  # one point per reply (no min/max buckets at 1000 rows)
        speed = np.hypot(vx, vy)  # mm/s
        # the first SPEED_WINDOW_S averages fewer replies; after that within 4 % of the truth
        settled = speed[int(SPEED_WINDOW_S * 500):]
        assert settled.min() > 0.96 * SPEED * 1e3 and settled.max() < 1.04 * SPEED * 1e3, (
            settled.min(), settled.max())
    # what one reply's dx/dt (the row's dt: sensor 0's stamps) would have drawn
    hist = ctx.session.history
    for k in range(2):
        one = np.hypot(hist.column(f"s{k}_dx"), hist.column(f"s{k}_dy")) / hist.column("dt")
        assert one.max() > 1.4 * SPEED and one.min() < 0.75 * SPEED


def test_the_speed_at_15_hz_is_each_reply_s_own(fake_bridge, feed):
    ctx = MonitorContext(MonitorSession(), fake_bridge)
    feed(ctx, rate_hz=15.0, seconds=2.0, name="straight")
    hist = ctx.session.history
    np.testing.assert_allclose(hist.column("s0_vy"), hist.column("s0_dy") / hist.column("dt"))


def test_an_outage_is_a_break_in_every_graph(qtbot, fake_bridge, feed):
    ctx = MonitorContext(MonitorSession(), fake_bridge)
    start = 1_700_000_000_000_000_000
    feed(ctx, rate_hz=50.0, seconds=2.0, start_ns=start)
    feed(ctx, rate_hz=50.0, seconds=2.0, start_ns=start + 10_000_000_000)  # 8 s without rows
    view = graphs(qtbot, ctx)
    view.window_box.setValue(20)
    view.refresh()
    t = ctx.session.history.column("t")
    gap = np.flatnonzero(np.diff(t) > 5.0)
    assert len(gap) == 1
    for (_k, _key, _axis), curve in view.curves.items():
        x, y = curve.getData()
        nan = np.flatnonzero(np.isnan(y))
        assert len(nan) == 1 and t[gap[0]] < x[nan[0]] < t[gap[0] + 1]
        assert np.isfinite(np.delete(y, nan)).all() and len(x) == len(t) + 1
        assert curve.opts["connect"] == "finite"
        path = curve.curve.getPath()  # two strokes: drawn, a break, drawn again
        starts = sum(path.elementAt(i).isMoveTo() for i in range(path.elementCount()))
        assert starts == 2


def test_one_colour_per_sensor_everywhere(qtbot, tmp_path):
    """Every pen drawing a sensor's data takes that sensor's colour from style.py: the map's
    paths and axes, the dials, the graphs (X the colour, Y its darker shade) and Health's
    lifted-polls and quality curves with their legends."""
    pytest.importorskip("rclpy")
    from PySide6.QtGui import QColor

    from mm_pc.monitor.context import MonitorConfig
    from mm_pc.monitor.main_window import MainWindow
    from mm_pc.monitor.ros_bridge import RosBridge
    from mm_pc.monitor.widgets.style import sensor_axis_colour, sensor_colour

    bridge = RosBridge("/mm_beagle", 100.0, node_name="mm_monitor_graphs_colours")
    config = MonitorConfig(rate_hz=100.0, calibration_file=tmp_path / "cal.yaml")
    window = MainWindow(MonitorContext(MonitorSession(), bridge, config))
    qtbot.addWidget(window)
    window._on_state("connected")
    for r in sim_replies("figure_eight", 50.0, 1.0):
        bridge.data_received.emit([r])
    window.frame()
    for view in window.views.values():
        if hasattr(view, "refresh"):
            view.refresh()

    def name(pen) -> str:
        return pen.color().name()

    colours = [sensor_colour(k) for k in range(2)]
    assert len(set(colours)) == 2
    graphs_view = window.views["Graphs"]
    for (k, _key, axis), curve in graphs_view.curves.items():
        assert name(curve.opts["pen"]) == sensor_axis_colour(k, axis)
        assert abs(QColor(name(curve.opts["pen"])).hue() - QColor(colours[k]).hue()) <= 2
    assert len(graphs_view.curves) == 8
    legend = graphs_view.legend.text()
    assert all(sensor_axis_colour(k, a) in legend for k in range(2) for a in "xy")
    for k in range(2):
        assert colours[k] in graphs_view.plots[(k, "speed")].titleLabel.text
    health = window.views["Health"]
    assert [name(c.opts["pen"]) for c in health.lift_curves] == colours
    assert all(c in health.lift_plot.titleLabel.text for c in colours)
    assert name(health.residual_curve.opts["pen"]) not in colours  # the robot's, no sensor's
    map_view = window.views["Map"]
    for k in range(2):
        assert name(map_view.paths[k].pen) == colours[k]
        assert name(map_view.sensor_items[k]["axes"]._pen) == colours[k]
    assert [d.colour.name() for d in window.direction_panel.widgets] == colours


# -- the mouse: real wheel, double-click and move events on the plots' canvas ---------------

def _at(canvas, plot):
    """The canvas viewport's point at the middle of ``plot``'s data area."""
    rect = plot.getViewBox().sceneBoundingRect()
    return canvas.mapFromScene(rect.center())


def wheel(canvas, point, delta: int = 120, modifiers=None) -> None:
    from PySide6.QtCore import QPoint, QPointF, Qt
    from PySide6.QtGui import QWheelEvent
    from PySide6.QtWidgets import QApplication

    vp = canvas.viewport()
    mods = Qt.KeyboardModifier.NoModifier if modifiers is None else modifiers
    ev = QWheelEvent(QPointF(point), QPointF(vp.mapToGlobal(point)), QPoint(0, 0),
                     QPoint(0, delta), Qt.MouseButton.NoButton, mods,
                     Qt.ScrollPhase.NoScrollPhase, False)
    QApplication.sendEvent(vp, ev)


def double_click(canvas, point) -> None:
    from PySide6.QtCore import Qt
    from PySide6.QtTest import QTest

    vp, left = canvas.viewport(), Qt.MouseButton.LeftButton
    # what a window system sends: press, release, double-click, release (QTest's
    # mouseDClick alone sends only the double-click; pyqtgraph acts on the release)
    QTest.mouseClick(vp, left, pos=point)
    QTest.mouseDClick(vp, left, pos=point)
    QTest.mouseRelease(vp, left, pos=point)


def x_range(plot):
    return tuple(plot.getViewBox().viewRange()[0])


def y_range(plot):
    return tuple(plot.getViewBox().viewRange()[1])


def test_the_wheel_zooms_time_a_modifier_values_double_click_resets(qtbot, fake_bridge, feed):
    from PySide6.QtCore import Qt

    ctx = MonitorContext(MonitorSession(), fake_bridge)
    feed(ctx, rate_hz=50.0, seconds=20.0)
    view = graphs(qtbot, ctx)
    qtbot.waitExposed(view)
    view.refresh()
    speed0, disp1 = view.plots[(0, "speed")], view.plots[(1, "disp")]
    assert view.window_s == 10
    x0 = x_range(speed0)
    assert x0[1] - x0[0] == pytest.approx(11.0)  # the window and its 10 % lead
    for plot in view.plots.values():  # time axes linked, the plots of a column lined up
        assert x_range(plot) == pytest.approx(x0)
    left = {k: {p.getViewBox().sceneBoundingRect().left() for (kk, _), p in view.plots.items()
                if kk == k} for k in range(2)}
    assert all(len(v) == 1 for v in left.values()), left

    # live: a notch away zooms time in by changing the window (x0.74): still live
    wheel(view.canvas, _at(view.canvas, speed0), 120)
    assert view.window_s == 7 and not view.paused
    x1 = x_range(speed0)
    assert x1[1] - x1[0] == pytest.approx(7.7) and x1[1] == pytest.approx(x0[1] - 0.3, abs=0.5)
    _x, vy = view.curves[(0, "speed", "y")].getData()  # the value axis holds the window's data
    assert y_range(speed0)[0] < np.nanmin(vy) and np.nanmax(vy) < y_range(speed0)[1]
    assert x_range(disp1) == pytest.approx(x1)

    # Ctrl + wheel zooms the value axis only (around the mouse), and holds it while live
    for mod in (Qt.KeyboardModifier.ControlModifier, Qt.KeyboardModifier.ShiftModifier):
        before = y_range(speed0)
        wheel(view.canvas, _at(view.canvas, speed0), 120, mod)
        after = y_range(speed0)
        assert after[1] - after[0] == pytest.approx(0.74 * (before[1] - before[0]), rel=0.01)
        assert x_range(speed0) == pytest.approx(x1)
    held = y_range(speed0)
    feed(ctx, rate_hz=50.0, seconds=1.0, start_ns=1_700_000_030_000_000_000)
    view.refresh()
    assert y_range(speed0) == pytest.approx(held)

    # a double-click resets: the window typed before, the value axis back to the data
    double_click(view.canvas, _at(view.canvas, speed0))
    assert view.window_s == 10
    x2, y2 = x_range(speed0), y_range(speed0)
    assert x2[1] - x2[0] == pytest.approx(11.0)
    assert y2[1] - y2[0] > held[1] - held[0]

    # paused: the wheel zooms time around the mouse, the window length stays
    view.set_paused(True)
    wheel(view.canvas, _at(view.canvas, speed0), 120)
    x3 = x_range(speed0)
    assert view.window_s == 10 and x3[1] - x3[0] == pytest.approx(0.74 * 11.0, rel=0.01)
    mid = (x2[0] + x2[1]) / 2
    assert x3[0] > x2[0] and x3[1] < x2[1] and (x3[0] + x3[1]) / 2 == pytest.approx(mid, abs=0.2)
    assert x_range(disp1) == pytest.approx(x3)
    double_click(view.canvas, _at(view.canvas, disp1))
    assert x_range(speed0) == pytest.approx(x2)


def test_hovering_a_plot_reads_its_values_out(qtbot, fake_bridge, feed):
    from PySide6.QtTest import QTest

    ctx = MonitorContext(MonitorSession(), fake_bridge)
    feed(ctx, rate_hz=50.0, seconds=5.0, name="straight")
    view = graphs(qtbot, ctx)
    qtbot.waitExposed(view)
    view.refresh()
    plot = view.plots[(1, "speed")]
    point = _at(view.canvas, plot)
    QTest.mouseMove(view.canvas.viewport(), point)
    qtbot.waitUntil(lambda: "at t =" in view.readout.text(), timeout=2000)
    text = view.readout.text()
    t = plot.getViewBox().mapSceneToView(view.canvas.mapToScene(point)).x()
    x, y = view.curves[(1, "speed", "y")].getData()
    i = int(np.argmin(np.abs(x - t)))
    assert text.startswith(f"{ctx.session.devices[1]} speed at t = {x[i]:.3f} s: ")
    assert f"Y {y[i]:.3f}" in text and text.endswith("mm/s")
    assert y[i] == pytest.approx(SPEED * 1e3 / 0.22 * 0.2, rel=0.05)  # 200 mm/s straight


def test_on_health_the_wheel_scrolls_the_page_ctrl_zooms_the_plot(qtbot, qapp, feed, tmp_path):
    from PySide6.QtCore import Qt

    from mm_pc.monitor.context import MonitorConfig
    from mm_pc.monitor.main_window import MainWindow

    config = MonitorConfig(rate_hz=15.0, calibration_file=tmp_path / "cal.yaml")
    window = MainWindow(MonitorContext(MonitorSession(), None, config), None)
    qtbot.addWidget(window)
    ctx = window.ctx
    ctx.session.configure_odometry(method="two-sensor")
    feed(ctx, rate_hz=50.0, seconds=10.0)
    window.show()
    window.resize(1024, 700)
    health = window.views["Health"]
    window.tabs.setCurrentIndex(5)
    assert window.tabs.tabText(5) == "Health"
    for _ in range(3):
        window.frame()
        qapp.processEvents()
    health._last_plot = 0.0
    health.refresh()
    page = window.tabs.currentWidget()
    bar = page.verticalScrollBar()
    assert bar.maximum() > 0, "the Health page scrolls at 1024x700"
    bar.setValue(0)
    canvas, plot = health.plots, health.residual_plot
    x0, y0 = x_range(plot), y_range(plot)
    wheel(canvas, _at(canvas, plot), -120)  # towards the user: the page goes down
    assert bar.value() > 0
    assert x_range(plot) == pytest.approx(x0) and y_range(plot) == pytest.approx(y0)
    scrolled = bar.value()
    wheel(canvas, _at(canvas, plot), 120, Qt.KeyboardModifier.ControlModifier)  # zoom time
    assert bar.value() == scrolled
    x1 = x_range(plot)
    assert x1[1] - x1[0] == pytest.approx(0.74 * (x0[1] - x0[0]), rel=0.01)
    assert y_range(plot) == pytest.approx(y0)
    # linked: the same time at the same x on the screen (the plots' left axes differ in width)
    lift = health.lift_plot.getViewBox()
    assert x_range(health.lift_plot)[1] == pytest.approx(x1[1], abs=0.01)
    assert (x_range(health.lift_plot)[1] - x_range(health.lift_plot)[0]) / lift.width() == (
        pytest.approx((x1[1] - x1[0]) / plot.getViewBox().width(), rel=0.01))
    wheel(canvas, _at(canvas, plot), 120,
          Qt.KeyboardModifier.ControlModifier | Qt.KeyboardModifier.ShiftModifier)
    y1 = y_range(plot)
    assert y1[1] - y1[0] == pytest.approx(0.74 * (y0[1] - y0[0]), rel=0.01)
    double_click(canvas, _at(canvas, plot))
    assert x_range(plot) == pytest.approx(x0) and y_range(plot) == pytest.approx(y0)


def test_a_long_window_over_little_data_shows_the_data_not_an_empty_axis(qtbot, fake_bridge,
                                                                         feed):
    ctx = MonitorContext(MonitorSession(), fake_bridge)
    feed(ctx, rate_hz=50.0, seconds=20.0)
    view = graphs(qtbot, ctx)
    view.window_box.setValue(3600)
    view.refresh()
    t = ctx.session.history.column("t")
    x0, x1 = x_range(view.plots[(0, "speed")])
    assert x0 == pytest.approx(t[0]) and x1 == pytest.approx(t[-1] + 0.1 * (t[-1] - t[0]))
    assert (t[-1] - t[0]) / (x1 - x0) > 0.9  # the data fill the axis
    view.window_box.setValue(10)  # a window shorter than the data: its last 10 s, as before
    view.refresh()
    x0, x1 = x_range(view.plots[(0, "speed")])
    assert (x0, x1) == pytest.approx((t[-1] - 10.0, t[-1] + 1.0))


def test_health_s_labels_never_overlap_the_table_at_first_start_height(qtbot, qapp, feed,
                                                                        tmp_path):
    """1024x640: the first start's inner size on a 1024x700 screen with a panel. The
    session counters wrap to a third line once data came: the pane grows (the page
    scrolls), the labels are not drawn over the table's last rows (seen in a real X run)."""
    from mm_pc.monitor.context import MonitorConfig
    from mm_pc.monitor.main_window import MainWindow

    config = MonitorConfig(rate_hz=15.0, calibration_file=tmp_path / "cal.yaml")
    window = MainWindow(MonitorContext(MonitorSession(), None, config), None)
    qtbot.addWidget(window)
    window.show()
    window.resize(1024, 640)
    window.tabs.setCurrentIndex(5)
    health = window.views["Health"]
    for _ in range(3):
        window.frame()
        qapp.processEvents()
    feed(window.ctx, rate_hz=50.0, seconds=20.0)  # the counters' text grows
    for _ in range(3):  # frames, a quarter of a second apart (the fit's check)
        health._last_fit = 0.0
        health.refresh()
        qapp.processEvents()
    table = health.table
    bottom = table.mapTo(health, table.rect().bottomLeft()).y()
    labels = [health.diag_state, health.session_label, health.bridge_label,
              health.residual_note, health.quality_note]
    tops = [lab.mapTo(health, lab.rect().topLeft()).y() for lab in labels if lab.isVisible()]
    assert min(tops) >= bottom, (tops, bottom)
    for lab in labels:
        if lab.isVisible():
            assert lab.height() >= lab.heightForWidth(lab.width()), lab.text()


def test_hovering_a_health_plot_reads_its_value_out(qtbot, qapp, fake_bridge, feed):
    from PySide6.QtCore import QPoint
    from PySide6.QtTest import QTest

    from mm_pc.monitor.widgets.health_view import HealthView

    ctx = MonitorContext(MonitorSession(), fake_bridge)
    ctx.session.configure_odometry(method="two-sensor")
    feed(ctx, rate_hz=50.0, seconds=10.0)
    view = HealthView(ctx)
    qtbot.addWidget(view)
    view.resize(900, 800)
    view.show()
    qtbot.waitExposed(view)
    view.refresh()
    qapp.processEvents()
    canvas, plot = view.plots, view.residual_plot
    box = plot.getViewBox()
    assert not box.readout.isVisible()
    point = _at(canvas, plot)
    qtbot.wait(20)
    QTest.mouseMove(canvas.viewport(), point)
    qtbot.waitUntil(lambda: box.readout.isVisible(), timeout=2000)
    t = box.mapSceneToView(canvas.mapToScene(point)).x()
    x, y = view.residual_curve.getData()
    i = int(np.argmin(np.abs(x - t)))
    assert box.readout.textItem.toPlainText() == f"t = {x[i]:.3f} s: {y[i]:.4g} mm"
    lift = view.lift_plot.getViewBox()
    qtbot.wait(20)
    QTest.mouseMove(canvas.viewport(), _at(canvas, view.lift_plot))
    qtbot.waitUntil(lambda: lift.readout.isVisible(), timeout=2000)
    assert lift.readout.textItem.toPlainText().endswith("s1 0, s2 0")  # no lifts in the sim
    assert not box.readout.isVisible()  # the mouse left the residual plot
    qtbot.wait(20)
    QTest.mouseMove(view.table.viewport(), QPoint(5, 5))  # off the plots
    qtbot.waitUntil(lambda: not lift.readout.isVisible(), timeout=2000)
