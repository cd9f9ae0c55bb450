"""Replay as a mode of its own: the replay bar, the status bar, the time base, live data kept
apart, the file checked before anything changes, errors in a dialog and the log."""

from __future__ import annotations

import logging
import math

import numpy as np
import pytest

pytest.importorskip("rclpy")
pytest.importorskip("PySide6")

from PySide6.QtCore import QTimer
from PySide6.QtWidgets import QMessageBox

from mm_pc.monitor.context import MonitorConfig, MonitorContext
from mm_pc.monitor.io.mcap_writer import McapRecorder
from mm_pc.monitor.main_window import MainWindow
from mm_pc.monitor.model.session import MonitorSession
from mm_pc.monitor.model.sim_feed import sim_replies
from mm_pc.monitor.replay import (
    leave_replay,
    load_in_background,
    parse_speed,
    speed_name,
    start_replay,
)
from mm_pc.monitor.ros_bridge import RosBridge
from mm_pc.monitor.widgets.replay_bar import replay_text

LIVE_NS = 1_800_000_000_000_000_000  # live stamps far after the recording's


def make_window(qtbot, tmp_path, bridge=None) -> MainWindow:
    config = MonitorConfig(rate_hz=100.0, calibration_file=tmp_path / "cal.yaml")
    window = MainWindow(MonitorContext(MonitorSession(), bridge, config))
    qtbot.addWidget(window)
    return window


def unused_bridge(name: str) -> RosBridge:
    return RosBridge("/mm_beagle", 100.0, node_name=name)  # never started: no network


@pytest.fixture(scope="module")
def run4(tmp_path_factory):
    """4 s of a straight run at 50 Hz (201 replies, stamps from the simulator's start)."""
    path = tmp_path_factory.mktemp("replay") / "run4.mcap"
    rec = McapRecorder(path)
    for r in sim_replies("straight", 50.0, 4.0):
        rec.write_reply(r)
    rec.close()
    return path


def test_replay_text_and_speed_names():
    assert replay_text("run.mcap", 12.04, 16.36) == "REPLAY run.mcap 12.0/16.4 s"
    assert replay_text("a.mcap", 0, 2, "paused") == "REPLAY a.mcap 0.0/2.0 s paused"
    assert [speed_name(parse_speed(s)) for s in ("1x", "2", "max", "2.5x")] == [
        "1x", "2x", "max", "2.5x",
    ]  # fmt: skip


def test_the_bar_shows_name_position_progress_and_pauses(qtbot, tmp_path, run4):
    window = make_window(qtbot, tmp_path)
    replayer = start_replay(window, run4, 1.0)
    bar = window.replay_bar
    assert bar.active and bar.isVisibleTo(window)
    assert bar.label.text().startswith("REPLAY run4.mcap 0.") and "/4.0 s" in bar.label.text()
    qtbot.waitUntil(lambda: replayer.played_s > 0.5, timeout=5000)
    bar.toggle_pause()
    assert not replayer.running and bar.pause_button.text() == "Resume"
    pos = replayer.position
    qtbot.wait(300)
    assert replayer.position == pos  # paused: nothing fed
    played = replayer.played_s
    assert bar.label.text() == replay_text("run4.mcap", played, 4.0, "paused")
    assert bar.progress.value() == int(1000 * played / 4.0)
    assert window.stop_replay_action.isEnabled()  # paused is still replaying
    bar.set_speed("max")  # the speed changes from where it is
    assert replayer.position == pos
    bar.toggle_pause()
    qtbot.waitUntil(lambda: replayer.done, timeout=10_000)
    assert replayer.position == len(replayer.replies) == 201
    assert bar.label.text() == "REPLAY run4.mcap 4.0/4.0 s ended"
    assert bar.progress.value() == 1000
    assert not bar.stop_button.isEnabled() and not bar.pause_button.isEnabled()
    assert window.ctx.session.pose.x == pytest.approx(0.8, abs=1e-4)  # the same path at any pace


def test_speed_change_keeps_the_recorded_time(qtbot, tmp_path, run4):
    """From max to 1x mid-way the recorded clock goes on from the last fed reply."""
    window = make_window(qtbot, tmp_path)
    replayer = start_replay(window, run4, 1.0)
    replayer.pause()
    replayer.set_speed("max")
    replayer.start()
    qtbot.waitUntil(lambda: replayer.position > 0, timeout=5000)
    replayer.pause()
    replayer.set_speed(1.0)
    at = replayer.played_s
    assert replayer._played() == pytest.approx(at)  # not inf, not 0
    with pytest.raises(ValueError, match="replay speed must be"):
        replayer.set_speed("slow")
    assert replayer.speed == 1.0
    replayer.stop()


