"""Record replies to MCAP (ROS 2 messages) and replay them through the same processing."""

from __future__ import annotations

import math
import time
from dataclasses import fields

import numpy as np
import pytest

pytest.importorskip("rclpy")
pytest.importorskip("PySide6")

from mcap.reader import make_reader
from mcap.writer import Writer
from rclpy.serialization import deserialize_message, serialize_message

from mm_interfaces.msg import SensorData
from mm_interfaces.srv import GetSamples
from mm_pc.core.geometry import DEFAULT_MOUNTS, SensorMount
from mm_pc.core.sensor_data import Reading, Reply
from mm_pc.monitor.context import MonitorConfig, MonitorContext
from mm_pc.monitor.io.mcap_reader import read_replies, read_samples
from mm_pc.monitor.io.mcap_writer import McapRecorder
from mm_pc.monitor.io.schemas import META_TOPIC, POLLS_TYPE, SENSOR_TOPIC, ros2msg_definition
from mm_pc.monitor.main_window import MainWindow
from mm_pc.monitor.model.session import MonitorSession
from mm_pc.monitor.model.sim_feed import sim_replies
from mm_pc.monitor.recording import (
    recording_text,
    start_recording,
    stop_recording,
    toggle_recording,
)
from mm_pc.monitor.replay import Replayer, parse_speed, start_replay
from mm_pc.monitor.ros_bridge import RosBridge

DEVICES = ("/dev/spidev1.0", "/dev/spidev1.1")


def odd_reply() -> Reply:
    """A reply in which every field has its own non-default value."""
    readings = tuple(
        Reading(
            id=dev,
            stamp_ns=1_700_000_003_050_000_123 + k,
            seq=4242 + k,
            x_total=0.125 + k,
            y_total=-1.5 - k,
            x_lift_total=0.0031,
            y_lift_total=-0.0042,
            x_speed=0.21,
            y_speed=-0.33,
            x_counts=-17 + k,
            y_counts=99,
            cpi=3200,
            samples=10 + k,
            lift_events=3,
            lift_events_total=77 + k,
            interval=0.0105,
            x_disp=0.21 * 0.0105,
            y_disp=-0.33 * 0.0105,
            x_total_counts=7085 + k,
            y_total_counts=-94488 - k,
            x_lift_est_counts=1.5,
            y_lift_est_counts=-2.5,
            x_lift_est_disp=0.0000238,
            y_lift_est_disp=-0.0000397,
            # one chip with its quality figure, one old node (no chip, no figure)
            chip=("pmw3360", "")[k],
            quality=(42, -1)[k],
            low_quality_events=2 - k,
            low_quality_events_total=9 + k,
            # the header (issue 25): one from a node, one from an old node (none)
            frame_id=("r1/mouse_spidev1_0_counts", "")[k],
            header_stamp_ns=(1_700_000_003_050_000_999, 0)[k],
        )
        for k, dev in enumerate(DEVICES)
    )
    return Reply(readings, received_s=12345.678901234, rtt_s=0.00123)


def write_straight_run(path, seconds: float):
    """A recording of a straight run at 20 Hz, from the simulator."""
    rec = McapRecorder(path)
    for r in sim_replies("straight", 20, seconds=seconds):
        rec.write_reply(r)
    rec.close()
    return path


def make_window(qtbot, tmp_path, bridge=None) -> MainWindow:
    config = MonitorConfig(rate_hz=100.0, calibration_file=tmp_path / "cal.yaml")
    window = MainWindow(MonitorContext(MonitorSession(), bridge, config))
    qtbot.addWidget(window)
    return window


def session_state(session: MonitorSession):
    hist = session.history
    return (
        session.pose,
        0 if hist is None else len(hist),
        0 if hist is None else hist.version,
        session.stats.replies,
        session.devices,
    )


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    """3 s of 100 Hz figure-eight replies plus an odd reply and an empty one, recorded."""
    replies = list(sim_replies("figure_eight", 100.0, 3.0))
    replies.insert(5, Reply((), received_s=replies[4].received_s + 1e-4, rtt_s=0.5))
    replies.append(odd_reply())
    path = tmp_path_factory.mktemp("rec") / "run.mcap"
    rec = McapRecorder(path, beagle="/robot/mm_beagle", rate_hz=100.0)
    for r in replies:
        rec.write_reply(r)
    rec.close()
    return path, replies


# -- file format --------------------------------------------------------------------------------


def test_read_back_equals_what_was_written_every_field(recording):
    path, replies = recording
    back = read_replies(path)
    assert len(back) == len(replies)
    for got, want in zip(back, replies, strict=True):
        assert got.received_s == want.received_s and got.rtt_s == want.rtt_s
        assert len(got.readings) == len(want.readings)
        for g, w in zip(got.readings, want.readings, strict=True):
            for f in fields(Reading):
                assert getattr(g, f.name) == getattr(w, f.name), f.name
    assert back[5].readings == ()


