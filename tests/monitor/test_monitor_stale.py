"""Values that never look live when they are not (issue 29, finding 8).

After the node is lost the dials drop their arrows and Health says the link is lost;
paused and replaying are said as such in the Sampling panel; a CPI refusal goes after
the next success or a timeout; an outage is a break in the residual plot, not a line.
Offscreen Qt; the real MainWindow with a never-started RosBridge (no network), fed the
simulated replies as its ``data_received`` would.
"""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np
import pytest

pytest.importorskip("rclpy")
pytest.importorskip("PySide6")

from PySide6.QtGui import QColor

from mm_pc.monitor.context import MonitorConfig, MonitorContext
from mm_pc.monitor.io.mcap_writer import McapRecorder
from mm_pc.monitor.main_window import IDLE_STYLE, WARNING_STYLE, MainWindow
from mm_pc.monitor.model.outages import OutageFinder, find_outages, with_breaks
from mm_pc.monitor.model.session import MonitorSession
from mm_pc.monitor.model.sim_feed import DEFAULT_DEVICES, sim_replies
from mm_pc.monitor.replay import leave_replay, start_replay
from mm_pc.monitor.ros_bridge import RosBridge
from mm_pc.monitor.widgets.direction_widget import DirectionWidget
from mm_pc.monitor.widgets.health_view import LEVEL_COLOURS, STALE_BACKGROUND, HealthView
from mm_pc.monitor.widgets.resolution_panel import ERROR_SHOW_S, ResolutionPanel
from mm_pc.monitor.widgets.style import STALE_STYLE, sensor_colour


def make_window(qtbot, tmp_path, name: str) -> tuple[MainWindow, RosBridge]:
    bridge = RosBridge("/mm_beagle", 100.0, node_name=name)  # never started: no network
    config = MonitorConfig(rate_hz=100.0, calibration_file=tmp_path / "cal.yaml")
    window = MainWindow(MonitorContext(MonitorSession(), bridge, config))
    qtbot.addWidget(window)
    return window, bridge


def live(window, bridge, seconds: float = 1.0, **kw) -> None:
    window._on_state("connected")
    for r in sim_replies("figure_eight", 50.0, seconds, **kw):
        bridge.data_received.emit([r])
    window.frame()


def since(ctx) -> str:
    return time.strftime("%H:%M:%S", time.localtime(ctx.last_data_time))


def colour_pixels(widget, colour: str) -> int:
    """Pixels of exactly ``colour`` in the widget's picture (an arrow's or a dot's)."""
    img = widget.grab().toImage()
    want = QColor(colour).rgb()
    return sum(img.pixel(x, y) == want for x in range(img.width()) for y in range(img.height()))


def test_a_lost_link_greys_the_dials_health_and_sampling(qtbot, tmp_path):
    window, bridge = make_window(qtbot, tmp_path, "mm_monitor_stale_lost")
    ctx = window.ctx
    health = window.views["Health"]
    bridge.diagnostics_received.emit(
        {DEFAULT_DEVICES[0]: {"level": 1, "message": "late polls", "state": "up"}})
    live(window, bridge)
    assert ctx.data_state == "live" and not ctx.stale
    dials = window.direction_panel.widgets
    assert len(dials) == 2 and all(d.stale_text == "" for d in dials)
    table = health.table
    assert (table.item(0, 0).text(), table.item(1, 0).text()) == ("WARN", "up")
    window._on_stats(bridge.stats())
    assert window.rate_editor.now.text().startswith("now: 100 Hz")

    window._on_state("lost")
    assert ctx.data_state == "lost" and ctx.stale
    text = f"link lost: no data since {since(ctx)}"
    assert [d.stale_text for d in dials] == [text, text]
    health.refresh()
    assert table.item(0, 0).text() == "no data"  # not the node's last "WARN"
    assert table.item(1, 0).text() == text  # not "up"
    assert table.item(0, 0).background().color().name() == STALE_BACKGROUND
    assert health.diag_state.text().startswith(f"/diagnostics: {text}")
    now = window.rate_editor.now
    assert now.text() == f"100 Hz asked; link lost, no data since {since(ctx)}"
    assert now.styleSheet() == WARNING_STYLE

    window._on_state("connected")  # back: fresh values show as they are
    bridge.diagnostics_received.emit(
        {DEFAULT_DEVICES[0]: {"level": 1, "message": "late polls", "state": "up"}})
    assert [d.stale_text for d in dials] == ["", ""]
    assert (table.item(0, 0).text(), table.item(1, 0).text()) == ("WARN", "up")
    assert table.item(0, 0).background().color().name() == LEVEL_COLOURS[1][1]