def test_status_bar_says_replay_and_keeps_saying_it_while_the_link_changes(qtbot, tmp_path, run4):
    bridge = unused_bridge("mm_monitor_replay_state")
    window = make_window(qtbot, tmp_path, bridge)
    window._on_state("connected")
    window.rtt_label.setText("RTT 1.2 ms")
    assert window.state_label.text() == "connected to /mm_beagle"
    start_replay(window, run4, 1.0)
    assert window.state_label.text() == "REPLAY run4.mcap"
    assert not window.rtt_label.isVisibleTo(window) and not window.rate_label.isVisibleTo(window)
    window._on_state("lost")  # the bridge's link changes meanwhile
    assert window.state_label.text() == "REPLAY run4.mcap"
    window.stop_replay()
    assert window.state_label.text() == "REPLAY run4.mcap"  # stopped, still the replay's path
    assert "stopped" in window.replay_bar.label.text()
    leave_replay(window)
    assert window.state_label.text() == "lost /mm_beagle (retrying)"  # the latest link state
    assert window.rtt_label.isVisibleTo(window)
    assert not window.replay_bar.isVisibleTo(window)


def test_stop_and_back_to_live_are_enabled_only_when_they_mean_something(qtbot, tmp_path, run4):
    bridge = unused_bridge("mm_monitor_replay_actions")
    window = make_window(qtbot, tmp_path, bridge)
    assert not window.stop_replay_action.isEnabled() and not window.live_action.isEnabled()
    assert window.pause_button.isEnabled()
    replayer = start_replay(window, run4, 1.0)
    assert window.stop_replay_action.isEnabled() and window.live_action.isEnabled()
    assert not window.pause_button.isEnabled()  # polling is the replay's business now
    assert window.replay_bar.stop_button.isEnabled()
    assert not window.replay_bar.live_button.isVisibleTo(window)
    window.stop_replay_action.trigger()
    assert replayer.done
    assert not window.stop_replay_action.isEnabled() and window.live_action.isEnabled()
    assert not window.replay_bar.stop_button.isEnabled()
    assert window.replay_bar.live_button.isVisibleTo(window)
    assert window.replay_bar.live_button.text() == "Back to live"
    window.live_action.trigger()
    assert not window.stop_replay_action.isEnabled() and not window.live_action.isEnabled()
    assert window.pause_button.isEnabled() and bridge.polling


def test_without_a_node_the_bar_closes_and_the_path_stays(qtbot, tmp_path, run4):
    window = make_window(qtbot, tmp_path)
    replayer = start_replay(window, run4, "max")
    qtbot.waitUntil(lambda: replayer.done, timeout=10_000)
    assert window.replay_bar.live_button.text() == "Close"
    rows = len(window.ctx.session.history)
    window.replay_bar.live_button.click()
    assert not window.replay_bar.active and window.state_label.text() == "offline (no node)"
    assert len(window.ctx.session.history) == rows == 200


def test_times_run_from_0_of_the_recording_and_never_jump(qtbot, tmp_path, run4):
    """Live first (stamps far later), replay, back to live: each path's t starts near 0 and
    rises; no live row ever lands in the replayed path."""
    bridge = unused_bridge("mm_monitor_replay_times")
    window = make_window(qtbot, tmp_path, bridge)
    live = list(sim_replies("straight", 50.0, 2.0, start_ns=LIVE_NS))
    for r in live[:30]:
        bridge.data_received.emit([r])
    replayer = start_replay(window, run4, "max")
    bridge.data_received.emit([live[30]])  # in flight while replaying: not shown
    qtbot.waitUntil(lambda: replayer.done, timeout=10_000)
    for r in live[31:40]:
        bridge.data_received.emit([r])  # ended, not yet back to live: still not shown
    t = window.ctx.session.history.column("t")
    assert len(t) == 200 and t[0] == pytest.approx(0.02) and t[-1] == pytest.approx(4.0)
    assert np.all(np.diff(t) > 0)
    data = window.views["Data"]
    assert "run4.mcap" in data.time_base.text()
    table = data.tables[0]
    table.model.sync()
    assert table.model.value(0, 0) == pytest.approx(4.0)  # newest row first, in s
    csv = tmp_path / "replayed.csv"
    assert table.export_to(csv)
    times = [float(line.split(",")[0]) for line in csv.read_text().splitlines()[1:]]
    assert times[0] == pytest.approx(0.02) and times[-1] == pytest.approx(4.0)
    assert table.csv_prefix == "run4"
    leave_replay(window)
    for r in live[40:60]:
        bridge.data_received.emit([r])
    t = window.ctx.session.history.column("t")
    assert len(t) == 19 and t[0] == pytest.approx(0.02) and np.all(np.diff(t) > 0)
    assert "live" in data.time_base.text() and table.csv_prefix == ""
    assert window.ctx.session.pose.x == pytest.approx(19 * 0.004, abs=1e-4)  # a new path