def test_file_is_ros2_mcap_that_rclpy_decodes(recording):
    path, replies = recording
    with open(path, "rb") as f:
        reader = make_reader(f)
        assert reader.get_header().profile == "ros2"
        summary = reader.get_summary()
        topics = {c.topic: c for c in summary.channels.values()}
        assert set(topics) == {SENSOR_TOPIC, META_TOPIC}
        for c in topics.values():
            assert c.message_encoding == "cdr"
            assert "offered_qos_profiles" in c.metadata
            schema = summary.schemas[c.schema_id]
            assert schema.encoding == "ros2msg"
        sensor_schema = summary.schemas[topics[SENSOR_TOPIC].schema_id]
        assert sensor_schema.name == "mm_interfaces/msg/SensorData"
        text = sensor_schema.data.decode()
        assert text.startswith("# Displacement of one sensor")
        assert "\n" + "=" * 80 + "\nMSG: builtin_interfaces/Time\n" in text
        assert "uint32 nanosec" in text
        meta = {m.name: dict(m.metadata) for m in reader.iter_metadata()}["mm_monitor"]
        assert meta["beagle"] == "/robot/mm_beagle"
        assert meta["devices"] == ",".join(DEVICES)
        assert meta["rate_hz"] == "100"
        assert meta["replies"] == str(len(replies))
        assert meta["start_time"].startswith("20")
        msgs = [
            (c.topic, m)
            for _, c, m in reader.iter_messages(topics=[SENSOR_TOPIC], log_time_order=False)
        ]
    assert len(msgs) == 2 * (len(replies) - 1)
    last = deserialize_message(msgs[-1][1].data, SensorData)
    want = odd_reply().readings[1]
    assert last.id == want.id
    assert last.stamp.sec * 10**9 + last.stamp.nanosec == want.stamp_ns
    assert (last.seq, last.x_counts, last.cpi, last.samples) == (4243, -16, 3200, 11)
    assert last.x_total_disp == 1.125 and last.y_lift_est_total_disp == -0.0042
    assert last.x_disp == want.x_disp and last.y_total_counts == want.y_total_counts
    assert last.x_lift_est_counts == 1.5 and last.y_lift_est_disp == want.y_lift_est_disp
    assert msgs[-1][1].publish_time == want.stamp_ns
    # every message of one reply shares log time and sequence number
    assert msgs[-1][1].log_time == msgs[-2][1].log_time
    assert msgs[-1][1].sequence == msgs[-2][1].sequence == len(replies) - 1


def test_a_file_with_only_sensor_data_groups_by_log_time(tmp_path, recording):
    """E.g. a rosbag2 MCAP of a SensorData topic: messages with one log time form one reply."""
    _, replies = recording
    path = tmp_path / "bag.mcap"
    with open(path, "wb") as f:
        w = Writer(f)
        w.start(profile="ros2", library="test")
        name = "mm_interfaces/msg/SensorData"
        sid = w.register_schema(name, "ros2msg", ros2msg_definition(name).encode())
        cid = w.register_channel("/mm_beagle/sensor_data", "cdr", sid, {"offered_qos_profiles": ""})
        for k, rep in enumerate(replies[:4]):
            for r in rep.readings:
                data = serialize_message(_sensor_msg(r))
                w.add_message(cid, 1_000_000_000 + k * 10_000_000, data, r.stamp_ns)
        w.finish()
    back = read_replies(path)
    assert [b.readings for b in back] == [r.readings for r in replies[:4]]
    assert [b.received_s for b in back] == [1.0, 1.01, 1.02, 1.03]
    assert all(b.rtt_s == 0.0 for b in back)


