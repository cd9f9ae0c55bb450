"""TF as ROS tools see it: the TFMessage type built here is Jazzy's, and what the
nodes' TfPublisher sends arrives on /tf and (latched) /tf_static."""

from __future__ import annotations

import contextlib
import json
import math
import time
from pathlib import Path

import pytest
from fakes import wait_until

rclpy = pytest.importorskip("rclpy")
tf2_msgs = pytest.importorskip("tf2_msgs.msg")


def test_tfmessage_has_the_jazzy_type_hash():
    from rosbags.typesys import Stores, get_typestore

    jazzy = get_typestore(Stores.ROS2_JAZZY).hash_rihs01("tf2_msgs/msg/TFMessage")
    share = Path(tf2_msgs.__file__).resolve().parents[5] / "share" / "tf2_msgs" / "msg"
    if not (share / "TFMessage.json").exists():  # a system ROS install: its own package
        pytest.skip(f"tf2_msgs comes from {share.parent}, not this project's build")
    ours = json.loads((share / "TFMessage.json").read_text())["type_hashes"][0]
    assert ours == {"type_name": "tf2_msgs/msg/TFMessage", "hash_string": jazzy}


@pytest.mark.ros
def test_transforms_arrive_on_tf_and_the_mounts_stay_latched_on_tf_static():
    from rclpy.executors import SingleThreadedExecutor
    from tf2_msgs.msg import TFMessage

    from mm_pc.core.angles import quaternion_yaw
    from mm_pc.core.geometry import DEFAULT_MOUNTS
    from mm_pc.ros.tf import STATIC_LISTENER_QOS, TfPublisher, mount_transforms, planar_transform

    ctx = rclpy.Context()  # its own: other tests may hold the default context
    rclpy.init(context=ctx)
    try:
        node = rclpy.create_node("mm_tf_test", context=ctx)
        tf = TfPublisher(node)
        stamp = node.get_clock().now().to_msg()
        tf.send_static(mount_transforms(stamp, "base_link", ["s0", "s1"], DEFAULT_MOUNTS))
        got: dict[str, list] = {"/tf": [], "/tf_static": []}
        # subscribed after the static transforms were sent: transient-local still delivers
        node.create_subscription(
            TFMessage, "/tf_static", got["/tf_static"].append, STATIC_LISTENER_QOS
        )
        node.create_subscription(TFMessage, "/tf", got["/tf"].append, 10)
        ex = SingleThreadedExecutor(context=ctx)
        ex.add_node(node)

        def both_received() -> bool:
            tf.send(planar_transform(stamp, "odom", "base_link", 1.5, -2.0, math.pi / 2))
            ex.spin_once(timeout_sec=0.1)
            return bool(got["/tf"] and got["/tf_static"])

        wait_until(both_received, 20, "/tf and /tf_static for a late subscriber", interval=0)
        t = got["/tf"][0].transforms[0]
        assert (t.header.frame_id, t.child_frame_id) == ("odom", "base_link")
        assert (t.transform.translation.x, t.transform.translation.y) == (1.5, -2.0)
        assert t.transform.rotation.z == pytest.approx(math.sqrt(0.5))
        statics = got["/tf_static"][0].transforms
        assert [m.child_frame_id for m in statics] == ["s0", "s1", "s0_counts", "s1_counts"]
        mounts, counts = statics[:2], statics[2:]
        for m, mount in zip(mounts, DEFAULT_MOUNTS, strict=True):
            assert m.header.frame_id == "base_link"
            assert m.transform.translation.x == pytest.approx(mount.x)
            assert m.transform.translation.y == pytest.approx(mount.y)
        for c, parent in zip(counts, ["s0", "s1"], strict=True):  # SensorData's axes
            assert c.header.frame_id == parent
            assert (c.transform.translation.x, c.transform.translation.y) == (0.0, 0.0)
            q = c.transform.rotation
            assert quaternion_yaw(q.x, q.y, q.z, q.w) == pytest.approx(-math.pi / 2)
        with pytest.raises(ValueError, match="give one each"):
            mount_transforms(stamp, "base_link", ["only_one"], DEFAULT_MOUNTS)
        ex.shutdown()
        node.destroy_node()
    finally:
        rclpy.shutdown(context=ctx)


def test_frame_ids_are_checked_and_sensor_frames_derived_from_the_devices():
    from mm_pc.ros.tf import frame_id_problem, sensor_frame_names

    assert frame_id_problem("odom_frame", "odom") == ""
    assert frame_id_problem("odom_frame", "robot1/odom") == ""
    assert "must not be empty" in frame_id_problem("odom_frame", "")
    assert "leading '/'" in frame_id_problem("odom_frame", "/odom")
    assert "a TF frame id" in frame_id_problem("base_frame", "base link")
    assert "a TF frame id" in frame_id_problem("base_frame", "1st")
    devices = ["/dev/spidev1.0", "/dev/spidev1.1"]
    assert sensor_frame_names(devices) == ["mouse_spidev1_0", "mouse_spidev1_1"]
    assert sensor_frame_names(devices, [""]) == ["mouse_spidev1_0", "mouse_spidev1_1"]
    assert sensor_frame_names(devices, ["left", "right"]) == ["left", "right"]
    for bad, why in ((["left"], "names 1 frames for 2"), (["a", "a"], "distinct"),
                     (["a", "/b"], "leading '/'")):  # fmt: skip
        with pytest.raises(ValueError, match=why):
            sensor_frame_names(devices, bad)