def test_a_replay_of_other_sensors_shows_in_the_data_list_and_live_gets_its_own_session(
    qtbot, tmp_path
):
    path = tmp_path / "ab.mcap"
    rec = McapRecorder(path)
    for r in sim_replies("straight", 50.0, 1.0, devices=("/dev/a", "/dev/b")):
        rec.write_reply(r)
    rec.close()
    bridge = unused_bridge("mm_monitor_replay_other")
    window = make_window(qtbot, tmp_path, bridge)
    live = list(sim_replies("straight", 50.0, 1.0, start_ns=LIVE_NS))
    for r in live[:10]:
        bridge.data_received.emit([r])
    replayer = start_replay(window, path, "max")
    qtbot.waitUntil(lambda: replayer.done, timeout=10_000)
    data = window.views["Data"]
    assert [data.tabs.tabText(i) for i in range(data.tabs.count())] == ["/dev/a", "/dev/b"]
    model = data.tables[0].model
    model.sync()
    assert model.session is window.ctx.session and model.rowCount() == 50
    leave_replay(window)
    for r in live[10:15]:
        bridge.data_received.emit([r])
    assert window.ctx.session.devices == ("/dev/spidev1.0", "/dev/spidev1.1")
    assert len(window.ctx.session.history) == 4


@pytest.mark.parametrize("kind", ["junk", "no_readings"])
def test_a_bad_file_is_reported_in_a_dialog_and_the_log_before_anything_changes(
    kind, qtbot, tmp_path, caplog
):
    bad = tmp_path / "bad.mcap"
    if kind == "junk":
        bad.write_bytes(b"no recording at all")
        why = "not an MCAP file"
    else:
        McapRecorder(bad).close()  # a valid file without a reply
        why = "holds no"
    bridge = unused_bridge("mm_monitor_replay_bad")
    window = make_window(qtbot, tmp_path, bridge)
    for r in sim_replies("straight", 50.0, 0.5, start_ns=LIVE_NS):
        bridge.data_received.emit([r])
    session, rows = window.ctx.session, len(window.ctx.session.history)
    with caplog.at_level(logging.WARNING, logger="mm_pc.monitor.replay"):
        load_in_background(window, bad, 1.0)  # what File > Replay does after the file dialog
        assert window.replay_reading is not None  # busy while the file is read
        qtbot.waitUntil(lambda: getattr(window, "replay_error", None) is not None, timeout=10_000)
    box = window.replay_error
    assert isinstance(box, QMessageBox) and why in box.text() and str(bad) in box.text()
    assert any(why in rec.getMessage() for rec in caplog.records)
    assert window.statusBar().currentMessage().startswith("replay: ")
    assert window.ctx.session is session and len(session.history) == rows
    assert bridge.polling and getattr(window, "replayer", None) is None
    assert window.replay_reading is None
    assert window.state_label.text() != "REPLAY bad.mcap"
    assert not window.stop_replay_action.isEnabled()
    box.done(0)


def test_the_chosen_speed_is_remembered_for_the_next_replay(qtbot, tmp_path, run4):
    from mm_pc.monitor.replay import remembered_speed

    window = make_window(qtbot, tmp_path)
    replayer = start_replay(window, run4, 1.0)
    window.replay_bar.speed_box.setCurrentText("5x")
    window.replay_bar.speed_box.activated.emit(window.replay_bar.speed_box.currentIndex())
    assert replayer.speed == 5.0
    assert remembered_speed() == 5.0
    window.replay_bar.set_speed("1x")
    assert remembered_speed() == 1.0
    replayer.stop()


