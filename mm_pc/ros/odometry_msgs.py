"""nav_msgs/Odometry builders shared by mm-odometry and mm-beagle's own odometry.

:func:`odometry_message`: a step of the integrated pose (mm-odometry's ~/odom and
mm-beagle's 1 kHz ~/odom), with the covariance of :mod:`mm_pc.core.uncertainty`.
:func:`chip_odometry`: a chip's own pose (the OTOS's on-chip fusion) as it reports it.
Poses in the odom frame, twists in the base frame (REP 103); metres, radians, seconds.
"""

from __future__ import annotations

import math

from nav_msgs.msg import Odometry as OdometryMsg

from mm_pc.core.angles import yaw_to_quaternion
from mm_pc.core.odometry import Pose2D
from mm_pc.core.uncertainty import PoseUncertainty, twist_covariance

#: a covariance nobody knows: the first element -1 (REP 103's "unknown"), the rest 0
UNKNOWN_COVARIANCE = [-1.0] + [0.0] * 35


def odometry_message(
    before: Pose2D,
    after: Pose2D,
    dt: float,
    stamp,
    cpi: int,
    uncertainty: PoseUncertainty,
    odom_frame: str,
    base_frame: str,
) -> OdometryMsg:
    """nav_msgs/Odometry for the step ``before`` -> ``after`` over ``dt`` s.

    The twist is the body-frame increment (x forward, y left, yaw) divided by
    dt; ``uncertainty`` is advanced by the step. Shared by mm-odometry and
    mm-beagle's own 1 kHz odometry.
    """
    c, s = math.cos(before.yaw), math.sin(before.yaw)
    ddx, ddy = after.x - before.x, after.y - before.y
    fwd, left = c * ddx + s * ddy, -s * ddx + c * ddy
    turned = after.yaw - before.yaw
    uncertainty.cpi = max(cpi, 1)  # the quantisation floor at the CPI in force
    uncertainty.add(fwd, turned, lateral=left, heading=before.yaw)
    msg = OdometryMsg()
    msg.header.stamp = stamp
    msg.header.frame_id = odom_frame
    msg.child_frame_id = base_frame
    msg.pose.pose.position.x, msg.pose.pose.position.y = after.x, after.y
    o = msg.pose.pose.orientation
    o.x, o.y, o.z, o.w = yaw_to_quaternion(after.yaw)
    msg.pose.covariance = uncertainty.pose_covariance()
    msg.twist.twist.linear.x, msg.twist.twist.linear.y = fwd / dt, left / dt
    msg.twist.twist.angular.z = turned / dt
    msg.twist.covariance = twist_covariance(max(cpi, 1), dt)
    return msg


def chip_odometry(
    pose: tuple[float, float, float],
    twist: tuple[float, float, float],
    stamp,
    odom_frame: str,
    base_frame: str,
) -> OdometryMsg:
    """nav_msgs/Odometry of a chip's own ``pose`` (x, y m, yaw rad in ``odom_frame``) and
    ``twist`` (vx, vy m/s, wz rad/s in ``base_frame``). The chip gives no covariance:
    both matrices are :data:`UNKNOWN_COVARIANCE`."""
    msg = OdometryMsg()
    msg.header.stamp = stamp
    msg.header.frame_id = odom_frame
    msg.child_frame_id = base_frame
    msg.pose.pose.position.x, msg.pose.pose.position.y = pose[0], pose[1]
    q = msg.pose.pose.orientation
    q.x, q.y, q.z, q.w = yaw_to_quaternion(pose[2])
    msg.twist.twist.linear.x, msg.twist.twist.linear.y = twist[0], twist[1]
    msg.twist.twist.angular.z = twist[2]
    msg.pose.covariance = UNKNOWN_COVARIANCE
    msg.twist.covariance = UNKNOWN_COVARIANCE
    return msg