def test_the_status_bar_round_trip_is_no_figure_while_lost_or_paused(qtbot, tmp_path):
    """Checked in X (issue 29 finding 8): after the node was killed the status bar kept
    "RTT 1.5 ms", the median of replies from before the loss, in black as if live."""
    window, bridge = make_window(qtbot, tmp_path, "mm_monitor_stale_rtt")
    ctx = window.ctx
    live(window, bridge)
    stats = replace(bridge.stats(), rtt_p50_s=0.0015)
    window._on_stats(stats)
    assert window.rtt_label.text() == "RTT 1.5 ms"
    window._on_state("lost")
    assert window.rtt_label.text() == "RTT –"
    assert window.rtt_label.toolTip().endswith(
        f"none while the link is lost (no data since {since(ctx)})")
    window._on_stats(stats)  # the bridge's stats go on with the old median
    assert window.rtt_label.text() == "RTT –"
    window._on_state("connected")
    assert window.rtt_label.text() == "RTT 1.5 ms"
    window.pause_button.setChecked(True)
    assert window.rtt_label.text() == "RTT –"
    assert "none while polling is paused" in window.rtt_label.toolTip()
    window.pause_button.setChecked(False)
    window._on_stats(replace(stats, rtt_p50_s=0.0021))
    assert window.rtt_label.text() == "RTT 2.1 ms"
    assert window.rtt_label.toolTip().startswith("round-trip time of a data request, median")


def test_a_stale_dial_draws_no_arrow(qtbot):
    dial = DirectionWidget(0, "/dev/spidev1.0")
    qtbot.addWidget(dial)
    dial.resize(180, 180)
    dial.set_sample(0.001, 0.002, 0.2, 0.002)
    assert colour_pixels(dial, sensor_colour(0)) > 20  # the arrow
    dial.set_stale("link lost: no data since 12:00:00")
    assert colour_pixels(dial, sensor_colour(0)) == 0
    dial.set_stale("")
    assert colour_pixels(dial, sensor_colour(0)) > 20


def test_paused_polling_says_paused_not_an_orange_0_hz(qtbot, tmp_path):
    window, bridge = make_window(qtbot, tmp_path, "mm_monitor_stale_paused")
    ctx = window.ctx
    live(window, bridge)
    window.pause_button.setChecked(True)  # Pause polling
    assert not bridge.polling and ctx.data_state == "paused"
    now = window.rate_editor.now
    assert now.text() == "paused: no requests (100 Hz when resumed)"
    assert now.styleSheet() == IDLE_STYLE
    assert not window.rate_editor.show_achieved(0.0)  # the stats go on: still "paused"
    assert now.text() == "paused: no requests (100 Hz when resumed)"
    assert window.rate_label.styleSheet() == ""
    dials = window.direction_panel.widgets
    assert [d.stale_text for d in dials] == [f"paused: no data since {since(ctx)}"] * 2
    window.pause_button.setChecked(False)
    assert ctx.data_state == "live" and now.text() == "now: 100 Hz"
    assert [d.stale_text for d in dials] == ["", ""]


def test_replaying_says_replaying_and_back_to_live_says_the_rate(qtbot, tmp_path):
    path = tmp_path / "run.mcap"
    rec = McapRecorder(path)
    for r in sim_replies("straight", 50.0, 1.0):
        rec.write_reply(r)
    rec.close()
    window, bridge = make_window(qtbot, tmp_path, "mm_monitor_stale_replay")
    live(window, bridge, start_ns=1_800_000_000_000_000_000)
    replayer = start_replay(window, path, "max")
    assert window.ctx.data_state == "replay"
    now = window.rate_editor.now
    assert now.text() == "replaying a recording (live 100 Hz after Back to live)"
    assert now.styleSheet() == IDLE_STYLE
    qtbot.waitUntil(lambda: replayer.done, timeout=10_000)
    assert window.ctx.data_state == "replay"  # ended: the path shown is still the replay's
    assert [d.stale_text for d in window.direction_panel.widgets] == ["", ""]
    leave_replay(window)
    assert window.ctx.data_state == "live" and now.text() == "now: 100 Hz"


def test_replaying_without_a_node_promises_no_live_rate(qtbot, tmp_path):
    """Checked in X (mm-monitor --replay FILE, no node): the Sampling panel said "live 15 Hz
    after Back to live", but without a node Back to live is offline."""
    path = tmp_path / "run.mcap"
    rec = McapRecorder(path)
    for r in sim_replies("straight", 50.0, 0.5):
        rec.write_reply(r)
    rec.close()
    config = MonitorConfig(rate_hz=15.0, calibration_file=tmp_path / "cal.yaml")
    window = MainWindow(MonitorContext(MonitorSession(), None, config))
    qtbot.addWidget(window)
    replayer = start_replay(window, path, "max")
    now = window.rate_editor.now
    assert now.text() == "replaying a recording (offline: no node to poll after it)"
    assert now.styleSheet() == IDLE_STYLE
    qtbot.waitUntil(lambda: replayer.done, timeout=10_000)
    leave_replay(window)
    assert window.ctx.data_state == "offline"