def test_the_bar_never_widens_the_window(qtbot, tmp_path, run4):
    window = make_window(qtbot, tmp_path)
    window.show()
    before = window.minimumSizeHint().width()
    replayer = start_replay(window, run4, 1.0)
    qtbot.wait(50)
    assert window.minimumSizeHint().width() <= max(before, 1024)
    assert window.replay_bar.minimumSizeHint().width() < 400
    replayer.stop()
    assert math.isfinite(window.replay_bar.replayer.total_s)


def test_a_second_replay_keeps_the_live_state_of_before_the_first(qtbot, tmp_path, run4):
    bridge = unused_bridge("mm_monitor_replay_twice")
    window = make_window(qtbot, tmp_path, bridge)
    for r in sim_replies("straight", 50.0, 0.5, start_ns=LIVE_NS):
        bridge.data_received.emit([r])
    first = start_replay(window, run4, 1.0)
    assert not bridge.polling
    other = tmp_path / "other.mcap"
    rec = McapRecorder(other)
    for r in sim_replies("straight", 50.0, 1.0):
        rec.write_reply(r)
    rec.close()
    second = start_replay(window, other, "max")  # while the first still runs
    assert first.done and second is not first
    qtbot.waitUntil(lambda: second.done, timeout=10_000)
    assert window.replay_bar.label.text() == "REPLAY other.mcap 1.0/1.0 s ended"
    assert window.ctx.session.pose.x == pytest.approx(0.2, abs=1e-4)  # only the second's path
    assert not bridge.polling
    leave_replay(window)
    assert bridge.polling  # as before the first replay
    assert len(window.ctx.session.history) == 0  # a new path
    for r in list(sim_replies("straight", 50.0, 1.0, start_ns=LIVE_NS))[30:33]:
        bridge.data_received.emit([r])  # live feeds again: a baseline and two steps
    assert len(window.ctx.session.history) == 2
    assert window.ctx.session.pose.x == pytest.approx(0.008, abs=1e-4)


def test_the_csv_dialog_starts_in_the_remembered_folder_with_the_recording_name(
    qtbot, tmp_path, run4, monkeypatch
):
    import mm_pc.monitor.widgets.data_list as data_list
    from mm_pc.monitor.settings import last_folder

    window = make_window(qtbot, tmp_path)
    replayer = start_replay(window, run4, "max")
    qtbot.waitUntil(lambda: replayer.done, timeout=10_000)
    table = window.views["Data"].tables[1]
    out = tmp_path / "csvs"
    out.mkdir()
    starts = []

    def save(_parent, _title, start, _filter):
        starts.append(start)
        return str(out / "s2.csv"), ""

    monkeypatch.setattr(data_list.QFileDialog, "getSaveFileName", save)
    table.choose_export()
    qtbot.waitUntil(lambda: table.export_done is not None, timeout=10_000)  # written by a timer
    assert table.export_done is True
    assert starts[-1].endswith("run4_dev_spidev1.1.csv")
    assert (out / "s2.csv").read_text().startswith("t_s,dx_mm")
    assert last_folder("csv") == str(out)
    table.choose_export()
    assert starts[-1] == str(out / "run4_dev_spidev1.1.csv")


def _fraction_x(bar, fraction: float) -> int:
    return round(fraction * bar.progress.width())


