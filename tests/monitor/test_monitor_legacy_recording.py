"""Recordings made before SensorData's header (issue 25) still replay, and ROS tools still
read them; a new recording carries the header.

``tests/data/legacy_sensor_data.mcap`` is a real recording made by the code before the
change (``tests/data/make_legacy_sensor_data.py``: a sim node, replies with their polls,
the live ``~/sensor_data`` topic); ``legacy_sensor_data.json`` holds what that code read
back from it: every reading, the pose and the session's statistics.
"""

from __future__ import annotations

import json
import shutil
from dataclasses import asdict
from pathlib import Path

import pytest

pytest.importorskip("rclpy")
pytest.importorskip("rosbags")
pytest.importorskip("mcap_ros2")

from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore

from mm_pc.core.sensor_data import Reading, Reply
from mm_pc.monitor.io.mcap_reader import read_replies, read_replies_up_to_cut
from mm_pc.monitor.io.mcap_writer import McapRecorder
from mm_pc.monitor.io.schemas import (
    LEGACY_SENSOR_HASH,
    SENSOR_TOPIC,
    SENSOR_TYPE,
    is_legacy_sensor_schema,
    ros2msg_definition,
)
from mm_pc.monitor.model.session import MonitorSession

ROOT = Path(__file__).resolve().parents[2]
OLD = ROOT / "tests" / "data" / "legacy_sensor_data.mcap"
EXPECTED = json.loads((ROOT / "tests" / "data" / "legacy_sensor_data.json").read_text())
HEADER_FIELDS = ("frame_id", "header_stamp_ns")
LIVE_TOPIC = "/mm_beagle/sensor_data"


def sensor_channels(path: Path) -> dict[str, tuple]:
    """topic -> (schema, channel) of every SensorData channel of an MCAP file."""
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    return {
        c.topic: (summary.schemas[c.schema_id], c)
        for c in summary.channels.values()
        if summary.schemas[c.schema_id].name == SENSOR_TYPE
    }


def test_the_old_recording_replays_to_the_same_readings_pose_and_statistics():
    replies = read_replies(OLD)
    assert len(replies) == len(EXPECTED["replies"]) == 29
    for got, want in zip(replies, EXPECTED["replies"], strict=True):
        assert (got.received_s, got.rtt_s) == (want["received_s"], want["rtt_s"])
        polls = None if got.polls is None else sorted(k for k, v in got.polls.items() if v)
        assert polls == want["polls"]
        for r, w in zip(got.readings, want["readings"], strict=True):
            as_read = asdict(r)
            header = {k: as_read.pop(k) for k in HEADER_FIELDS}
            assert header == {"frame_id": "", "header_stamp_ns": 0}  # an old node: none
            assert as_read == w  # every other field exactly as before the change
    session = MonitorSession()
    for r in replies:
        session.process(r)
    assert [session.pose.x, session.pose.y, session.pose.yaw] == EXPECTED["pose"]
    assert {k: getattr(session.stats, k) for k in EXPECTED["stats"]} == EXPECTED["stats"]
    assert session.stats.polls == 1482 and session.stats.used == 28  # integrated per poll


def test_the_old_file_is_told_apart_by_its_schema_text_and_its_type_hash():
    channels = sensor_channels(OLD)
    assert set(channels) == {SENSOR_TOPIC, LIVE_TOPIC}  # the replies and the live topic
    frozen = (ROOT / "mm_interfaces" / "msg" / "LegacySensorData.msg").read_text()
    for schema, channel in channels.values():
        text = schema.data.decode()
        assert text.startswith(frozen.rstrip("\n") + "\n")  # LegacySensorData is that text
        assert channel.metadata["topic_type_hash"] == LEGACY_SENSOR_HASH
        assert is_legacy_sensor_schema(schema.data, channel.metadata["topic_type_hash"])
        assert is_legacy_sensor_schema(b"", LEGACY_SENSOR_HASH)  # a schema without text
    new = ros2msg_definition(SENSOR_TYPE)
    assert not is_legacy_sensor_schema(new) and "\nMSG: std_msgs/Header\n" in new
    assert not is_legacy_sensor_schema(b"", "RIHS01_" + "0" * 64)


