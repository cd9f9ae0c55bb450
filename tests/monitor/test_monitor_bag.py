"""Recordings that ROS tools read without this code: rosbags (AnyReader, and its rosbag2
reader of metadata.yaml) and mcap-ros2-support decode every message of every channel."""

from __future__ import annotations

import os
import subprocess
import sys
from collections import Counter
from pathlib import Path

import pytest

pytest.importorskip("rclpy")
pytest.importorskip("PySide6")
pytest.importorskip("rosbags")
pytest.importorskip("mcap_ros2")

import yaml
from mcap.reader import make_reader
from mcap.writer import Writer
from mcap_ros2.decoder import DecoderFactory
from rclpy.serialization import serialize_message
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from mm_interfaces.msg import SensorData
from mm_interfaces.srv import GetSamples
from mm_pc.monitor.io.bag_format import (
    SENSOR_DATA_QOS,
    TF_STATIC_QOS,
    bag_files,
    live_topics,
    recording_target,
)
from mm_pc.monitor.io.mcap_reader import read_replies, read_samples
from mm_pc.monitor.io.mcap_writer import McapRecorder
from mm_pc.monitor.io.schemas import (
    LEGACY_POLLS_TYPE,
    META_TOPIC,
    REPLY_POLLS_TOPIC,
    SENSOR_TOPIC,
    ros2msg_definition,
)
from mm_pc.monitor.model.session import MonitorSession

ROOT = Path(__file__).resolve().parents[2]
DEVS = ("/dev/spidev1.0", "/dev/spidev1.1")


def source_typestore():
    """Jazzy's types plus mm_interfaces' messages parsed from the .msg files of this repo."""
    store = get_typestore(Stores.ROS2_JAZZY)
    types = {}
    for f in sorted((ROOT / "mm_interfaces" / "msg").glob("*.msg")):
        types.update(get_types_from_msg(f.read_text(), f"mm_interfaces/msg/{f.stem}"))
    store.register(types)
    return store