def test_the_progress_bar_seeks_by_click_drag_and_keys(qtbot, tmp_path, run4):
    from PySide6.QtCore import QPoint, Qt
    from PySide6.QtTest import QTest

    window = make_window(qtbot, tmp_path)
    window.show()
    replayer = start_replay(window, run4, 1.0)
    bar = window.replay_bar
    bar.toggle_pause()
    assert not replayer.running
    progress = bar.progress
    y = progress.height() // 2
    QTest.mouseClick(progress, Qt.MouseButton.LeftButton, pos=QPoint(_fraction_x(bar, 0.75), y))
    assert replayer.played_s == pytest.approx(3.0, abs=0.03)  # fed at once up to 3 s
    assert replayer.position == int(np.searchsorted(replayer.times, replayer.played_s)) + 1
    assert window.ctx.session.pose.x == pytest.approx(0.6, abs=0.005)  # 3 s at 0.2 m/s
    assert bar.label.text() == replay_text("run4.mcap", replayer.played_s, 4.0, "paused")
    assert progress.value() == pytest.approx(750, abs=8)
    assert not replayer.running  # paused stays paused

    # a drag back: only the label follows until the release, then the path starts over
    QTest.mousePress(progress, Qt.MouseButton.LeftButton, pos=QPoint(_fraction_x(bar, 0.6), y))
    QTest.mouseMove(progress, QPoint(_fraction_x(bar, 0.25), y))
    assert "seek" in bar.label.text() and replayer.played_s == pytest.approx(3.0, abs=0.03)
    QTest.mouseRelease(progress, Qt.MouseButton.LeftButton, pos=QPoint(_fraction_x(bar, 0.25), y))
    assert replayer.played_s == pytest.approx(1.0, abs=0.03)
    hist = window.ctx.session.history
    t = hist.column("t")
    assert t[0] >= 0 and t[-1] == pytest.approx(replayer.played_s, abs=1e-6)  # one path, 0..1 s
    assert np.all(np.diff(t) > 0)
    pose = window.ctx.session.pose
    assert math.hypot(pose.x, pose.y) == pytest.approx(0.2, abs=0.01)  # 1 s at 0.2 m/s

    # keys, the bar focused: Right 5 s on (clamped at the end: the replay ends), Home
    progress.setFocus()
    QTest.keyClick(progress, Qt.Key.Key_Home)
    assert replayer.played_s == 0.0
    QTest.keyClick(progress, Qt.Key.Key_Right)
    assert replayer.done and replayer.position == len(replayer.replies)
    assert window.ctx.session.pose.x == pytest.approx(0.8, abs=1e-4)  # as a whole replay
    assert bar.state() == "ended" and not window.stop_replay_action.isEnabled()

    # after the end: a seek takes the replay up again, paused there
    QTest.mouseClick(progress, Qt.MouseButton.LeftButton, pos=QPoint(_fraction_x(bar, 0.5), y))
    assert not replayer.done and not replayer.running
    assert replayer.played_s == pytest.approx(2.0, abs=0.03)
    assert window.ctx.session.pose.x == pytest.approx(0.4, abs=0.005)
    assert bar.state() == "paused" and window.stop_replay_action.isEnabled()
    assert bar.pause_button.isEnabled() and bar.pause_button.text() == "Resume"
    bar.toggle_pause()
    qtbot.waitUntil(lambda: replayer.done, timeout=10_000)
    assert window.ctx.session.pose.x == pytest.approx(0.8, abs=1e-4)


def test_a_long_seek_keeps_the_window_responsive_and_gives_the_same_path(qtbot, tmp_path):
    """1501 replies: a seek over more than SEEK_AT_ONCE is fed by the timer in slices (the
    window's events go on meanwhile); the path is the one a replay to there draws."""
    from mm_pc.monitor.replay import SEEK_AT_ONCE

    path = tmp_path / "run30.mcap"
    rec = McapRecorder(path)
    replies = list(sim_replies("straight", 50.0, 30.0))
    for r in replies:
        rec.write_reply(r)
    rec.close()
    window = make_window(qtbot, tmp_path)
    replayer = start_replay(window, path, 1.0)
    bar = window.replay_bar
    bar.toggle_pause()
    assert len(replies) - 1 > SEEK_AT_ONCE
    bar.seek(27.0)
    assert replayer.seeking and replayer.position < len(replies) - 1  # not all at once
    assert bar.state() == "seeking" and not replayer.running  # paused before: stays so
    ticks = []
    timer = QTimer()
    timer.timeout.connect(lambda: ticks.append(1))
    timer.start(10)
    qtbot.waitUntil(lambda: not replayer.seeking, timeout=20_000)
    timer.stop()
    assert len(ticks) >= 2  # other timers ran during the seek: no frozen window
    assert replayer.played_s == pytest.approx(27.0, abs=0.03) and not replayer.running
    fresh = MonitorSession()
    for r in replies[:replayer.position]:
        fresh.process(r)
    assert window.ctx.session.pose == pytest.approx(fresh.pose)
    np.testing.assert_array_equal(window.ctx.session.history.column("t"),
                                  fresh.history.column("t"))
    bar.seek(2.0)  # back: short, done at once, the path starts over
    assert not replayer.seeking and replayer.played_s == pytest.approx(2.0, abs=0.03)
    assert window.ctx.session.pose.x == pytest.approx(0.4, abs=0.005)
