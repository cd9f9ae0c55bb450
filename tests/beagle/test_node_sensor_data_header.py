"""SensorData's header (issue 25): the counting-axes frame and the node-clock stamp.

Real processes. The module's node (sim, and remote over an agent) runs with
``frame_prefix`` r1/ and its own odometry publishing TF: every SensorData, on the
topic and in a ``get_sensor_data`` reply, names ``r1/mouse_*_counts``, and that frame
is on /tf_static, a child of ``r1/mouse_*`` turned by -90 deg. A node without a prefix
under ``use_sim_time`` stamps the header on /clock and keeps the poll's wall-clock time
in ``stamp``.
"""

from __future__ import annotations

import math
import os
import subprocess
import threading
import time

import pytest
from fakes import scaled, wait_until

rclpy = pytest.importorskip("rclpy")
from rclpy.qos import qos_profile_sensor_data  # noqa: E402

from mm_beagle.tools.harness import BeagleClient, beagle_process, node_command  # noqa: E402
from mm_interfaces.msg import SensorData  # noqa: E402
from mm_pc.core.angles import quaternion_yaw  # noqa: E402

pytestmark = pytest.mark.ros

S0, S1 = "/dev/spidev1.0", "/dev/spidev1.1"
_ROBOT = {"frame_prefix": "r1/", "odometry_rate": 10.0, "publish_tf": True,
          "sim_trajectory": "straight"}  # fmt: skip
BEAGLE_NODE = {"namespace": "/hdr", "sim": _ROBOT, "remote": _ROBOT}
COUNTS = {S0: "r1/mouse_spidev1_0_counts", S1: "r1/mouse_spidev1_1_counts"}


def _ns(t) -> int:
    return int(t.sec) * 1_000_000_000 + int(t.nanosec)


def _topic(client, topic: str, n: int = 2) -> list:
    """The first messages of both sensors on ``topic`` (sensor-data QoS)."""
    got: list = []
    sub = client.node.create_subscription(SensorData, topic, got.append, qos_profile_sensor_data)
    try:
        wait_until(lambda: len({m.id for m in got}) == n, 20, f"SensorData of both on {topic}",
                   interval=0.05)  # fmt: skip
    finally:
        client.node.destroy_subscription(sub)
    return list(got)


def test_topic_and_reply_name_the_prefixed_counting_frame(node, client):
    wait_until(lambda: client.call("get_sensor_data", id="").success, 30, "a reply")
    before = time.time_ns()
    res = client.call("get_sensor_data", id="")
    assert res.success, res.message
    published = _topic(client, "/hdr/mm_beagle/sensor_data")
    for m in list(res.data) + published:
        assert m.header.frame_id == COUNTS[m.id]
        # no use_sim_time: the node clock is the wall clock, the header the poll's stamp
        assert _ns(m.header.stamp) == _ns(m.stamp) > 0
    assert all(_ns(m.stamp) <= time.time_ns() for m in res.data)
    assert all(_ns(m.stamp) > before - 5_000_000_000 for m in res.data)  # a fresh poll


def test_the_counting_frame_is_on_tf_static_turned_by_minus_90_degrees(node, client):
    from tf2_msgs.msg import TFMessage

    from mm_pc.ros.tf import STATIC_LISTENER_QOS

    statics: list = []
    sub = client.node.create_subscription(
        TFMessage, "/tf_static", lambda m: statics.extend(m.transforms), STATIC_LISTENER_QOS
    )
    try:  # latched: this late subscriber still gets them
        wait_until(lambda: set(COUNTS.values()) <= {t.child_frame_id for t in statics}, 20,
                   "the _counts frames on /tf_static")  # fmt: skip
    finally:
        client.node.destroy_subscription(sub)
    parent = {t.child_frame_id: t for t in statics}
    for frame in COUNTS.values():
        t = parent[frame]
        mouse = frame.removesuffix("_counts")
        assert t.header.frame_id == mouse
        assert (t.transform.translation.x, t.transform.translation.y) == (0.0, 0.0)
        q = t.transform.rotation
        assert quaternion_yaw(q.x, q.y, q.z, q.w) == pytest.approx(-math.pi / 2)
        assert parent[mouse].header.frame_id == "r1/base_link"  # the mount
    # the frame each SensorData names is in that tree: counts -> mouse -> base_link
    for m in _topic(client, "/hdr/mm_beagle/sensor_data"):
        mouse = parent[m.header.frame_id].header.frame_id
        assert (mouse, parent[mouse].header.frame_id) == (
            f"r1/mouse_spidev1_{m.id[-1]}", "r1/base_link"
        )


def test_without_a_prefix_under_use_sim_time_the_header_follows_clock(tmp_path):
    """Default frames (mouse_*_counts, given sensor_frames: left_counts...); /clock at
    1000 s: header.stamp on it (the poll's age behind), ``stamp`` the poll's wall clock."""
    from rosgraph_msgs.msg import Clock

    client = BeagleClient("hdr_simtime_client", namespace="/simhdr/mm_beagle")
    pub = client.node.create_publisher(Clock, "/clock", 10)
    stop = threading.Event()
    t0 = time.monotonic()

    def tick() -> None:  # sim time 1000 s + wall seconds since the test started
        while not stop.is_set():
            t = 1000.0 + time.monotonic() - t0
            msg = Clock()
            msg.clock.sec, msg.clock.nanosec = int(t), int((t % 1) * 1e9)
            pub.publish(msg)
            time.sleep(0.01)

    ticker = threading.Thread(target=tick, daemon=True)
    ticker.start()
    params = {"backend": "sim", "use_sim_time": True, "sensor_frames": ["left", "right"]}
    log = tmp_path / "b.log"
    try:
        with beagle_process(params, dict(os.environ), str(log), "/simhdr"):
            assert client.wait(scaled(60)), log.read_text()
            wait_until(lambda: client.call("get_sensor_data", id="").success, 30, "a reply")
            res = client.call("get_sensor_data", id="")
            published = _topic(client, "/simhdr/mm_beagle/sensor_data")
            elapsed = time.monotonic() - t0
    finally:
        stop.set()
        ticker.join(timeout=5)
        client.close()
    frames = {S0: "left_counts", S1: "right_counts"}
    wall_now = time.time_ns()
    for m in list(res.data) + published:
        assert m.header.frame_id == frames[m.id]
        header_s = _ns(m.header.stamp) / 1e9
        assert 1000.0 - 1.0 <= header_s <= 1000.0 + elapsed + 0.5, header_s
        assert wall_now - 120e9 < _ns(m.stamp) <= wall_now  # the poll's wall clock


def test_sensor_frames_that_do_not_fit_the_devices_are_refused_with_odometry_off():
    """The frames name SensorData's frames now, so they are checked with the odometry off."""
    cmd = node_command({"backend": "sim", "sensor_frames": ["only_one"]}, "/badframes")
    out = subprocess.run(cmd, env=dict(os.environ), capture_output=True, text=True,
                         timeout=scaled(60))  # fmt: skip
    assert out.returncode == 2, out.stderr
    assert "mm-beagle: 'sensor_frames' names 1 frames for 2 devices; give one each" in out.stderr
    assert "Traceback" not in out.stderr
