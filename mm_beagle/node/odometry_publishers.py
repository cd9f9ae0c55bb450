"""The node's two optional nav_msgs/Odometry outputs.

:class:`OnboardOdometryPublisher` (``odometry_rate`` > 0): every 1 kHz poll integrated
here (:mod:`mm_beagle.node.onboard_odometry`) and published on ``~/odom`` as
mm-odometry's (same math, same message); with ``publish_tf`` also odom -> base_link on
/tf and the mounts on /tf_static; ``~/reset`` (std_srvs/Trigger) puts the pose and its
covariance back to the start.

:class:`ChipOdometryPublisher`: the OTOS's on-chip pose (issue 15 part 5).
"""

from __future__ import annotations

from nav_msgs.msg import Odometry as OdometryMsg

from mm_beagle.node.onboard_odometry import OnboardOdometry
from mm_beagle.poller import shared_state as ss
from mm_pc.core.uncertainty import PoseUncertainty, calibration_se
from mm_pc.ros.clock import node_stamp
from mm_pc.ros.odometry_msgs import chip_odometry, odometry_message
from mm_pc.ros.reset import create_reset_service
from mm_pc.ros.tf import TfPublisher, mount_transforms, planar_transform, sensor_frame_names


class OnboardOdometryPublisher:
    """~/odom from every poll of ``node`` (a BeagleNode), at ``odometry_rate`` Hz."""

    def __init__(self, node) -> None:
        self.node = node
        o = node.settings.odometry
        self.onboard = OnboardOdometry(o, node.devices, node.poller.state, node.chips)
        self.sensor_frames = sensor_frame_names(node.devices, o.sensor_frames, o.frame_prefix)
        self.uncertainty = PoseUncertainty(**calibration_se(self.onboard.calibration, node.devices))
        self.tf = TfPublisher(node, o.publish_tf)
        self.send_static_frames()
        self.pub = node.create_publisher(OdometryMsg, "~/odom", 10)
        create_reset_service(node, self.reset)
        node.create_timer(1.0 / o.rate, self.tick)

    def tick(self) -> None:
        """Integrate the polls since the previous tick; publish the pose (and its TF)."""
        o = self.node.settings.odometry  # frames are live parameters
        try:
            step = self.onboard.step()
        except ss.PollerBusyError:
            return  # the polls stay in the ring: the next tick integrates them
        if step is None:
            return
        before, after, dt, stamp_ns, cpi = step
        msg = odometry_message(
            before,
            after,
            dt,
            node_stamp(self.node, stamp_ns),
            cpi,
            self.uncertainty,
            o.odom_frame,
            o.base_frame,
        )
        self.pub.publish(msg)
        self.tf.send(
            planar_transform(
                msg.header.stamp, o.odom_frame, o.base_frame, after.x, after.y, after.yaw
            )
        )

    def reset(self) -> str:
        self.onboard.reset()
        self.uncertainty.reset()
        frame = self.node.settings.odometry.odom_frame
        return f"onboard odometry back to (0, 0, 0) in {frame}, covariance cleared"

    def send_static_frames(self) -> None:
        """base_link -> each sensor frame at its (calibrated) mount, and each sensor frame ->
        its ``_counts`` frame (SensorData's), latched on /tf_static."""
        self.tf.send_static(
            mount_transforms(
                self.node.get_clock().now().to_msg(),
                self.node.settings.odometry.base_frame,
                self.sensor_frames,
                self.onboard.odometry.mounts,
            )
        )


class ChipOdometryPublisher:
    """The OTOS's on-chip pose as a second nav_msgs/Odometry.

    One topic per OTOS device: ``~/otos/odom`` for the first, ``~/otos/odom_<index>``
    (its index in ``devices``) for any further one; frame ids as the onboard odometry's
    (``odom_frame``, ``base_frame``); at ``publish_rate`` (0: none), a message only when
    the chip's pose is newer than the last one sent. The chip gives no covariance: the
    first element of each matrix is -1 (unknown), the rest 0; do not fuse it as is.
    """

    def __init__(self, node, otos: list[int]) -> None:
        self.node = node
        self.pubs = {
            i: node.create_publisher(
                OdometryMsg, "~/otos/odom" if k == 0 else f"~/otos/odom_{i}", 10
            )
            for k, i in enumerate(otos)
        }
        self.sent = dict.fromkeys(otos, 0)
        node.create_timer(1.0 / node.settings.publish_rate, self.tick)
        node.get_logger().info(
            "OTOS on-chip pose on "
            + ", ".join(f"{pub.topic_name} ({node.devices[i]})" for i, pub in self.pubs.items())
        )

    def tick(self) -> None:
        node = self.node
        o = node.settings.odometry
        for i, pub in self.pubs.items():
            try:
                t = node.poller.state.snapshot(i)
            except ss.PollerBusyError:
                continue
            if t.chip_pose_ns == self.sent[i] or t.state != ss.STATE_UP:
                continue
            self.sent[i] = t.chip_pose_ns
            pub.publish(
                chip_odometry(
                    (t.chip_x, t.chip_y, t.chip_yaw),
                    (t.chip_vx, t.chip_vy, t.chip_wz),
                    node_stamp(node, t.chip_pose_ns),
                    o.odom_frame,
                    o.base_frame,
                )
            )
