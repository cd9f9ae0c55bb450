"""The calibration file's standard errors reach the covariance mm-odometry publishes
(issue 28 item 3): the same straight run with and without them."""

from __future__ import annotations

import os
import signal
import subprocess
import threading

import pytest
from fakes import wait_until

pytest.importorskip("rclpy")
from nav_msgs.msg import Odometry

from mm_beagle.tools.harness import BeagleClient, beagle_process
from mm_pc.core.calibration import Calibration, SensorCalibration
from mm_pc.core.uncertainty import calibration_se

pytestmark = pytest.mark.ros

DEVICES = ["/dev/spidev1.0", "/dev/spidev1.1"]
YAW_SE, SCALE_SE = 0.004, 0.02  # rad, relative: the largest of the two sensors counts
LEVER_M = 0.049  # exact: sensor 0's forward offset turns X into yaw


def test_calibration_se_takes_the_largest_over_the_sensors():
    cal = Calibration({
        DEVICES[0]: SensorCalibration(angle_offset_se=0.001, scale_x_se=SCALE_SE, scale_y_se=0.0),
        DEVICES[1]: SensorCalibration(angle_offset_se=YAW_SE),
    })  # fmt: skip
    assert calibration_se(cal, DEVICES) == {"cal_yaw_se": YAW_SE, "cal_scale_se": SCALE_SE}
    assert calibration_se(Calibration(), DEVICES) == {"cal_yaw_se": 0.0, "cal_scale_se": 0.0}


def test_mm_odometry_publishes_the_calibrations_share(tmp_path, ros_command):
    """Robot stands 4 s, drives 0.4 m straight: the x variance grows by (scale SE x 0.4)^2
    and the yaw variance by (yaw SE x 0.4 / lever)^2 over the run without a file."""
    cal = tmp_path / "cal.yaml"
    Calibration({d: SensorCalibration(angle_offset_se=YAW_SE, scale_x_se=SCALE_SE,
                                      scale_y_se=SCALE_SE) for d in DEVICES}).save(cal)  # fmt: skip
    beagle = {"backend": "sim", "sim_trajectory": "straight", "sim_start_delay": 4.0,
              "sim_duration": 2.0}  # fmt: skip
    procs, got, lock = {}, {"plain": [], "cal": []}, threading.Lock()
    for name, extra in (("plain", {}), ("cal", {"calibration_file": str(cal)})):
        params = {"beagle": "/mm_beagle", "rate": 20.0, "publish_tf": False, **extra}
        procs[name] = subprocess.Popen(
            ros_command("mm_pc.ros.odometry_node", params, f"/cov_{name}"), env=dict(os.environ),
            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
        )  # fmt: skip
    try:
        with beagle_process(beagle, env=dict(os.environ), log_path=str(tmp_path / "beagle.log")):
            client = BeagleClient("cov_client")
            assert client.wait(30)
            for name in got:
                def on(m, name=name):
                    with lock:
                        got[name].append(m)
                        del got[name][:-5]

                client.node.create_subscription(Odometry, f"/cov_{name}/mm_odometry/odom", on, 10)
            try:
                def both_stopped():
                    with lock:
                        last = {k: v[-1] for k, v in got.items() if v}
                    done = len(last) == 2 and all(
                        m.pose.pose.position.x > 0.39 and m.twist.twist.linear.x == 0
                        for m in last.values()
                    )
                    return last if done else None

                last = wait_until(both_stopped, 40, "both poses at the end of the run")
            finally:
                client.close()
    finally:
        for p in procs.values():
            p.send_signal(signal.SIGINT)
        outs = {k: p.communicate(timeout=15)[0] for k, p in procs.items()}
    assert all(p.returncode == 0 for p in procs.values()), outs
    plain, calibrated = (last[k].pose.covariance for k in ("plain", "cal"))
    d = calibrated[0] - plain[0]  # x: the scale error along the run
    assert d == pytest.approx((SCALE_SE * 0.4) ** 2, rel=0.05)
    d_yaw = calibrated[35] - plain[35]  # yaw: the mounting-angle error through the lever
    assert d_yaw == pytest.approx((YAW_SE * 0.4 / LEVER_M) ** 2, rel=0.05)