def _sensor_msg(r: Reading) -> SensorData:
    from builtin_interfaces.msg import Time

    return SensorData(
        stamp=Time(sec=r.stamp_ns // 10**9, nanosec=r.stamp_ns % 10**9), id=r.id, seq=r.seq,
        x_total_disp=r.x_total, y_total_disp=r.y_total, x_speed=r.x_speed, y_speed=r.y_speed,
        x_counts=r.x_counts, y_counts=r.y_counts, cpi=r.cpi, samples=r.samples,
        interval=r.interval, x_disp=r.x_disp, y_disp=r.y_disp,
        x_total_counts=r.x_total_counts, y_total_counts=r.y_total_counts,
    )  # fmt: skip


def test_schema_of_a_nested_type_lists_each_dependency_once():
    text = ros2msg_definition("std_msgs/msg/Float64MultiArray")
    assert text.count("MSG: std_msgs/MultiArrayLayout\n") == 1
    assert text.count("MSG: std_msgs/MultiArrayDimension\n") == 1
    assert "MSG: " not in ros2msg_definition("mm_interfaces/srv/GetSamples_Response")


def test_fetched_single_polls_are_recorded(tmp_path):
    path = tmp_path / "samples.mcap"
    rec = McapRecorder(path)
    res = GetSamples.Response(
        success=True, first_seq=10, next_seq=13, cpi=1600, stamp_ns=[5, 6, 7], dx=[1, -2, 3],
        dy=[0, 4, -5], status=[128, 128, 129], flags=[2, 2, 3],
    )  # fmt: skip
    rec.write_samples("/dev/spidev1.1", res)
    rec.write_reply(odd_reply())
    rec.close()
    ((device, back),) = read_samples(path)
    assert device == "/dev/spidev1.1"
    assert list(back.dx) == [1, -2, 3] and list(back.flags) == [2, 2, 3] and back.next_seq == 13
    assert read_replies(path) == [odd_reply()]


def test_a_reading_that_does_not_fit_the_message_is_refused_and_nothing_written(tmp_path):
    rec = McapRecorder(tmp_path / "bad.mcap")
    bad = Reply((Reading(id="/dev/a", stamp_ns=1, seq=-1, x_total=0.0, y_total=0.0),))
    with pytest.raises(ValueError, match=r"does not fit .*seq=-1 is not an integer in 0\.\."):
        rec.write_reply(bad)
    assert rec.replies == 0
    rec.close()
    with pytest.raises(ValueError, match="closed"):
        rec.write_reply(odd_reply())
    assert read_replies(tmp_path / "bad.mcap") == []


def corrupt_files(tmp_path, good):
    data = good.read_bytes()
    files = {}
    files["missing"] = (tmp_path / "nope.mcap", "file not found")
    p = tmp_path / "text.mcap"
    p.write_text("this is not a recording\n")
    files["not_mcap"] = (p, "not an MCAP file")
    p = tmp_path / "empty.mcap"
    p.write_bytes(b"")
    files["empty"] = (p, "not an MCAP file")
    p = tmp_path / "cut.mcap"
    p.write_bytes(data[: len(data) // 2])
    files["truncated"] = (p, "damaged or incomplete MCAP file")
    p = tmp_path / "garbled.mcap"
    garbled = bytearray(data)
    mid = len(data) // 2
    garbled[mid : mid + 2000] = bytes(2000)  # inside the compressed chunk
    p.write_bytes(bytes(garbled))
    files["garbled"] = (p, "damaged or incomplete MCAP file|could not be decoded")
    p = tmp_path / "other.mcap"
    with open(p, "wb") as f:
        w = Writer(f)
        w.start(profile="ros2", library="test")
        sid = w.register_schema("std_msgs/msg/String", "ros2msg", b"string data\n")
        cid = w.register_channel("/chatter", "cdr", sid)
        w.add_message(cid, 1, b"\x00\x01\x00\x00\x01\x00\x00\x00\x00\x00\x00\x00", 1)
        w.finish()
    files["other_topics"] = (p, r"holds no mm_interfaces/msg/SensorData .*\(topics: /chatter\)")
    return files


@pytest.mark.parametrize(
    "kind", ["missing", "not_mcap", "empty", "truncated", "garbled", "other_topics"]
)
def test_bad_files_raise_a_clear_value_error(kind, recording, tmp_path):
    path, message = corrupt_files(tmp_path, recording[0])[kind]
    with pytest.raises(ValueError, match=message):
        read_replies(path)


# -- recording from the window -------------------------------------------------------------------


def test_record_from_the_window_and_stop(qtbot, tmp_path):
    window = make_window(qtbot, tmp_path)
    ctx = window.ctx
    path = tmp_path / "live.mcap"
    assert start_recording(window, path)
    assert ctx.recorder is not None and ctx.recorder.path == path
    assert window.record_action.text() == "Stop &recording"
    assert str(path) in window.statusBar().currentMessage()
    # the size the file would have if stopped now: the schemas and channels (~10 kB)
    assert window._recording_label.text() == recording_text(0.0, ctx.recorder.size_bytes())
    assert 5_000 < ctx.recorder.size_bytes() < 20_000
    assert str(path) in window._recording_label.toolTip()
    assert not start_recording(window, tmp_path / "second.mcap")  # one at a time
    assert "already recording" in window.statusBar().currentMessage()
    replies = list(sim_replies("straight", 50.0, 1.0))
    for r in replies:
        ctx.on_reply(r)
    toggle_recording(window)  # the menu action stops a running recording
    assert ctx.recorder is None
    assert window.record_action.text() == "&Record…"
    assert window._recording_label is None
    assert f"recorded {len(replies)} replies" in window.statusBar().currentMessage()
    assert read_replies(path) == replies
    assert stop_recording(window) is None  # nothing running: no-op


def test_single_polls_fetched_while_recording_go_into_the_file(qtbot, tmp_path):
    bridge = RosBridge("/mm_beagle", 100.0, node_name="mm_monitor_unused")  # never started
    window = make_window(qtbot, tmp_path, bridge)
    path = tmp_path / "polls.mcap"
    res = GetSamples.Response(success=True, first_seq=1, next_seq=2, stamp_ns=[9], dx=[4], dy=[5])
    bridge.samples_received.emit("/dev/spidev1.0", res)  # before: not recorded
    assert start_recording(window, path)
    bridge.samples_received.emit("/dev/spidev1.0", res)
    stop_recording(window)
    bridge.samples_received.emit("/dev/spidev1.0", res)  # after: no error, not recorded
    ((device, back),) = read_samples(path)
    assert device == "/dev/spidev1.0" and list(back.dx) == [4] and back.next_seq == 2


def test_menu_actions_ask_for_the_file_only_and_remember_the_folders(
    qtbot, tmp_path, monkeypatch, recording
):
    import mm_pc.monitor.recording as recording_mod
    import mm_pc.monitor.replay as replay_mod
    from mm_pc.monitor.settings import last_folder

    window = make_window(qtbot, tmp_path)
    folder = tmp_path / "runs"
    folder.mkdir()
    path = folder / "menu.mcap"
    starts = []

    def save(_parent, _title, start, _filter):
        starts.append(start)
        return str(path), ""

    monkeypatch.setattr(recording_mod.QFileDialog, "getSaveFileName", save)
    window.record_action.trigger()  # File > Record…
    assert window.ctx.recorder is not None and window.ctx.recorder.path == path
    window.record_action.trigger()  # File > Stop recording
    assert window.ctx.recorder is None and read_replies(path) == []
    assert last_folder("recording") == str(folder)
    assert not starts[0].startswith(str(folder))  # the first dialog: home, never the repo
    opened = []

    def open_(_parent, _title, start, _filter):
        opened.append(start)
        return str(recording[0]), ""

    monkeypatch.setattr(replay_mod.QFileDialog, "getOpenFileName", open_)
    assert not hasattr(replay_mod, "QInputDialog")  # no question besides the file
    window.open_replay()  # File > Replay… (read in the background, then started)
    assert opened == [str(folder)]
    qtbot.waitUntil(lambda: getattr(window, "replayer", None) is not None, timeout=10_000)
    replayer = window.replayer
    assert replayer.speed == 1.0  # nothing chosen on the bar yet
    assert last_folder("recording") == str(recording[0].parent)
    replayer.stop()
    monkeypatch.setattr(replay_mod.QFileDialog, "getOpenFileName", lambda *a, **k: ("", ""))
    window.open_replay()  # file dialog cancelled: nothing starts
    qtbot.wait(200)
    assert window.replayer is replayer


def test_unwritable_path_shows_why_and_attaches_nothing(qtbot, tmp_path):
    window = make_window(qtbot, tmp_path)
    bad = tmp_path / "no_such_dir" / "x.mcap"
    assert not start_recording(window, bad)
    assert window.ctx.recorder is None
    assert window.record_action.text() == "&Record…"
    msg = window.statusBar().currentMessage()
    assert f"cannot record to {bad}" in msg and "does not exist" in msg


def test_a_write_error_stops_the_recording_without_breaking_processing(qtbot, tmp_path):
    window = make_window(qtbot, tmp_path)
    ctx = window.ctx
    assert start_recording(window, tmp_path / "full.mcap")

    def disk_full(*_a, **_k):
        raise OSError(28, "No space left on device")

    ctx.recorder._writer.add_message = disk_full
    replies = list(sim_replies("straight", 50.0, 0.5))
    for r in replies:
        ctx.on_reply(r)  # must not raise
    assert ctx.session.stats.replies == len(replies)
    qtbot.waitUntil(lambda: ctx.recorder is None, timeout=2000)
    assert "No space left on device" in window.statusBar().currentMessage()
    assert window.record_action.text() == "&Record…"


# -- replay -------------------------------------------------------------------------------------


def run_replay(qtbot, window, path, speed):
    replayer = start_replay(window, path, speed)
    assert replayer is not None, window.statusBar().currentMessage()
    with qtbot.waitSignal(replayer.finished, timeout=20_000):
        pass
    return replayer


def assert_same_history(a: MonitorSession, b: MonitorSession):
    assert len(a.history) == len(b.history) > 0
    for name in a.history.columns:  # before the pose: the first differing row says more
        np.testing.assert_array_equal(a.history.column(name), b.history.column(name), name)
    assert a.pose == b.pose, (a.stats, b.stats, list(a.gaps), list(b.gaps))


def test_replay_at_max_speed_ends_where_the_live_session_ended(qtbot, tmp_path):
    live = make_window(qtbot, tmp_path)
    path = tmp_path / "fig8.mcap"
    start_recording(live, path)
    for r in sim_replies("figure_eight", 100.0, 8.0):
        live.ctx.on_reply(r)
    stop_recording(live)
    fresh = make_window(qtbot, tmp_path)
    replayer = run_replay(qtbot, fresh, path, "max")
    assert replayer.position == len(replayer.replies) == live.ctx.session.stats.replies
    assert_same_history(live.ctx.session, fresh.ctx.session)
    assert "ended: 801 of 801 replies" in fresh.statusBar().currentMessage()


def test_replay_at_1x_takes_the_recorded_time(qtbot, tmp_path):
    path = tmp_path / "two_s.mcap"
    rec = McapRecorder(path)
    for r in sim_replies("straight", 100.0, 2.0):
        rec.write_reply(r)
    rec.close()
    window = make_window(qtbot, tmp_path)
    t0 = time.monotonic()
    replayer = run_replay(qtbot, window, path, 1.0)
    took = time.monotonic() - t0
    assert 1.8 < took < 4.0
    assert replayer.position == 201
    assert window.ctx.session.pose.x == pytest.approx(0.4, abs=2e-5)  # CPI-quantised


def test_replay_replaces_what_the_session_showed(qtbot, tmp_path, recording):
    path, _ = recording
    fresh = make_window(qtbot, tmp_path)
    run_replay(qtbot, fresh, path, "max")
    used = make_window(qtbot, tmp_path)
    for r in sim_replies("meander", 100.0, 5.0, start_ns=1_800_000_000_000_000_000):
        used.ctx.on_reply(r)  # same sensors, far-away totals and stamps
    session = used.ctx.session
    run_replay(qtbot, used, path, "max")
    assert used.ctx.session is session  # same sensors: reset, not replaced
    assert_same_history(fresh.ctx.session, session)
    assert session.history.column("t")[0] == pytest.approx(0.01)


def test_replay_of_other_sensors_gets_a_new_session_with_the_same_settings(qtbot, tmp_path):
    path = tmp_path / "other.mcap"
    rec = McapRecorder(path)
    for r in sim_replies("straight", 50.0, 1.0, devices=("/dev/a", "/dev/b")):
        rec.write_reply(r)
    rec.close()
    window = make_window(qtbot, tmp_path)
    for r in sim_replies("straight", 50.0, 0.5):
        window.ctx.on_reply(r)
    window.ctx.session.configure_odometry(method="two-sensor")
    old = window.ctx.session
    run_replay(qtbot, window, path, "max")
    new = window.ctx.session
    assert new is not old and new.devices == ("/dev/a", "/dev/b")
    assert new.method == "two-sensor" and new.calibration is old.calibration
    assert new.pose.x == pytest.approx(0.2, abs=2e-5)


def test_a_recording_with_more_sensors_than_mounts_is_refused(qtbot, tmp_path):
    path = tmp_path / "three.mcap"
    rec = McapRecorder(path)
    mounts = (*DEFAULT_MOUNTS, SensorMount(-0.05, 0.0))
    for r in sim_replies(
        "straight", 50.0, 0.2, devices=("/dev/a", "/dev/b", "/dev/c"), mounts=mounts
    ):
        rec.write_reply(r)
    rec.close()
    window = make_window(qtbot, tmp_path)
    before = session_state(window.ctx.session)
    assert start_replay(window, path, "max") is None
    assert "3 sensors need 3 mounts, the geometry has 2" in window.statusBar().currentMessage()
    assert session_state(window.ctx.session) == before


@pytest.mark.parametrize(  # a truncated one replays up to its cut: test_monitor_replay_cut.py
    "kind", ["missing", "not_mcap", "empty", "garbled", "other_topics"]
)
def test_bad_file_replay_shows_a_message_and_changes_nothing(kind, qtbot, tmp_path, recording):
    path, message = corrupt_files(tmp_path, recording[0])[kind]
    bridge = RosBridge("/mm_beagle", 100.0, node_name="mm_monitor_unused")  # never started
    window = make_window(qtbot, tmp_path, bridge)
    for r in sim_replies("straight", 50.0, 0.5):
        window.ctx.on_reply(r)
    session = window.ctx.session
    before = session_state(session)
    assert start_replay(window, path, "max") is None
    assert window.ctx.session is session and session_state(session) == before
    assert bridge.polling
    import re

    shown = window.statusBar().currentMessage()
    assert shown.startswith("replay: ") and re.search(message, shown), shown
    assert getattr(window, "replayer", None) is None


def test_bad_speed_is_refused(qtbot, tmp_path, recording):
    for bad in ("fast", "0", "-2x", "nan", ""):
        with pytest.raises(ValueError, match="replay speed must be"):
            parse_speed(bad)
    assert parse_speed("5x") == 5.0 and parse_speed(2) == 2.0 and parse_speed("max") == math.inf
    window = make_window(qtbot, tmp_path)
    before = session_state(window.ctx.session)
    assert start_replay(window, recording[0], "slow") is None
    assert "replay speed must be" in window.statusBar().currentMessage()
    assert session_state(window.ctx.session) == before


def test_live_bridge_is_paused_and_disconnected_while_replaying(qtbot, tmp_path, recording):
    path, _ = recording
    bridge = RosBridge("/mm_beagle", 100.0, node_name="mm_monitor_unused")  # never started
    window = make_window(qtbot, tmp_path, bridge)
    live = list(sim_replies("straight", 50.0, 1.0, start_ns=1_800_000_000_000_000_000))
    for r in live[:20]:
        bridge.data_received.emit([r])  # as the bridge thread would
    assert window.ctx.session.stats.replies == 20
    replayer = start_replay(window, path, 10.0)
    assert not bridge.polling
    n = window.ctx.session.stats.replies
    bridge.data_received.emit([live[20]])  # a reply still in flight: ignored
    assert window.ctx.session.stats.replies == n
    replayer.pause()
    pos = replayer.position
    qtbot.wait(100)
    assert replayer.position == pos and not replayer.running
    replayer.start()
    with qtbot.waitSignal(replayer.finished, timeout=10_000):
        pass
    assert not bridge.polling  # ended: the replayed path stays, live data waits
    rows = len(window.ctx.session.history)
    bridge.data_received.emit([live[21]])
    assert len(window.ctx.session.history) == rows  # never added to the replayed path
    window.leave_replay()  # Back to live: a new path
    assert bridge.polling
    assert len(window.ctx.session.history) == 0
    bridge.data_received.emit([live[21]])  # a new baseline at t = 0, no jump
    bridge.data_received.emit([live[22]])
    assert len(window.ctx.session.history) == 1
    assert window.ctx.session.history.column("t")[0] == pytest.approx(0.02)
    assert window.ctx.session.pose.x == pytest.approx(0.004, abs=2e-5)


def test_stop_ends_the_replay_early(qtbot, tmp_path, recording):
    window = make_window(qtbot, tmp_path)
    replayer = start_replay(window, recording[0], 1.0)
    qtbot.wait(100)
    with qtbot.waitSignal(replayer.finished, timeout=1000):
        replayer.stop()
    assert 0 < replayer.position < len(replayer.replies)
    assert not replayer.running and replayer.done
    assert isinstance(replayer, Replayer)


# -- against the real node -----------------------------------------------------------------------


#: the module-wide mm-beagle of tests/monitor/conftest.py
BEAGLE_PARAMS = {"backend": "sim", "sim_trajectory": "figure_eight"}


@pytest.mark.ros
def test_recording_live_replies_from_the_node_and_replaying_them(qtbot, tmp_path, beagle_node):
    bridge = RosBridge("/mm_beagle", 100.0, node_name="mm_monitor_rec_test")
    bridge.set_polling(False)
    window = make_window(qtbot, tmp_path, bridge)
    path = tmp_path / "node.mcap"
    try:
        bridge.start()
        assert start_recording(window, path)
        bridge.set_polling(True)
        qtbot.waitUntil(lambda: bridge.replies >= 200, timeout=25_000)  # ~2 s at 100 Hz
        bridge.set_polling(False)
        qtbot.wait(400)  # the last request in flight is answered
        stop_recording(window)
    finally:
        bridge.stop()
    live = window.ctx.session
    back = read_replies(path)
    assert len(back) == bridge.replies == live.stats.replies
    assert {r.id for r in back[-1].readings} == {"/dev/spidev1.0", "/dev/spidev1.1"}
    assert all(0 < r.rtt_s < 2.0 for r in back)
    assert live.pose != MonitorSession().pose  # the robot moved
    fresh = make_window(qtbot, tmp_path)
    run_replay(qtbot, fresh, path, "max")
    assert_same_history(live, fresh.ctx.session)


def test_a_recording_read_in_the_background_then_replays(qtbot, tmp_path):
    """File > Replay reads on a worker thread; the window keeps running meanwhile."""
    from mm_pc.monitor.replay import load_in_background

    path = write_straight_run(tmp_path / "bg.mcap", 1.0)
    window = make_window(qtbot, tmp_path)
    ctx = window.ctx
    future = load_in_background(window, path, "max")
    assert "reading bg.mcap" in window.statusBar().currentMessage()
    qtbot.waitUntil(lambda: getattr(window, "replayer", None) is not None, timeout=10_000)
    qtbot.waitUntil(lambda: window.replayer.done, timeout=10_000)
    assert future.result()[0] == float("inf")
    assert ctx.session.pose.x == pytest.approx(0.2, abs=1e-3)
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(b"not an mcap")
    load_in_background(window, bad, 1.0)
    qtbot.waitUntil(lambda: "replay:" in window.statusBar().currentMessage(), timeout=10_000)


def test_stop_replay_ends_a_running_replay(qtbot, tmp_path):
    path = write_straight_run(tmp_path / "run.mcap", 3.0)
    window = make_window(qtbot, tmp_path)
    window.stop_replay()
    assert "no replay is running" in window.statusBar().currentMessage()
    replayer = start_replay(window, path, speed=1.0)
    assert replayer is not None and not replayer.done
    qtbot.wait(300)
    window.stop_replay()
    assert replayer.done
    used = window.ctx.session.stats.used
    assert 0 < used < 60  # stopped part-way through the 3 s at 20 Hz
    qtbot.wait(300)
    assert window.ctx.session.stats.used == used


def test_recorded_polls_replay_to_the_same_per_poll_pose(tmp_path, qtbot):
    """Replies with their single polls (one fetch failed) are recorded and come back; a
    replay integrates them per poll to the live pose, and says so."""
    from fakes import FakeRing
    from test_monitor_session import DEVS, _poll_replies

    from mm_pc.monitor.replay import pose_source
    from mm_pc.sim.robot import trajectory

    v, w = trajectory("s_curves")
    ring = FakeRing(v[:4000], w[:4000])
    replies = _poll_replies(ring, [0, 700, 1400, 2000, 3000, 4000], skip=(2000,))
    live = MonitorSession(devices=DEVS)
    for r in replies:
        live.process(r)
    path = tmp_path / "polls.mcap"
    rec = McapRecorder(path)
    for r in replies:
        rec.write_reply(r)
    rec.close()
    back = read_replies(path)
    assert [r.polls is not None for r in back] == [True] * len(replies)
    assert back[3].polls[DEVS[1]] is None and back[3].polls[DEVS[0]] is not None
    assert list(back[2].polls[DEVS[0]].dx) == list(replies[2].polls[DEVS[0]].dx)
    again = MonitorSession(devices=DEVS)
    for r in back:
        again.process(r)
    assert again.pose == live.pose
    assert (again.stats.polls, again.stats.gaps) == (live.stats.polls, live.stats.gaps) == (3400, 1)
    assert "pose per poll" in pose_source(back)
    old = [Reply(r.readings, r.received_s, r.rtt_s) for r in back]
    assert "no single polls" in pose_source(old)


def test_recordings_made_before_the_node_identity_still_decode():
    """SensorData / GetSamples' response bytes from before instance_id was appended."""
    from rclpy.serialization import serialize_message

    from mm_interfaces.msg import LegacySensorData as SensorData  # before its header
    from mm_interfaces.srv import GetSamples
    from mm_pc.monitor.io import cdr

    new = serialize_message(SensorData(id="/dev/spidev1.0", seq=42, y_total_disp=0.5,
                                       instance_id=99))  # fmt: skip
    assert cdr.deserialize_appended(new, SensorData).instance_id == 99
    before_id = new[: new.rfind((99).to_bytes(8, "little"))]  # the layout before issue 13
    old = cdr.deserialize_appended(before_id, SensorData)
    assert (old.id, old.seq, old.y_total_disp, old.instance_id) == ("/dev/spidev1.0", 42, 0.5, 0)
    res = serialize_message(GetSamples.Response(success=True, first_seq=3, next_seq=4, dx=[5],
                                                flags=[1, 2, 9], instance_id=7))  # fmt: skip
    assert cdr.deserialize_appended(res, GetSamples.Response).instance_id == 7
    # the old layout ended with the flags (not 8-aligned): no padding, no instance_id
    old_bytes = res[: res.rfind(bytes([1, 2, 9])) + 3]
    assert len(res) - len(old_bytes) > 8
    old = cdr.deserialize_appended(old_bytes, GetSamples.Response)
    assert (old.first_seq, list(old.dx), list(old.flags), old.instance_id) == (3, [5], [1, 2, 9], 0)


def test_recordings_made_before_the_chip_fields_still_decode():
    """SensorData / SensorPolls bytes from before chip and quality were appended (issue 15)."""
    from rclpy.serialization import serialize_message

    from mm_interfaces.msg import LegacySensorData as SensorData  # before its header
    from mm_interfaces.msg import SensorPolls
    from mm_pc.monitor.io import cdr

    new = serialize_message(SensorData(id="/dev/spidev1.0", seq=7, instance_id=99, chip="pmw3360",
                                       quality=40, low_quality_events=2))  # fmt: skip
    got = cdr.deserialize_appended(new, SensorData)
    assert (got.chip, got.quality, got.low_quality_events) == ("pmw3360", 40, 2)
    # the old layout ended with instance_id: cut the appended fields off
    before = serialize_message(SensorData(id="/dev/spidev1.0", seq=7, instance_id=99))
    old_bytes = before[: before.rfind((99).to_bytes(8, "little")) + 8]
    old = cdr.deserialize_appended(old_bytes, SensorData)
    assert (old.seq, old.instance_id, old.chip, old.quality) == (7, 99, "", 0)
    polls = serialize_message(SensorPolls(first_seq=1, next_seq=3, dx=[4, 5], flags=[2, 34],
                                          quality=[50, 3]))  # fmt: skip
    got = cdr.decode_polls(POLLS_TYPE, polls)
    assert list(got.quality) == [50, 3] and list(got.flags) == [2, 34]
    old_polls = polls[: polls.rfind(bytes([2, 34])) + 2]
    got = cdr.decode_polls(POLLS_TYPE, old_polls)
    assert (list(got.dx), list(got.flags), list(got.quality)) == ([4, 5], [2, 34], [])


def test_an_old_recording_reads_as_a_pln2033_without_a_quality_figure():
    """The zero-filled quality of a reply from before issue 15 is no SQUAL 0."""
    from mm_interfaces.msg import LegacySensorData
    from mm_pc.monitor.io import cdr
    from mm_pc.monitor.model.chips import chip_title, quality_figure

    before = serialize_message(LegacySensorData(id="/dev/spidev1.0", seq=7, instance_id=99))
    old_bytes = before[: before.rfind((99).to_bytes(8, "little")) + 8]
    r = Reading.from_msg(cdr.decode_sensor_data(old_bytes, legacy=True))
    assert (r.chip, r.quality, r.low_quality_events) == ("", -1, 0)
    assert (r.frame_id, r.header_stamp_ns) == ("", 0)  # no header either
    assert chip_title(r.chip) == "Philips PLN2033" and math.isnan(quality_figure(r.chip, 0))
    new = SensorData(id="/dev/spidev1.0", seq=7, chip="pmw3360", quality=0)
    assert Reading.from_msg(new).quality == 0  # a real SQUAL 0 stays 0


def test_per_poll_quality_is_recorded_and_old_polls_without_it_replay(tmp_path):
    """The quality arrays go into the file and come back; polls recorded without them
    (empty arrays) give the same per-poll pose."""
    from fakes import FakeRing
    from test_monitor_session import DEVS, _poll_replies

    from mm_pc.sim.robot import trajectory

    v, w = trajectory("s_curves")
    poor = np.zeros(3000, bool)
    poor[1200:1260] = True
    ring = FakeRing(v[:3000], w[:3000], low_quality=poor, quality_ok=90, quality_low=3)
    replies = _poll_replies(ring, [0, 700, 1400, 2000, 3000])
    path = tmp_path / "q.mcap"
    rec = McapRecorder(path)
    for r in replies:
        rec.write_reply(r)
    rec.close()
    back = read_replies(path)
    got = back[2].polls[DEVS[0]]
    assert list(got.quality) == [int(q) for q in replies[2].polls[DEVS[0]].quality]
    assert sorted(set(got.quality)) == [3, 90] and list(got.flags).count(34) == 60

    def without_quality(reply):
        return Reply(reply.readings, reply.received_s, reply.rtt_s,
                     {d: _strip(p) for d, p in reply.polls.items()})

    def _strip(p):
        from types import SimpleNamespace
        return SimpleNamespace(**{**{k: getattr(p, k) for k in (
            "first_seq", "next_seq", "dropped", "cpi", "stamp_ns", "dx", "dy", "status",
            "flags")}, "quality": ()})

    path_old = tmp_path / "old.mcap"
    rec = McapRecorder(path_old)
    for r in replies:
        rec.write_reply(without_quality(r))
    rec.close()
    old = read_replies(path_old)
    assert list(old[2].polls[DEVS[0]].quality) == []
    a, b = MonitorSession(devices=DEVS), MonitorSession(devices=DEVS)
    for r in back:
        a.process(r)
    for r in old:
        b.process(r)
    assert a.pose == b.pose and a.stats.polls == b.stats.polls == 3000


def test_the_status_bar_shows_elapsed_time_and_size_while_recording(qtbot, tmp_path):
    assert recording_text(83.9, 1_420_000) == "● REC 01:23 1.4 MB"
    assert recording_text(3725, 2_500_000_000) == "● REC 1:02:05 2.50 GB"
    assert recording_text(0, 512) == "● REC 00:00 1 kB"
    window = make_window(qtbot, tmp_path)
    path = tmp_path / "long.mcap"
    assert start_recording(window, path)
    for r in sim_replies("figure_eight", 100.0, 30.0):  # enough for chunks on disk
        window.ctx.on_reply(r)
    window._recording_began = time.monotonic() - 75.0  # as if it began 75 s ago
    label = window._recording_label
    qtbot.waitUntil(lambda: " 01:1" in label.text(), timeout=3000)  # the 1 s update
    assert path.stat().st_size > 100_000  # chunks on disk
    size = window.ctx.recorder.size_bytes()  # and the chunk still in memory
    assert size > path.stat().st_size
    assert label.text() in (recording_text(s, size) for s in (75, 76, 77))
    stop_recording(window)
    assert window._recording_label is None
    assert abs(path.stat().st_size - size) <= 0.005 * size  # what the file came to
