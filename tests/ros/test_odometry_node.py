"""mm-odometry against a real mm-beagle process: nav_msgs/Odometry and Path out."""

from __future__ import annotations

import math
import os
import signal
import subprocess
import threading
import time

import pytest
from fakes import wait_until

pytest.importorskip("rclpy")
from nav_msgs.msg import Odometry, Path

from mm_beagle.tools.harness import BeagleClient, beagle_process
from mm_pc.core.uncertainty import PoseUncertainty, twist_covariance

pytestmark = pytest.mark.ros


@pytest.mark.parametrize("method", ["exact", "two-sensor"])
def test_straight_run_ends_where_the_robot_stopped(method, tmp_path, ros_command):
    """Robot stands 4 s, drives 2 s straight at 0.2 m/s, stands: odom ends at x = 0.4 m."""
    ns = f"/odo_{method.replace('-', '_')}"
    beagle = {
        "backend": "sim",
        "sim_trajectory": "straight",
        "sim_start_delay": 4.0,
        "sim_duration": 2.0,
    }
    # mm-odometry first: it waits for the service, so its baseline is the node's first
    # reply, long before the robot starts (a late start under load missed part of the run)
    params = {"beagle": "/mm_beagle", "rate": 50.0, "method": method, "path_rate": 5.0}
    odo = subprocess.Popen(
        ros_command("mm_pc.ros.odometry_node", params, ns),
        env=dict(os.environ),
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    try:
        with beagle_process(beagle, env=dict(os.environ), log_path=str(tmp_path / "beagle.log")):
            client = BeagleClient("odo_test_client")
            assert client.wait(30)
            got: list[Odometry] = []
            paths: list[Path] = []
            lock = threading.Lock()

            def on_odom(m):
                with lock:
                    got.append(m)

            client.node.create_subscription(Odometry, f"{ns}/mm_odometry/odom", on_odom, 10)
            client.node.create_subscription(Path, f"{ns}/mm_odometry/path", paths.append, 10)
            try:
                def stopped_at_the_end():
                    with lock:
                        last = got[-1] if got else None
                    at_end = last is not None and last.pose.pose.position.x > 0.39
                    return last if at_end and last.twist.twist.linear.x == 0 else None

                final = wait_until(stopped_at_the_end, 40, "the final pose (x > 0.39, standing)")
                pos = final.pose.pose.position
                assert pos.x == pytest.approx(0.4, abs=0.002)
                assert pos.y == pytest.approx(0.0, abs=0.002)
                yaw = 2 * math.atan2(final.pose.pose.orientation.z, final.pose.pose.orientation.w)
                assert yaw == pytest.approx(0.0, abs=0.005)
                assert final.header.frame_id == "odom" and final.child_frame_id == "base_link"
                # covariance grew with the 0.4 m travelled
                assert final.pose.covariance[0] == pytest.approx(0.015**2 * 0.4, rel=0.05)
                assert paths and len(paths[-1].poses) > 10
            finally:
                client.close()
    finally:
        odo.send_signal(signal.SIGINT)
        out, _ = odo.communicate(timeout=15)
    assert odo.returncode == 0, out


@pytest.mark.parametrize(
    ("params", "expect"),
    [
        ({"method": "guess"}, "unknown odometry method 'guess'"),
        ({"base_frame": "base link"}, "'base_frame' is 'base link': a TF frame id"),
        ({"sensor_frames": ["a", "a"]}, "'sensor_frames' must be distinct"),
        ({"sensor_frames": ["/left", "right"]}, "no leading '/'"),
    ],
)
def test_bad_parameters_exit_2_with_a_message(params, expect, ros_command):
    out = subprocess.run(
        ros_command("mm_pc.ros.odometry_node", params, "/odo_bad"),
        capture_output=True,
        text=True,
        timeout=60,
        env=dict(os.environ),
    )
    assert out.returncode == 2
    assert expect in out.stderr
    assert "Traceback" not in out.stderr


def test_uncertainty_grows_with_distance_and_turn():
    u = PoseUncertainty()
    floor_yaw = u.pose_covariance()[35]  # quantisation at 1600 CPI: never 0
    assert floor_yaw > 0 and u.pose_covariance()[0] > 0
    u.add(1.0, 0.0)
    assert u.pose_covariance()[0] == pytest.approx(0.015**2)
    assert u.pose_covariance()[35] == pytest.approx(0.01**2 + floor_yaw)
    u.add(-1.0, -math.pi)
    # the yaw random walk adds; position also takes the heading error over the step
    assert u.pose_covariance()[35] == pytest.approx(2 * 0.01**2 + math.pi * 0.01**2 + floor_yaw)
    assert u.pose_covariance()[0] > 2 * 0.015**2
    assert (u.var_along, u.var_yaw) == pytest.approx((2 * 0.015**2, (2 + math.pi) * 0.01**2))
    with pytest.raises(ValueError, match="q_pos"):
        PoseUncertainty(q_pos=-1.0)
    with pytest.raises(ValueError, match="cpi and dt"):
        twist_covariance(0, 0.1)


@pytest.mark.parametrize("method", ["exact", "two-sensor"])
def test_beagle_onboard_odometry_integrates_every_poll(method, tmp_path):
    """mm-beagle's own ~/odom (odometry_rate > 0): the same run, integrated at 1 kHz."""
    beagle = {
        "backend": "sim",
        "sim_trajectory": "straight",
        "sim_start_delay": 3.0,
        "sim_duration": 2.0,
        "odometry_rate": 20.0,
        "odometry_method": method,
    }
    with beagle_process(beagle, env=dict(os.environ), log_path=str(tmp_path / "beagle.log")):
        client = BeagleClient(f"onboard_{method.replace('-', '_')}")
        assert client.wait(30)
        got: list[Odometry] = []
        client.node.create_subscription(Odometry, "/mm_beagle/odom", got.append, 10)
        try:
            def stopped_at_the_end():
                last = got[-1] if got else None
                stopped = last is not None and last.twist.twist.linear.x == 0
                return last if stopped and last.pose.pose.position.x > 0.39 else None

            final = wait_until(stopped_at_the_end, 40, "the final pose on /mm_beagle/odom")
            assert final.pose.pose.position.x == pytest.approx(0.4, abs=0.002)
            assert final.pose.pose.position.y == pytest.approx(0.0, abs=0.002)
        finally:
            client.close()


def test_beagle_rejects_bad_odometry_settings():
    from mm_beagle.tools.harness import node_command

    for params, expect in (
        ({"backend": "sim", "odometry_rate": 10.0, "odometry_method": "guess"}, "guess"),
        ({"backend": "sim", "odometry_rate": 10.0, "mounts": [0.1, 0.2]}, "'mounts' needs x, y"),
        (
            {"backend": "sim", "odometry_rate": 10.0, "calibration_file": "/nonexistent.yaml"},
            "nonexistent.yaml",
        ),
        ({"backend": "sim", "odometry_rate": 10.0, "odom_frame": "/odom"}, "leading '/'"),
        (
            {"backend": "sim", "odometry_rate": 10.0, "sensor_frames": ["only_one"]},
            "names 1 frames for 2 devices",
        ),
    ):
        out = subprocess.run(
            node_command(params, "/bad_odo"),
            capture_output=True,
            text=True,
            timeout=60,
            env=dict(os.environ),
        )
        assert out.returncode == 2, out.stdout + out.stderr
        assert expect in out.stdout + out.stderr
        assert "Traceback" not in out.stdout + out.stderr


def _garbage_calibration(tmp_path):
    bad = tmp_path / "cal.yaml"
    bad.write_text("version: 2\nsensors: {/dev/spidev1.0: {scale_x: 0}}\n")
    return bad


def test_bad_calibration_file_exits_2_naming_the_file(ros_command, tmp_path):
    bad = _garbage_calibration(tmp_path)
    out = subprocess.run(
        ros_command("mm_pc.ros.odometry_node", {"calibration_file": str(bad)}, "/odo_badcal"),
        capture_output=True,
        text=True,
        timeout=60,
        env=dict(os.environ),
    )
    assert out.returncode == 2, out.stdout + out.stderr
    assert f"calibration file {bad}: calibration of /dev/spidev1.0: missing key(s)" in out.stderr
    assert "Traceback" not in out.stdout + out.stderr


def test_beagle_bad_calibration_file_exits_2_naming_the_file(tmp_path):
    from mm_beagle.tools.harness import node_command

    bad = _garbage_calibration(tmp_path)
    params = {"backend": "sim", "odometry_rate": 10.0, "calibration_file": str(bad)}
    out = subprocess.run(
        node_command(params, "/bad_cal"), capture_output=True, text=True, timeout=60,
        env=dict(os.environ),
    )
    assert out.returncode == 2, out.stdout + out.stderr
    assert f"calibration file {bad}: calibration of /dev/spidev1.0" in out.stderr
    assert "Traceback" not in out.stdout + out.stderr


def _write_tour(path, lateral: bool = False):
    """A 14 s path at 100 Hz: speed changes, left and right turns, a spin; (v, w) rows."""
    import numpy as np

    t = np.arange(0, 14.0 + 1e-9, 0.01)
    v = 0.15 + 0.1 * np.sin(2 * np.pi * t / 7.0)
    w = 0.9 * np.sin(2 * np.pi * t / 5.0)
    spin = (t > 9.0) & (t < 10.5)
    v[spin], w[spin] = 0.0, 1.5
    cols = [t, v, w]
    header = "t,v,w"
    if lateral:
        cols = [t, v, 0.02 * np.sin(2 * np.pi * t / 3.0), w]
        header = "t,vx,vy,w"
    with open(path, "w") as f:
        f.write(header + "\n")
        for row in zip(*cols, strict=True):
            f.write(",".join(f"{x:.6f}" for x in row) + "\n")


def test_file_trajectory_at_15_hz_ends_on_the_files_ground_truth(tmp_path, ros_command):
    """mm-beagle drives its emulated sensors along a CSV path (turns, speed changes, a
    spin); mm-odometry asks at 15 Hz and integrates every poll: the final pose is the
    simulator's exact integration of the file within 0.5 mm."""
    import numpy as np

    from mm_pc.sim import robot

    path = tmp_path / "tour.csv"
    _write_tour(path)
    v, w, vy = robot.load_trajectory_file(path)
    assert vy is None
    truth = robot.integrate_pose(v, w, robot.DT)[-1]
    beagle = {
        "backend": "sim",
        "sim_trajectory": f"file:{path}",
        "sim_start_delay": 4.0,
        "sim_loop": False,
        "cpi": 6400,  # quantisation (floor of 4 um) well below the tolerance
    }
    ns = "/odo_file"
    params = {"beagle": "/mm_beagle", "rate": 15.0, "method": "exact", "path_rate": 1.0}
    odo = subprocess.Popen(
        ros_command("mm_pc.ros.odometry_node", params, ns), env=dict(os.environ),
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
    )  # fmt: skip
    try:
        with beagle_process(beagle, env=dict(os.environ), log_path=str(tmp_path / "beagle.log")):
            client = BeagleClient("odo_file_client")
            assert client.wait(30)
            got: list[Odometry] = []
            diags = []
            lock = threading.Lock()

            def on_odom(m):
                with lock:
                    got.append(m)

            client.node.create_subscription(Odometry, f"{ns}/mm_odometry/odom", on_odom, 10)
            from diagnostic_msgs.msg import DiagnosticArray

            client.node.create_subscription(DiagnosticArray, "/diagnostics", diags.append, 10)
            try:
                def standing_after_the_tour():
                    with lock:
                        recent = got[-20:]
                    moved = recent and abs(recent[-1].pose.pose.position.x) > 0.1
                    still = len(recent) == 20 and all(
                        m.twist.twist.linear.x == 0 and m.twist.twist.angular.z == 0
                        for m in recent
                    )
                    return recent[-1] if moved and still else None

                final = wait_until(standing_after_the_tour, 60, "standing still after the tour",
                                   interval=0.3)
                p = final.pose.pose
                yaw = 2 * math.atan2(p.orientation.z, p.orientation.w)
                err = math.hypot(p.position.x - truth[0], p.position.y - truth[1])
                assert err < 5e-4, (p.position, truth)
                assert abs(math.remainder(yaw - truth[2], 2 * math.pi)) < 2e-3
                # /diagnostics: every poll integrated, no gap
                # (published once a second: the newest may predate the tour's last polls)
                def newest_pose_status():
                    mine = [s for a in list(diags) for s in a.status
                            if s.name.endswith("mm_odometry: pose")]  # fmt: skip
                    values = {kv.key: kv.value for kv in mine[-1].values} if mine else {}
                    done = int(values.get("polls_integrated", 0)) > 2 * 14_000
                    return values if done else None

                values = wait_until(newest_pose_status, 20,
                                    "/diagnostics counting the tour's 2 x 14000 polls")
                assert values["gaps"] == "0"
                assert np.isfinite(err)
            finally:
                client.close()
    finally:
        odo.send_signal(signal.SIGINT)
        out, _ = odo.communicate(timeout=15)
    assert odo.returncode == 0, out


def test_polls_lost_to_a_ring_overrun_are_a_gap_on_diagnostics(tmp_path, ros_command):
    """mm-odometry stopped for 3 s (SIGSTOP) while mm-beagle's ring holds ~1 s: the polls
    are gone, the interval is stepped with the totals (the pose still ends right) and
    /diagnostics says so."""
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus

    beagle = {"backend": "sim", "sim_trajectory": "straight", "sim_start_delay": 3.0,
              "sim_duration": 5.0, "ring_size": 1024}  # fmt: skip
    ns = "/odo_gap"
    params = {"beagle": "/mm_beagle", "rate": 15.0}
    odo = subprocess.Popen(
        ros_command("mm_pc.ros.odometry_node", params, ns), env=dict(os.environ),
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
    )  # fmt: skip
    try:
        with beagle_process(beagle, env=dict(os.environ), log_path=str(tmp_path / "beagle.log")):
            client = BeagleClient("odo_gap_client")
            assert client.wait(30)
            got: list[Odometry] = []
            diags: list = []
            client.node.create_subscription(Odometry, f"{ns}/mm_odometry/odom", got.append, 10)
            client.node.create_subscription(DiagnosticArray, "/diagnostics", diags.append, 10)
            try:
                wait_until(lambda: got and got[-1].pose.pose.position.x > 0.1, 40,
                           "odometry past x = 0.1 m")
                odo.send_signal(signal.SIGSTOP)
                time.sleep(3.0)
                odo.send_signal(signal.SIGCONT)
                def pose_warning():
                    # the stop may first show as "no reply from ..." (the request out
                    # during the stop waited past reply_timeout): the gap's WARN follows
                    for a in list(diags):
                        for st in a.status:
                            pose = st.name.endswith("mm_odometry: pose")
                            gap = "gap(s) in the single polls" in st.message
                            if pose and gap and st.level == DiagnosticStatus.WARN:
                                return st
                    return None

                warn = wait_until(pose_warning, 30, "a gap's WARN after the overrun")
                values = {kv.key: kv.value for kv in warn.values}
                assert int(values["gaps"]) >= 1
                # the run (1 m straight) still ends at x = 1 m: the totals covered the gap
                wait_until(lambda: got[-1].pose.pose.position.x >= 0.999, 30, "the end at x = 1 m")
                assert got[-1].pose.pose.position.x == pytest.approx(1.0, abs=0.002)
            finally:
                client.close()
    finally:
        odo.send_signal(signal.SIGCONT)
        odo.send_signal(signal.SIGINT)
        out, _ = odo.communicate(timeout=15)
    assert "gap in the single polls" in out and "left the node's ring buffer" in out, out
