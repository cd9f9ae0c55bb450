"""mm-odometry as ROS tools see it, with real processes: TF on /tf and /tf_static, the
~/reset service, live parameters, a namespace-relative ``beagle`` and sim time."""

from __future__ import annotations

import math
import os
import subprocess
import threading
import time

import pytest
from fakes import wait_until

pytest.importorskip("rclpy")
from nav_msgs.msg import Odometry, Path

from mm_beagle.tools.harness import BeagleClient, beagle_process, stop_process
from mm_pc.core.angles import quaternion_yaw
from mm_pc.core.geometry import DEFAULT_MOUNTS

pytestmark = pytest.mark.ros

STRAIGHT = {"backend": "sim", "sim_trajectory": "straight", "sim_speed": 0.2}


def key(m) -> tuple[int, int]:
    return m.header.stamp.sec, m.header.stamp.nanosec


def planar_tf(t) -> tuple[float, float, float]:
    r = t.transform.rotation
    return t.transform.translation.x, t.transform.translation.y, quaternion_yaw(r.x, r.y, r.z, r.w)


def planar_odom(m) -> tuple[float, float, float]:
    p, o = m.pose.pose.position, m.pose.pose.orientation
    return p.x, p.y, quaternion_yaw(o.x, o.y, o.z, o.w)


def start_odometry(ros_command, params: dict, ns: str) -> subprocess.Popen:
    return subprocess.Popen(
        ros_command("mm_pc.ros.odometry_node", params, ns),
        env=dict(os.environ),
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )


def finish(proc: subprocess.Popen) -> str:
    stop_process(proc)
    out, _ = proc.communicate(timeout=5)
    assert proc.returncode == 0, out
    assert "Traceback" not in out, out
    return out