def test_a_counts_vector_through_the_counts_frame_is_the_robots_motion_in_base_link():
    """SensorData's numbers (counting axes, X right, Y forward) taken through
    base_link <- mouse_X <- mouse_X_counts give the robot's motion, for a mount turned by
    a mounting error: what mm_pc.core.frames and geometry compute without TF."""
    from builtin_interfaces.msg import Time

    from mm_pc.core.angles import quaternion_yaw
    from mm_pc.core.frames import base_to_sensor
    from mm_pc.core.geometry import SensorMount
    from mm_pc.ros.tf import COUNTS_YAW, counts_frame, mount_transforms

    def turn(yaw: float, x: float, y: float) -> tuple[float, float]:
        c, s = math.cos(yaw), math.sin(yaw)
        return c * x - s * y, s * x + c * y

    mount = SensorMount(0.049, -0.0395, 0.07)  # 4 deg mounting error
    mouse, counts = mount_transforms(Time(), "r1/base_link", ["r1/mouse_a"], [mount])
    assert (counts.header.frame_id, counts.child_frame_id) == ("r1/mouse_a", "r1/mouse_a_counts")
    assert counts_frame("r1/mouse_a") == "r1/mouse_a_counts"
    yaws = [quaternion_yaw(t.transform.rotation.x, t.transform.rotation.y,
                           t.transform.rotation.z, t.transform.rotation.w)
            for t in (mouse, counts)]  # fmt: skip
    assert yaws == pytest.approx([mount.yaw, COUNTS_YAW])
    assert math.isclose(COUNTS_YAW, -math.pi / 2)
    for d in [(0.01, 0.0), (0.0, 0.01), (-0.003, 0.004)]:  # base_link motion, m
        reported = turn(-mount.yaw, *map(float, base_to_sensor(*d)))  # what the chip counts
        back = turn(yaws[0], *turn(yaws[1], *reported))  # tf2: counts -> mouse -> base_link
        assert back == pytest.approx(d, abs=1e-15)


def _recorder_static_qos():
    from mm_pc.monitor.io.bag_format import live_topics
    from mm_pc.monitor.ros_bridge import _qos_from_dict

    (topic,) = [t for t in live_topics() if t.name == "/tf_static"]
    return _qos_from_dict(topic.subscription_qos)


@pytest.mark.ros
@pytest.mark.parametrize("listener", ["STATIC_LISTENER_QOS", "the monitor's recorder"])
def test_a_late_static_listener_keeps_every_publishers_mounts(listener):
    """Three nodes latch their mounts on /tf_static (two robots, or mm-odometry beside
    mm-beagle's own odometry); a subscriber that joins later and has not spun yet still
    gets all three. At depth 1 it kept only the last (a CI run lost r1's mounts)."""
    from rclpy.executors import SingleThreadedExecutor
    from tf2_msgs.msg import TFMessage

    from mm_pc.core.geometry import DEFAULT_MOUNTS
    from mm_pc.ros.tf import STATIC_LISTENER_QOS, TfPublisher, mount_transforms

    qos = STATIC_LISTENER_QOS if listener == "STATIC_LISTENER_QOS" else _recorder_static_qos()
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    try:
        robots = ("r0", "r1", "r2")
        publishers = []  # held: a collected node takes its latched message with it
        for r in robots:
            node = rclpy.create_node(f"mm_tf_static_{r}", context=ctx)
            publishers.append(TfPublisher(node))
            publishers[-1].send_static(mount_transforms(
                node.get_clock().now().to_msg(), f"{r}/base_link", [f"{r}/s0"], DEFAULT_MOUNTS[:1]
            ))  # fmt: skip
        listener_node = rclpy.create_node("mm_tf_static_listener", context=ctx)
        seen: set[str] = set()
        listener_node.create_subscription(
            TFMessage, "/tf_static", lambda m: seen.update(t.child_frame_id for t in m.transforms),
            qos,
        )  # fmt: skip
        time.sleep(1.0)  # every latched message is in the reader's queue before it is taken
        ex = SingleThreadedExecutor(context=ctx)
        ex.add_node(listener_node)
        want = {f"{r}/{f}" for r in robots for f in ("s0", "s0_counts")}

        def all_seen() -> bool:
            ex.spin_once(timeout_sec=0.1)
            return want <= seen

        with contextlib.suppress(AssertionError):  # the assert below says what was missing
            wait_until(all_seen, 10, "every robot's mounts on /tf_static", interval=0)
        assert seen == want
        ex.shutdown()
    finally:
        rclpy.shutdown(context=ctx)
