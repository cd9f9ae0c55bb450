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
    """The replies with each stamp moved by up to +-``jitter_ns`` (uniform) from the time
    its totals were read: what a poll stamp taken a little off its read does to a reply
    that covers two polls (500 Hz): dx/dt of one reply swings up to 2x."""
    rng = np.random.default_rng(seed)
    first = True
    for r in replies:
        if first:  # the baseline
            first = False
            yield r
            continue
        shift = int(rng.integers(-jitter_ns, jitter_ns + 1))
        yield dataclasses.replace(r, readings=tuple(
            dataclasses.replace(x, stamp_ns=x.stamp_ns + shift) for x in r.readings))


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
    # what one reply's dx/dt would have drawn: up to twice the speed
    hist = ctx.session.history
    one = np.hypot(hist.column("s0_dx"), hist.column("s0_dy")) / hist.column("dt")
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