def test_tf_follows_odom_reset_starts_over_and_live_parameters_are_checked(
    tmp_path, ros_command
):
    from tf2_msgs.msg import TFMessage

    from mm_pc.ros.tf import DYNAMIC_QOS, STATIC_LISTENER_QOS

    ns = "/tfo"
    odo = start_odometry(ros_command, {"rate": 20.0, "path_rate": 5.0}, ns)
    client = BeagleClient("tfo_client", f"{ns}/mm_odometry")
    odoms: list = []
    tfs: list = []
    paths: list = []
    client.node.create_subscription(Odometry, f"{ns}/mm_odometry/odom", odoms.append, 50)
    client.node.create_subscription(Path, f"{ns}/mm_odometry/path", paths.append, 5)
    client.node.create_subscription(TFMessage, "/tf", tfs.append, DYNAMIC_QOS)
    try:
        with beagle_process(STRAIGHT, dict(os.environ), str(tmp_path / "b.log"), ns):
            moving = lambda: len(odoms) > 10 and odoms[-1].pose.pose.position.x > 0.1  # noqa: E731
            wait_until(moving, 40, "motion on ~/odom")
            # /tf: odom -> base_link with the pose and stamp of ~/odom
            sent = {key(t): t for m in list(tfs) for t in m.transforms}
            matched = [(o, sent[key(o)]) for o in list(odoms) if key(o) in sent]
            assert len(matched) >= 5, (len(odoms), len(tfs))
            for o, t in matched:
                assert (t.header.frame_id, t.child_frame_id) == ("odom", "base_link")
                assert planar_tf(t) == pytest.approx(planar_odom(o), abs=1e-12)
            # /tf_static: a subscriber that comes late still gets the mounts
            statics: list = []
            client.node.create_subscription(
                TFMessage, "/tf_static", statics.append, STATIC_LISTENER_QOS
            )
            wait_until(lambda: statics, 10, "/tf_static for a late subscriber")
            frames, counts = statics[0].transforms[:2], statics[0].transforms[2:]
            assert [f.child_frame_id for f in frames] == ["mouse_spidev1_0", "mouse_spidev1_1"]
            for f, mount in zip(frames, DEFAULT_MOUNTS, strict=True):
                assert f.header.frame_id == "base_link"
                assert planar_tf(f) == pytest.approx((mount.x, mount.y, mount.yaw), abs=1e-12)
            for c, f in zip(counts, frames, strict=True):  # SensorData's counting axes
                assert (c.header.frame_id, c.child_frame_id) == (
                    f.child_frame_id, f"{f.child_frame_id}_counts"
                )
                assert planar_tf(c) == pytest.approx((0.0, 0.0, -math.pi / 2), abs=1e-12)

            # ~/reset: back to the origin with a fresh covariance, path cleared, then on
            before = odoms[-1]
            res = client.trigger(f"{ns}/mm_odometry/reset")
            assert res.success and "pose back to (0, 0, 0)" in res.message
            n = len(odoms)  # messages sent before the reset may still arrive after its reply
            first = wait_until(
                lambda: next((o for o in odoms[n:] if abs(o.pose.pose.position.x) < 0.03), None),
                10, "a pose near the origin after the reset")  # fmt: skip
            assert before.pose.pose.position.x - 0.05 > 0.03
            assert first.pose.covariance[0] < before.pose.covariance[0] / 2
            m = len(paths)
            wait_until(lambda: len(paths) > m + 1, 10, "a path after the reset")
            # cleared: the path holds only poses from after the reset (n - 1 may be older)
            assert min(key(p) for p in paths[-1].poses) >= key(odoms[n - 1])
            assert paths[-1].poses[0].pose.position.x < 0.05
            wait_until(
                lambda: odoms[-1].pose.pose.position.x > first.pose.pose.position.x + 0.05,
                10,
                "the pose to move on after the reset",
            )

            # live parameters: checked, refused ones keep the old value
            refused = {
                "odom_frame": ("/odom", "leading '/'"),
                "base_frame": ("base link", "a TF frame id"),
                "method": ("best", "unknown method"),
                "rate": (0.0, ""),  # outside the declared range
                "devices": (["/dev/x"], "read-only"),
            }
            for name, (value, why) in refused.items():
                (r,) = client.set_parameters(**{name: value})
                assert not r.successful and why in r.reason, (name, r.reason)
            assert client.get_parameters("odom_frame", "base_frame", "method", "rate") == [
                "odom", "base_link", "exact", 20.0
            ]
            r1, r2, r3 = client.set_parameters(
                rate=5.0, odom_frame="odom_mouse", method="two-sensor"
            )
            assert r1.successful and r2.successful and r3.successful, (r1, r2, r3)
            assert client.get_parameters("rate", "odom_frame", "method") == [
                5.0, "odom_mouse", "two-sensor"
            ]
            n = len(odoms)
            wait_until(lambda: len(odoms) > n + 2, 10, "odometry after the live change")
            assert odoms[-1].header.frame_id == "odom_mouse"
            assert tfs[-1].transforms[0].header.frame_id == "odom_mouse"
    finally:
        client.close()
        log = finish(odo)
    assert "reset: pose back to (0, 0, 0)" in log
    assert "parameter rate set to 5.0" in log and "parameters not changed: unknown method" in log


