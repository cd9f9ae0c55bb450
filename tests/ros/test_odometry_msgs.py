"""mm_pc.ros.odometry_msgs: the nav_msgs/Odometry builders mm-odometry and mm-beagle share."""

from __future__ import annotations

import math

import pytest

pytest.importorskip("nav_msgs")

from builtin_interfaces.msg import Time

from mm_pc.core.odometry import Pose2D
from mm_pc.core.uncertainty import PoseUncertainty
from mm_pc.ros.odometry_msgs import UNKNOWN_COVARIANCE, chip_odometry, odometry_message


def test_a_step_gives_the_pose_and_the_body_twist():
    before, after = Pose2D(1.0, 2.0, math.pi / 2), Pose2D(1.0, 2.5, math.pi / 2 + 0.1)
    unc = PoseUncertainty()
    msg = odometry_message(before, after, 0.5, Time(sec=3), 1600, unc, "odom", "base_link")
    assert (msg.header.frame_id, msg.child_frame_id) == ("odom", "base_link")
    assert msg.header.stamp.sec == 3
    assert (msg.pose.pose.position.x, msg.pose.pose.position.y) == (1.0, 2.5)
    q = msg.pose.pose.orientation
    half = (math.pi / 2 + 0.1) / 2
    assert (q.z, q.w) == pytest.approx((math.sin(half), math.cos(half)))
    # heading +y: 0.5 m along +y is 0.5 m forward in the body frame, over 0.5 s
    assert msg.twist.twist.linear.x == pytest.approx(1.0)
    assert msg.twist.twist.linear.y == pytest.approx(0.0, abs=1e-12)
    assert msg.twist.twist.angular.z == pytest.approx(0.2)
    assert unc.cpi == 1600
    assert msg.pose.covariance[0] > 0 and msg.twist.covariance[0] > 0


def test_a_chips_pose_has_no_covariance():
    msg = chip_odometry((0.3, -0.2, -math.pi / 2), (0.1, 0.0, 0.5), Time(sec=7), "odom", "base")
    assert (msg.header.frame_id, msg.child_frame_id, msg.header.stamp.sec) == ("odom", "base", 7)
    assert (msg.pose.pose.position.x, msg.pose.pose.position.y) == (0.3, -0.2)
    q = msg.pose.pose.orientation
    assert (q.x, q.y) == (0.0, 0.0)
    assert (q.z, q.w) == pytest.approx((-math.sqrt(0.5), math.sqrt(0.5)))
    assert (msg.twist.twist.linear.x, msg.twist.twist.angular.z) == (0.1, 0.5)
    assert list(msg.pose.covariance) == UNKNOWN_COVARIANCE == list(msg.twist.covariance)
    assert UNKNOWN_COVARIANCE[0] == -1.0 and not any(UNKNOWN_COVARIANCE[1:])