def decode_everything(path: Path) -> dict[str, list]:
    """Decode every message three ways; assert they agree on the topics and counts.

    1. rosbags' AnyReader with the types embedded in the MCAP schemas (on a
       folder it reads metadata.yaml);
    2. rosbags' typestore with mm_interfaces from the .msg source files;
    3. mcap-ros2-support's decoder. Returns {topic: [AnyReader's messages]}.
    """
    by_anyreader: dict[str, list] = {}
    with AnyReader([path], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
        for con, _t, raw in reader.messages():
            by_anyreader.setdefault(con.topic, []).append(reader.deserialize(raw, con.msgtype))
    store = source_typestore()
    by_source, by_mcap_ros2 = Counter(), Counter()
    for file in bag_files(path):
        with open(file, "rb") as f:
            for schema, channel, message in make_reader(f).iter_messages():
                store.deserialize_cdr(message.data, schema.name)
                by_source[channel.topic] += 1
        with open(file, "rb") as f:
            reader = make_reader(f, decoder_factories=[DecoderFactory()])
            for _s, channel, _m, decoded in reader.iter_decoded_messages():
                assert decoded is not None
                by_mcap_ros2[channel.topic] += 1
    counts = Counter({k: len(v) for k, v in by_anyreader.items()})
    assert counts == by_source == by_mcap_ros2
    return by_anyreader


def poll_replies():
    """Replies of two sensors with their single polls (one fetch failed), from a fake ring."""
    from fakes import FakeRing
    from test_monitor_session import _poll_replies

    from mm_pc.sim.robot import trajectory

    v, w = trajectory("s_curves")
    return _poll_replies(FakeRing(v[:2000], w[:2000]), [0, 500, 1000, 1500, 2000], skip=(1000,))


def live_messages():
    """(topic, type, CDR bytes) of one message on each kind of live topic."""
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
    from nav_msgs.msg import Odometry
    from rclpy.clock import Clock
    from tf2_msgs.msg import TFMessage

    from mm_pc.ros.tf import planar_transform

    stamp = Clock().now().to_msg()
    odom = Odometry()
    odom.header.stamp, odom.header.frame_id, odom.child_frame_id = stamp, "odom", "base_link"
    odom.pose.pose.position.x = 1.25
    tf = TFMessage(transforms=[planar_transform(stamp, "odom", "base_link", 1.25, -0.5, 0.3)])
    static = TFMessage(
        transforms=[planar_transform(stamp, "base_link", "mouse0", 0.1, 0.0, 0.0)]
    )
    diag = DiagnosticArray(status=[DiagnosticStatus(name="/mm_beagle: x", message="OK")])
    sensor = SensorData(id=DEVS[0], seq=7, x_total_counts=-3)
    types = {t.name: t.type_name for t in live_topics()}
    out = [
        ("/mm_odometry/odom", odom),
        ("/tf", tf),
        ("/tf_static", static),
        ("/diagnostics", diag),
        ("/mm_beagle/sensor_data", sensor),
    ]
    return [(topic, types[topic], serialize_message(m)) for topic, m in out]


def write_everything(path: Path) -> tuple[McapRecorder, list]:
    replies = poll_replies()
    rec = McapRecorder(path, rate_hz=100.0)
    res = GetSamples.Response(
        success=True, first_seq=3, next_seq=5, cpi=1600, stamp_ns=[11, 12], dx=[1, -2],
        dy=[3, 4], status=[128, 129], flags=[2, 3],
    )  # fmt: skip
    rec.write_samples(DEVS[1], res)
    for k, r in enumerate(replies):
        rec.write_reply(r)
        for topic, type_name, data in live_messages():
            if topic == "/tf_static" and k:
                continue  # latched: once
            qos = [TF_STATIC_QOS] if topic == "/tf_static" else None
            rec.write_live(topic, type_name, data, qos)
    rec.close()
    return rec, replies


def test_every_channel_of_a_file_decodes_with_rosbags_and_mcap_ros2(tmp_path):
    rec, replies = write_everything(tmp_path / "all.mcap")
    msgs = decode_everything(tmp_path / "all.mcap")
    assert Counter({k: len(v) for k, v in msgs.items()}) == Counter(rec.topic_counts())
    n = len(replies)
    assert len(msgs[SENSOR_TOPIC]) == 2 * n and len(msgs[META_TOPIC]) == n
    dev0 = f"{REPLY_POLLS_TOPIC}/dev/spidev1_0"
    polls = msgs[dev0]
    assert len(polls) == n and polls[0].__msgtype__ == "mm_interfaces/msg/SensorPolls"
    want = replies[2].polls[DEVS[0]]
    assert polls[2].id == DEVS[0] and list(polls[2].dx) == list(want.dx)
    assert (polls[2].first_seq, polls[2].next_seq) == (want.first_seq, want.next_seq)
    newest = int(want.stamp_ns[-1])
    assert polls[2].stamp.sec * 10**9 + polls[2].stamp.nanosec == newest
    # the failed fetch of sensor 1 in the third reply has no message
    assert len(msgs[f"{REPLY_POLLS_TOPIC}/dev/spidev1_1"]) == n - 1
    (sample,) = msgs["/mm_monitor/samples/dev/spidev1_1"]
    assert list(sample.dy) == [3, 4] and sample.next_seq == 5 and sample.stamp.nanosec == 12
    assert msgs["/mm_odometry/odom"][-1].pose.pose.position.x == 1.25
    assert msgs["/tf"][0].transforms[0].child_frame_id == "base_link"
    assert len(msgs["/tf_static"]) == 1 and len(msgs["/tf"]) == n
    assert msgs["/mm_beagle/sensor_data"][0].x_total_counts == -3
    # the replay reads only the monitor's own SensorData channel, not the live one
    assert len(read_replies(tmp_path / "all.mcap")) == n
    with open(tmp_path / "all.mcap", "rb") as f:
        summary = make_reader(f).get_summary()
    for c in summary.channels.values():
        assert "/srv/" not in summary.schemas[c.schema_id].name
        profiles = yaml.safe_load(c.metadata["offered_qos_profiles"])
        assert profiles[0]["reliability"] in ("reliable", "best_effort")
        assert c.metadata["topic_type_hash"].startswith("RIHS01_")
    static = next(c for c in summary.channels.values() if c.topic == "/tf_static")
    assert yaml.safe_load(static.metadata["offered_qos_profiles"])[0]["durability"] == (
        "transient_local"
    )


def metadata_records(path: Path) -> dict[str, list[dict[str, str]]]:
    """name -> the fields of each MCAP Metadata record of that name, read by the mcap library."""
    out: dict[str, list[dict[str, str]]] = {}
    with open(path, "rb") as f:
        for record in make_reader(f).iter_metadata():
            out.setdefault(record.name, []).append(dict(record.metadata))
    return out


def test_a_file_carries_rosbag2s_metadata_record_as_jazzy_writes_it(tmp_path):
    from rosbags.rosbag2 import Reader

    path = tmp_path / "all.mcap"
    rec, replies = write_everything(path)
    records = metadata_records(path)
    assert sorted(records) == ["mm_monitor", "rosbag2"]
    ((fields,),) = [records["rosbag2"]]
    # the name and keys rosbag2's MCAP plugin reads (read_metadata): Jazzy's
    # serialized_metadata, and the ROS_DISTRO key Humble and Iron wrote
    assert sorted(fields) == ["ROS_DISTRO", "serialized_metadata"]
    assert fields["ROS_DISTRO"] == "jazzy"
    info = yaml.safe_load(fields["serialized_metadata"])
    assert "rosbag2_bagfile_information" not in info  # the inner mapping, as rosbag2's
    assert info["version"] == 9 and info["storage_identifier"] == "mcap"
    assert info["ros_distro"] == "jazzy"
    assert info["relative_file_paths"] == ["all.mcap"]
    counts = rec.topic_counts()
    topics = {t["topic_metadata"]["name"]: t for t in info["topics_with_message_count"]}
    assert {name: t["message_count"] for name, t in topics.items()} == counts
    assert info["message_count"] == sum(counts.values()) == info["files"][0]["message_count"]
    assert counts[SENSOR_TOPIC] == 2 * len(replies)
    types = {name: t["topic_metadata"] for name, t in topics.items()}
    assert types[SENSOR_TOPIC]["type"] == "mm_interfaces/msg/SensorData"
    assert types["/tf_static"]["offered_qos_profiles"][0]["durability"] == "transient_local"
    assert types[SENSOR_TOPIC]["type_description_hash"].startswith("RIHS01_")
    with open(path, "rb") as f:
        stats = make_reader(f).get_summary().statistics
    assert stats.message_count == info["message_count"]
    assert info["starting_time"]["nanoseconds_since_epoch"] == stats.message_start_time
    assert info["duration"]["nanoseconds"] == stats.message_end_time - stats.message_start_time
    assert info["duration"]["nanoseconds"] > 0
    with Reader(path) as reader:  # rosbags still reads the bare file
        assert reader.message_count == sum(counts.values())
        assert {t: i.msgcount for t, i in reader.topics.items()} == counts
        assert reader.duration == stats.message_end_time - stats.message_start_time + 1
    assert [r.readings for r in read_replies(path)] == [r.readings for r in replies]


def test_an_empty_recording_has_a_rosbag2_record_of_no_messages(tmp_path):
    McapRecorder(tmp_path / "empty.mcap").close()
    ((fields,),) = [metadata_records(tmp_path / "empty.mcap")["rosbag2"]]
    info = yaml.safe_load(fields["serialized_metadata"])
    assert info["message_count"] == 0 and info["duration"] == {"nanoseconds": 0}
    assert {t["topic_metadata"]["name"] for t in info["topics_with_message_count"]} == {
        SENSOR_TOPIC, META_TOPIC
    }  # fmt: skip


def test_a_folder_gets_a_rosbag2_metadata_yaml_that_rosbags_reads(tmp_path):
    from rosbags.rosbag2 import Reader

    folder = tmp_path / "run"
    rec, replies = write_everything(folder)
    assert sorted(p.name for p in folder.iterdir()) == ["metadata.yaml", "run_0.mcap"]
    counts = rec.topic_counts()
    with Reader(folder) as reader:  # rosbags' own rosbag2 reader: parses metadata.yaml
        assert reader.message_count == sum(counts.values())
        assert {t: i.msgcount for t, i in reader.topics.items()} == counts
        assert reader.topics["/mm_monitor/reply_polls/dev/spidev1_0"].msgtype == (
            "mm_interfaces/msg/SensorPolls"
        )
        assert reader.duration > 0 and reader.start_time > 1.7e18
        qos = {c.topic: c.ext.offered_qos_profiles[0] for c in reader.connections}
        assert qos["/tf_static"].durability.name == "TRANSIENT_LOCAL"
        assert qos[SENSOR_TOPIC].reliability.name == "RELIABLE"
    info = yaml.safe_load((folder / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert info["version"] == 9 and info["storage_identifier"] == "mcap"
    # the file's rosbag2 record holds the very same metadata
    ((fields,),) = [metadata_records(folder / "run_0.mcap")["rosbag2"]]
    assert yaml.safe_load(fields["serialized_metadata"]) == info
    assert info["relative_file_paths"] == ["run_0.mcap"]
    assert info["files"][0]["message_count"] == info["message_count"]
    store = source_typestore()
    for t in info["topics_with_message_count"]:
        meta = t["topic_metadata"]
        assert meta["serialization_format"] == "cdr"
        # the hash of the installed type description = rosbags' own from the .msg text
        assert meta["type_description_hash"] == store.hash_rihs01(meta["type"]), meta["name"]
    decode_everything(folder)
    back = read_replies(folder)
    assert [r.readings for r in back] == [r.readings for r in replies]
    assert list(back[2].polls[DEVS[0]].dx) == list(replies[2].polls[DEVS[0]].dx)
    # File > Replay picks the folder's metadata.yaml: the same recording
    assert [r.readings for r in read_replies(folder / "metadata.yaml")] == [
        r.readings for r in back
    ]
    ((device, res),) = read_samples(folder)
    assert device == DEVS[1] and list(res.flags) == [2, 3]


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (lambda p: p / "nodir" / "x.mcap", "does not exist"),
        (lambda p: p / "nodir" / "bag", "does not exist"),
        (lambda p: (p / "full").mkdir() or (p / "full" / "a").write_text("") or p / "full",
         "is not empty"),
        (lambda p: (p / "plain").write_text("") or p / "plain", "needs the .mcap suffix"),
        (lambda p: (p / "d.mcap").mkdir() or p / "d.mcap", "is a folder"),
    ],
)  # fmt: skip
def test_a_path_that_cannot_take_a_recording_is_refused_and_nothing_created(
    tmp_path, make, message
):
    path = make(tmp_path)
    before = sorted(tmp_path.rglob("*"))
    with pytest.raises(ValueError, match=message):
        recording_target(path)
    with pytest.raises(ValueError, match=message):
        McapRecorder(path)
    assert sorted(tmp_path.rglob("*")) == before


def test_an_empty_folder_takes_a_recording(tmp_path):
    (tmp_path / "empty").mkdir()
    assert recording_target(tmp_path / "empty") == (
        tmp_path / "empty" / "empty_0.mcap", tmp_path / "empty"
    )  # fmt: skip


def test_a_broken_metadata_yaml_is_a_clear_error(tmp_path):
    folder = tmp_path / "bag"
    write_everything(folder)
    (folder / "metadata.yaml").write_text("rosbag2_bagfile_information: [1, 2\n")
    with pytest.raises(ValueError, match="no rosbag2 metadata file"):
        read_replies(folder)
    (folder / "metadata.yaml").write_text(
        "rosbag2_bagfile_information: {storage_identifier: sqlite3, relative_file_paths: [a]}"
    )
    with pytest.raises(ValueError, match="storage 'sqlite3'"):
        read_replies(folder)
    empty = tmp_path / "nothing"
    empty.mkdir()
    with pytest.raises(ValueError, match="holds no recording"):
        read_replies(empty)


def write_legacy(path: Path, replies) -> None:
    """A recording as the monitor wrote it before SensorPolls: the polls as
    GetSamples_Response on /mm_monitor/reply_polls/<device>."""
    from std_msgs.msg import Float64MultiArray

    from mm_pc.monitor.io.cdr import serialize_reading

    qos = {"offered_qos_profiles": ""}
    with open(path, "wb") as f:
        w = Writer(f)
        w.start(profile="ros2", library="mm_monitor")

        def channel(topic: str, type_name: str, **meta) -> int:
            sid = w.register_schema(type_name, "ros2msg", ros2msg_definition(type_name).encode())
            return w.register_channel(topic, "cdr", sid, {**qos, **meta})

        sensor = channel(SENSOR_TOPIC, "mm_interfaces/msg/SensorData")
        meta = channel(META_TOPIC, "std_msgs/msg/Float64MultiArray")
        polls = {
            d: channel(f"{REPLY_POLLS_TOPIC}/{d.strip('/').replace('.', '_')}",
                       LEGACY_POLLS_TYPE, device=d)
            for d in DEVS
        }  # fmt: skip
        for seq, rep in enumerate(replies):
            t = 1_700_000_000_000_000_000 + seq * 10_000_000
            data = [rep.received_s, rep.rtt_s, 1.0]
            w.add_message(meta, t, serialize_message(Float64MultiArray(data=data)), t, seq)
            for r in rep.readings:
                w.add_message(sensor, t, serialize_reading(r), r.stamp_ns, seq)
            for dev, res in rep.polls.items():
                if res is None:
                    continue
                msg = GetSamples.Response(
                    success=True, first_seq=res.first_seq, next_seq=res.next_seq,
                    dropped=res.dropped, cpi=res.cpi, stamp_ns=list(res.stamp_ns),
                    dx=list(res.dx), dy=list(res.dy), status=list(res.status),
                    flags=list(res.flags),
                )  # fmt: skip
                w.add_message(polls[dev], t, serialize_message(msg), t, seq)
        w.finish()


def test_an_old_recording_with_getsamples_responses_still_replays_per_poll(tmp_path):
    replies = poll_replies()
    live = MonitorSession(devices=DEVS)
    for r in replies:
        live.process(r)
    old, new = tmp_path / "old.mcap", tmp_path / "new.mcap"
    write_legacy(old, replies)
    rec = McapRecorder(new)
    for r in replies:
        rec.write_reply(r)
    rec.close()
    for path in (old, new):
        back = read_replies(path)
        assert back[2].polls[DEVS[1]] is None  # the failed fetch
        assert list(back[3].polls[DEVS[1]].dx) == list(replies[3].polls[DEVS[1]].dx)
        again = MonitorSession(devices=DEVS)
        for r in back:
            again.process(r)
        assert again.pose == live.pose
        assert (again.stats.polls, again.stats.gaps) == (live.stats.polls, live.stats.gaps)
        assert again.stats.polls == 1500  # 2000 polls, the 500 of the failed fetch stepped over
    with open(old, "rb") as f:
        kinds = {s.name for s, _c, _m in make_reader(f).iter_messages()}
    assert LEGACY_POLLS_TYPE in kinds  # the file is the old layout
    # recordings made before the rosbag2 metadata record replay without it
    assert metadata_records(old) == {}
    assert "rosbag2" in metadata_records(new)


def test_the_live_topics_and_their_qos():
    topics = {t.name: t for t in live_topics("/robot1/mm_beagle")}
    assert set(topics) == {
        "/robot1/mm_beagle/sensor_data", "/robot1/mm_odometry/odom", "/robot1/mm_beagle/odom",
        "/robot1/mm_fusion/odom", "/tf", "/tf_static", "/diagnostics",
    }  # fmt: skip
    assert topics["/robot1/mm_beagle/sensor_data"].qos == SENSOR_DATA_QOS
    assert SENSOR_DATA_QOS["reliability"] == "best_effort"
    assert topics["/tf_static"].qos["durability"] == "transient_local"
    # the recording states the broadcaster's depth 1; the recorder listens with tf2_ros's 100
    assert topics["/tf_static"].qos["depth"] == 1
    assert topics["/tf_static"].subscription_qos == {**TF_STATIC_QOS, "depth": 100}
    assert topics["/tf"].subscription_qos == topics["/tf"].qos
    assert topics["/tf"].qos["depth"] == 100


# -- the command line --------------------------------------------------------------------------


def run_monitor(*args: str, timeout: float = 120.0) -> subprocess.CompletedProcess:
    env = dict(os.environ, QT_QPA_PLATFORM="offscreen")
    return subprocess.run(
        [sys.executable, "-m", "mm_pc.monitor.app", *args],
        capture_output=True, text=True, timeout=timeout, env=env,
    )  # fmt: skip


@pytest.mark.ros
def test_mm_monitor_record_takes_the_sim_into_a_rosbag2_folder(tmp_path):
    folder = tmp_path / "sim-bag"
    out = run_monitor("--sim", "--headless", "--duration", "6", "--record", str(folder))
    assert out.returncode == 0, out.stdout + out.stderr
    assert f"recording to {folder}" in out.stdout and "mm-monitor: recorded " in out.stdout
    assert (folder / "metadata.yaml").is_file()
    msgs = decode_everything(folder)
    replies = msgs[SENSOR_TOPIC]
    assert len(replies) >= 2 * 20  # 15 Hz for ~3 s after the node came up
    assert len(msgs["/mm_beagle/sensor_data"]) > 20  # the live topic, best effort
    assert msgs["/diagnostics"]
    for dev in DEVS:
        mine = [m for m in replies if m.id == dev]
        polls = msgs[f"{REPLY_POLLS_TOPIC}/{dev.strip('/').replace('.', '_')}"]
        assert len(polls) == len(mine)  # a message per reply and sensor, none failed
        first, last = mine[0], mine[-1]
        # the polls of the replies after the first cover exactly what the totals added
        assert sum(p.next_seq - p.first_seq for p in polls) == last.seq - first.seq > 1000
        assert sum(len(p.dx) for p in polls) == last.seq - first.seq
        dx = sum(int(v) for p in polls for v in p.dx)
        dy = sum(int(v) for p in polls for v in p.dy)
        assert dx == last.x_total_counts - first.x_total_counts
        assert dy == last.y_total_counts - first.y_total_counts
        assert abs(dx) + abs(dy) > 100  # the robot drove
        assert all(p.id == dev for p in polls)
    with AnyReader([folder]) as reader:
        assert reader.message_count == sum(len(v) for v in msgs.values())


def _touch(path: Path) -> None:
    path.write_bytes(b"x")


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (lambda p: [p / "no" / "x.mcap"], "does not exist"),
        (lambda p: (p / "full").mkdir() or (p / "full" / "a").write_text("")
         or [p / "full"], "is not empty"),
        (lambda p: _touch(p / "in.mcap") or [p / "in.mcap", "--replay", p / "in.mcap"],
         "--replay input"),
        (lambda p: (p / "c.yaml").write_text("") or [p / "c.yaml"], "needs the .mcap suffix"),
    ],
)  # fmt: skip
def test_mm_monitor_record_refuses_a_bad_path_with_exit_2(tmp_path, make, message):
    args = [str(a) for a in make(tmp_path)]
    before = sorted(tmp_path.rglob("*"))
    out = run_monitor("--headless", "--duration", "1", "--record", *args, timeout=60)
    assert out.returncode == 2, out.stdout + out.stderr
    assert "--record" in out.stderr and message in out.stderr
    assert "Traceback" not in out.stderr
    assert sorted(tmp_path.rglob("*")) == before