def test_two_namespaces_ask_their_own_beagle_and_publish_tf_false_sends_no_tf(
    tmp_path, ros_command
):
    """``beagle`` defaults to the node's namespace: /robot1 drives, /robot2 stands still."""
    from diagnostic_msgs.msg import DiagnosticArray
    from tf2_msgs.msg import TFMessage

    from mm_pc.ros.tf import DYNAMIC_QOS, STATIC_LISTENER_QOS

    robots = {"/robot1": STRAIGHT, "/robot2": {"backend": "sim", "sim_trajectory": "still"}}
    procs = {ns: start_odometry(ros_command, {"rate": 20.0, "publish_tf": False}, ns)
             for ns in robots}  # fmt: skip
    client = BeagleClient("ns_odo_client")
    odoms: dict[str, list] = {ns: [] for ns in robots}
    tf_seen: list = []
    hardware: dict[str, str] = {}
    for ns in robots:
        client.node.create_subscription(Odometry, f"{ns}/mm_odometry/odom", odoms[ns].append, 50)
    client.node.create_subscription(TFMessage, "/tf", tf_seen.append, DYNAMIC_QOS)

    def on_diag(arr):
        for s in arr.status:
            if s.name.endswith("mm_odometry: pose"):
                hardware[s.name] = s.hardware_id

    client.node.create_subscription(DiagnosticArray, "/diagnostics", on_diag, 10)
    logs = {}
    try:
        with (
            beagle_process(robots["/robot1"], dict(os.environ), str(tmp_path / "1.log"), "/robot1"),
            beagle_process(robots["/robot2"], dict(os.environ), str(tmp_path / "2.log"), "/robot2"),
        ):
            wait_until(
                lambda: len(odoms["/robot2"]) > 10
                and odoms["/robot1"]
                and odoms["/robot1"][-1].pose.pose.position.x > 0.05,
                60,  # four processes starting at once: slow on a busy machine
                "odometry from both namespaces (robot1 moving)",
            )
            assert all(o.pose.pose.position.x == 0.0 for o in odoms["/robot2"])
            static: list = []
            client.node.create_subscription(
                TFMessage, "/tf_static", static.append, STATIC_LISTENER_QOS
            )
            wait_until(lambda: len(hardware) == 2, 10, f"diagnostics: {hardware}")
            time.sleep(0.5)
            assert not tf_seen and not static  # publish_tf false: nothing on either
            # status names carry the node's full name, hardware ids its own mm_beagle
            assert hardware == {
                "/robot1/mm_odometry: pose": "/robot1/mm_beagle",
                "/robot2/mm_odometry: pose": "/robot2/mm_beagle",
            }
    finally:
        client.close()
        for ns, proc in procs.items():
            logs[ns] = finish(proc)
    for ns in robots:
        assert f"from {ns}/mm_beagle at 20 Hz" in logs[ns], logs[ns]
        assert "TF odom" not in logs[ns]


def test_stamps_follow_the_clock_topic_under_use_sim_time(tmp_path, ros_command):
    """No /clock: a log line says it waits. /clock at 1000 s: ~/odom and /tf stamped on it."""
    from rosgraph_msgs.msg import Clock
    from tf2_msgs.msg import TFMessage

    from mm_pc.ros.tf import DYNAMIC_QOS

    ns = "/simt"
    odo = start_odometry(ros_command, {"rate": 20.0, "use_sim_time": True}, ns)
    client = BeagleClient("simt_client")
    odoms: list = []
    tfs: list = []
    client.node.create_subscription(Odometry, f"{ns}/mm_odometry/odom", odoms.append, 50)
    client.node.create_subscription(TFMessage, "/tf", tfs.append, DYNAMIC_QOS)
    clock_pub = client.node.create_publisher(Clock, "/clock", 10)
    stop = threading.Event()
    t0 = [0.0]

    def tick() -> None:  # sim time 1000 s + wall seconds since the clock started
        t0[0] = time.monotonic()
        while not stop.is_set():
            t = 1000.0 + time.monotonic() - t0[0]
            msg = Clock()
            msg.clock.sec, msg.clock.nanosec = int(t), int((t % 1) * 1e9)
            clock_pub.publish(msg)
            time.sleep(0.01)

    ticker = threading.Thread(target=tick, daemon=True)
    try:
        with beagle_process(STRAIGHT, dict(os.environ), str(tmp_path / "b.log"), ns):
            time.sleep(4.0)  # the node is up, its services too, but there is no /clock
            assert not odoms, "published without /clock"
            ticker.start()
            wait_until(lambda: len(odoms) > 10, 30, "odometry once /clock ticks")
            elapsed = time.monotonic() - t0[0]
            stamps = [m.header.stamp.sec + m.header.stamp.nanosec * 1e-9 for m in list(odoms)]
            assert all(1000.0 <= s <= 1000.0 + elapsed + 0.5 for s in stamps), stamps[:3]
            assert stamps == sorted(stamps)
            sent = {key(t) for m in list(tfs) for t in m.transforms}
            assert sum(key(o) in sent for o in list(odoms)) >= 5  # the same sim stamps on /tf
    finally:
        stop.set()
        client.close()
        log = finish(odo)
    assert "waiting for /clock" in log and "/clock started at 10" in log, log