def test_ros_tools_decode_the_old_file_from_its_embedded_schema():
    """rosbags' AnyReader and mcap-ros2-support read SensorData as the file defines it."""
    expected = {(r["id"], r["seq"]) for rep in EXPECTED["replies"] for r in rep["readings"]}
    by_rosbags: dict[str, list] = {}
    with AnyReader([OLD], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
        for con, _t, raw in reader.messages():
            if con.msgtype == SENSOR_TYPE:
                by_rosbags.setdefault(con.topic, []).append(reader.deserialize(raw, con.msgtype))
    by_mcap_ros2: dict[str, list] = {}
    with open(OLD, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for schema, channel, _m, msg in reader.iter_decoded_messages():
            if schema.name == SENSOR_TYPE:
                by_mcap_ros2.setdefault(channel.topic, []).append(msg)
    for decoded in (by_rosbags, by_mcap_ros2):
        assert {k: len(v) for k, v in decoded.items()} == {SENSOR_TOPIC: 58, LIVE_TOPIC: 34}
        assert {(m.id, m.seq) for m in decoded[SENSOR_TOPIC]} == expected
        for m in decoded[SENSOR_TOPIC] + decoded[LIVE_TOPIC]:
            assert not hasattr(m, "header") and m.stamp.sec > 1_700_000_000
            assert m.chip == "pln2033" and m.cpi == 1600


def test_a_cut_old_recording_replays_up_to_its_cut(tmp_path):
    """Cut in the block of live messages after the replies' (the recorder wrote them last):
    every reply is whole and decodes as before."""
    cut = tmp_path / "cut.mcap"
    data = OLD.read_bytes()
    cut.write_bytes(data[: len(data) * 2 // 3])
    replies, warning = read_replies_up_to_cut(cut)
    assert "cut short" in warning and "the rest is lost" in warning and len(replies) == 29
    want = EXPECTED["replies"][: len(replies)]
    got = [[{k: v for k, v in asdict(r).items() if k not in HEADER_FIELDS} for r in rep.readings]
           for rep in replies]  # fmt: skip
    assert got == [w["readings"] for w in want]


def test_a_new_recording_carries_the_header_and_ros_tools_decode_it(tmp_path):
    path = tmp_path / "new.mcap"
    readings = tuple(
        Reading(id=dev, stamp_ns=1_796_000_000_123_456_789, seq=5 + k, x_total=0.5, y_total=-1.0,
                cpi=1600, chip="pln2033", frame_id=f"r1/mouse_spidev1_{k}_counts",
                header_stamp_ns=1_000_250_000_000 + k)
        for k, dev in enumerate(("/dev/spidev1.0", "/dev/spidev1.1"))
    )  # fmt: skip
    rec = McapRecorder(path)
    rec.write_reply(Reply(readings, received_s=12.5, rtt_s=0.001))
    rec.close()
    assert [r.readings for r in read_replies(path)] == [readings]  # the header comes back
    ((schema, channel),) = sensor_channels(path).values()
    assert not is_legacy_sensor_schema(schema.data, channel.metadata["topic_type_hash"])
    with AnyReader([path], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
        got = [reader.deserialize(raw, con.msgtype) for con, _t, raw in reader.messages()
               if con.msgtype == SENSOR_TYPE]  # fmt: skip
    with open(path, "rb") as f:
        got_mcap = [m for s, _c, _m, m in make_reader(
            f, decoder_factories=[DecoderFactory()]).iter_decoded_messages()
            if s.name == SENSOR_TYPE]  # fmt: skip
    for msgs in (got, got_mcap):
        assert [m.header.frame_id for m in msgs] == [r.frame_id for r in readings]
        assert [(m.header.stamp.sec, m.header.stamp.nanosec) for m in msgs] == [
            (1000, 250_000_000), (1000, 250_000_001)
        ]  # fmt: skip
        assert [(m.stamp.sec, m.stamp.nanosec) for m in msgs] == [(1_796_000_000, 123_456_789)] * 2


def test_old_and_new_files_in_one_folder_each_decode_by_their_own_schema(tmp_path):
    """Channel ids repeat across a folder's files: each file's SensorData is decoded by its
    own schema, not by what another file's channel of the same id was."""
    from mm_pc.monitor.io.mcap_reader import _replies_of, open_messages

    folder = tmp_path / "mixed"
    folder.mkdir()
    shutil.copy(OLD, folder / "a_old.mcap")
    rec = McapRecorder(folder / "b_new.mcap")
    new = Reading(id="/dev/spidev1.0", stamp_ns=2_000_000_000_000_000_000, seq=1, x_total=0.0,
                  y_total=0.0, frame_id="mouse_a_counts", header_stamp_ns=7)  # fmt: skip
    rec.write_reply(Reply((new,), received_s=1.0))
    rec.close()
    messages, types = open_messages(folder)
    # a foreign bag's layout: no reply_meta, replies grouped by log time
    plain = [(s, c, m) for s, c, m in messages if c.topic == SENSOR_TOPIC]
    readings = [r for reply in _replies_of(folder, plain, types) for r in reply.readings]
    assert len(readings) == 58 + 1
    assert [r for r in readings if r.frame_id] == [new]
    old = [r for r in readings if not r.frame_id]
    assert {(r.id, r.seq) for r in old} == {
        (w["id"], w["seq"]) for rep in EXPECTED["replies"] for w in rep["readings"]
    }