def test_a_cpi_refusal_goes_after_the_next_success_or_a_timeout(qtbot, fake_bridge, feed):
    ctx = MonitorContext(MonitorSession(), fake_bridge)
    feed(ctx, rate_hz=50.0, seconds=0.2)
    panel = ResolutionPanel(ctx)
    qtbot.addWidget(panel)
    dev = DEFAULT_DEVICES[0]
    row = panel.rows[dev]
    row.edit.setText("junk")
    assert not panel.apply(dev) and "whole number" in row.error.text()
    row.edit.setText("800")
    assert panel.apply(dev) and row.error.text() == ""  # a change that is sent
    panel.on_resolution_done(dev, False, "the node refused 800", 1600)
    assert row.error.text() == "the node refused 800"
    panel.on_resolution_done(dev, True, "", 800)  # the next change succeeded
    assert row.error.text() == ""
    row.edit.setText("junk")
    panel.apply(dev)
    panel.refresh()
    assert row.error.text() != ""  # not yet
    row.error_at -= ERROR_SHOW_S + 0.1
    panel.refresh()
    assert row.error.text() == ""


def test_outages_are_found_and_drawn_as_breaks():
    t = np.r_[np.arange(0, 2, 0.02), np.arange(7, 9, 0.02)]  # 5 s without rows at 50 Hz
    out = find_outages(t)
    np.testing.assert_allclose(out, [[1.98, 7.0]])
    assert find_outages(np.arange(0, 10, 0.5)).shape == (0, 2)  # 2 Hz: slow, not an outage
    bt, by = with_breaks(t, np.ones_like(t), out)
    assert len(bt) == len(t) + 1 and np.all(np.diff(bt) >= 0)
    i = int(np.flatnonzero(np.isnan(by))[0])
    assert bt[i] == pytest.approx(4.49) and np.isfinite(np.delete(by, i)).all()
    finder = OutageFinder()  # the same, scanned as the column grows
    assert finder.update(t[:100]).shape == (0, 2)
    np.testing.assert_allclose(finder.update(t[:101]), [[1.98, 7.0]])
    np.testing.assert_allclose(finder.update(t), [[1.98, 7.0]])


def test_the_residual_plot_breaks_at_an_outage(qtbot, fake_bridge, feed):
    ctx = MonitorContext(MonitorSession(), fake_bridge)
    ctx.session.configure_odometry(method="two-sensor")
    start = 1_700_000_000_000_000_000
    feed(ctx, rate_hz=50.0, seconds=2.0, start_ns=start)
    feed(ctx, rate_hz=50.0, seconds=2.0, start_ns=start + 10_000_000_000)  # 8 s later
    view = HealthView(ctx)
    qtbot.addWidget(view)
    view.refresh()
    t = ctx.session.history.column("t")
    x, y = view.residual_data()
    gap = np.flatnonzero(np.diff(t) > 5.0)
    assert len(gap) == 1
    nan = np.flatnonzero(np.isnan(y))
    assert len(nan) == 1 and t[gap[0]] < x[nan[0]] < t[gap[0] + 1]
    assert len(x) == len(t) + 1


def test_the_map_pose_and_the_graphs_note_say_the_values_are_old(qtbot, tmp_path):
    """Checked in X (issue 29 finding 8): with the node killed, the Map's pose readout stayed
    black and the Graphs note read as live; the curves just end, like a robot that stopped."""
    window, bridge = make_window(qtbot, tmp_path, "mm_monitor_stale_map_graphs")
    ctx = window.ctx
    live(window, bridge)
    pose, note = window.views["Map"].pose_label, window.views["Graphs"].note
    window.views["Graphs"].refresh()
    live_note = note.text()
    assert live_note.endswith("s") and "no data" not in live_note
    assert pose.styleSheet() == "" and note.styleSheet() == ""
    window._on_state("lost")
    text = f"link lost: no data since {since(ctx)}"
    assert pose.styleSheet() == STALE_STYLE == note.styleSheet()
    assert pose.toolTip() == f"the last pose known: {text}"
    assert note.text() == f"{live_note}; {text}"
    window._on_state("connected")
    assert pose.styleSheet() == "" and note.styleSheet() == ""
    assert note.text() == live_note and not pose.toolTip().startswith("the last pose")
    window.pause_button.setChecked(True)
    assert note.text() == f"{live_note}; paused: no data since {since(ctx)}"
    assert pose.styleSheet() == STALE_STYLE