# -- live topics through the bridge, against the real node ---------------------------------------


#: the module-wide mm-beagle (tests/monitor/conftest.py), with its own odometry on ~/odom
BEAGLE_PARAMS = {"backend": "sim", "sim_trajectory": "figure_eight", "odometry_rate": 50.0}


@pytest.mark.ros
def test_the_bridge_records_the_live_topics_with_the_publishers_qos(qtbot, tmp_path, beagle_node):
    """SensorData (best effort), mm-beagle's Odometry, /tf, a /tf_static latched before the
    recording started (transient local) and /diagnostics land in a rosbag2 folder that
    both readers decode, with the publishers' offered QoS in metadata.yaml."""
    import rclpy
    from rclpy.context import Context

    from mm_pc.monitor.context import MonitorConfig, MonitorContext
    from mm_pc.monitor.main_window import MainWindow
    from mm_pc.monitor.recording import start_recording, stop_recording
    from mm_pc.monitor.ros_bridge import RosBridge
    from mm_pc.ros.tf import TfPublisher, planar_transform

    ctx = Context()
    rclpy.init(context=ctx)
    node = rclpy.create_node("mm_test_tf", context=ctx)
    tf = TfPublisher(node)
    now = node.get_clock().now
    tf.send_static([planar_transform(now().to_msg(), "base_link", "mouse0", 0.1, 0.0, 0.0)])
    bridge = RosBridge("/mm_beagle", 20.0, node_name="mm_monitor_bag_test")
    config = MonitorConfig(rate_hz=20.0, calibration_file=tmp_path / "cal.yaml")
    window = MainWindow(MonitorContext(MonitorSession(), bridge, config))
    qtbot.addWidget(window)
    folder = tmp_path / "live"
    want = {"/mm_beagle/sensor_data": 20, "/mm_beagle/odom": 5, "/tf": 5, "/tf_static": 1,
            "/diagnostics": 1, SENSOR_TOPIC: 10}  # fmt: skip

    def enough() -> bool:
        tf.send(planar_transform(now().to_msg(), "odom", "base_link", 0.5, 0.25, 0.1))
        counts = recorder.topic_counts()
        return all(counts.get(t, 0) >= n for t, n in want.items())

    try:
        bridge.start()
        assert start_recording(window, folder)
        recorder = window.ctx.recorder
        qtbot.waitUntil(enough, timeout=30_000)
        stop_recording(window)
    finally:
        bridge.stop()
        node.destroy_node()
        ctx.try_shutdown()
    assert bridge.recording_skipped == {}
    msgs = decode_everything(folder)
    assert msgs["/mm_beagle/odom"][-1].child_frame_id == "base_link"
    assert msgs["/tf_static"][0].transforms[0].child_frame_id == "mouse0"
    assert msgs["/tf"][-1].transforms[0].transform.translation.x == 0.5
    assert {m.id for m in msgs["/mm_beagle/sensor_data"]} == set(DEVS)
    info = yaml.safe_load((folder / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    qos = {
        t["topic_metadata"]["name"]: t["topic_metadata"]["offered_qos_profiles"][0]
        for t in info["topics_with_message_count"]
    }
    assert qos["/mm_beagle/sensor_data"]["reliability"] == "best_effort"
    assert qos["/tf_static"]["durability"] == "transient_local"
    assert qos["/tf"]["reliability"] == "reliable"
    assert qos["/mm_beagle/odom"]["reliability"] == "reliable"
    counts = {
        t["topic_metadata"]["name"]: t["message_count"] for t in info["topics_with_message_count"]
    }
    assert counts == {k: len(v) for k, v in msgs.items()}


def test_mm_monitor_records_a_replay_into_a_file(tmp_path):
    """--replay with --record (no node): the replayed replies and polls are recorded again."""
    source = tmp_path / "in.mcap"
    rec = McapRecorder(source)
    replies = poll_replies()
    for r in replies:
        rec.write_reply(r)
    rec.close()
    out_path = tmp_path / "again.mcap"
    out = run_monitor(
        "--headless", "--duration", "3", "--replay", str(source), "--record", str(out_path)
    )
    assert out.returncode == 0, out.stdout + out.stderr
    assert f"recorded {len(replies)} replies and 0 live messages" in out.stdout
    back = read_replies(out_path)
    assert [r.readings for r in back] == [r.readings for r in replies]
    assert [sorted(k for k, v in r.polls.items() if v is not None) for r in back] == [
        sorted(k for k, v in r.polls.items() if v is not None) for r in replies
    ]
    decode_everything(out_path)


def test_a_live_topic_of_an_unknown_type_is_skipped_not_raised(tmp_path):
    rec = McapRecorder(tmp_path / "x.mcap")
    rec.write_live("/odd", "no_such_pkg/msg/Thing", b"\x00\x01\x00\x00")
    rec.write_live("/odd", "no_such_pkg/msg/Thing", b"\x00\x01\x00\x00")
    assert "no_such_pkg" in rec.skipped["/odd"] and rec.live_messages == 0
    rec.close()
    rec.write_live("/tf", "tf2_msgs/msg/TFMessage", b"")  # after close: dropped silently
    assert decode_everything(tmp_path / "x.mcap") == {}
