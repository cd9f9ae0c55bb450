"""TF for the nodes: planar transforms on /tf, the sensor mounts on /tf_static.

tf2_ros is not among the PyPI Jazzy wheels, so the nodes publish
``tf2_msgs/msg/TFMessage`` themselves with the QoS tf2_ros's broadcasters use
(RViz, Nav2 and robot_localization cannot tell the difference): /tf reliable,
volatile, depth 100; /tf_static reliable, transient-local, depth 1 (a late
subscriber still gets the mounts). ./compile builds tf2_msgs where no system
ROS provides it (mm_interfaces/vendor/tf2_msgs, same type hash as Jazzy's).

Frames: REP 103/105 (odom -> base_link, map -> odom); poses in metres and rad.
"""

from __future__ import annotations

from collections.abc import Sequence

from geometry_msgs.msg import TransformStamped
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from tf2_msgs.msg import TFMessage

from mm_pc.core.angles import yaw_to_quaternion
from mm_pc.core.geometry import SensorMount

__all__ = ["DYNAMIC_QOS", "STATIC_QOS", "TfPublisher", "mount_transforms", "planar_transform"]

DYNAMIC_QOS = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
STATIC_QOS = QoSProfile(
    depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL
)


def planar_transform(
    stamp, parent: str, child: str, x: float, y: float, yaw: float
) -> TransformStamped:
    """``child`` in ``parent`` at (x, y) metres, turned by ``yaw`` rad (CCW+), z = 0."""
    t = TransformStamped()
    t.header.stamp = stamp
    t.header.frame_id = parent
    t.child_frame_id = child
    t.transform.translation.x = float(x)
    t.transform.translation.y = float(y)
    r = t.transform.rotation
    r.x, r.y, r.z, r.w = yaw_to_quaternion(float(yaw))
    return t


def mount_transforms(
    stamp, base_frame: str, sensor_frames: Sequence[str], mounts: Sequence[SensorMount]
) -> list[TransformStamped]:
    """base_link -> each sensor frame at its mount (position; yaw = the mounting error).

    The sensor frame's axes are REP 103's for the sensor (x = the robot's forward
    direction when ideally mounted), not the seed's sensor axes (X right, Y forward).
    """
    if len(sensor_frames) != len(mounts):
        raise ValueError(
            f"{len(sensor_frames)} sensor frame names for {len(mounts)} sensors; give one each"
        )
    return [
        planar_transform(stamp, base_frame, name, m.x, m.y, m.yaw)
        for name, m in zip(sensor_frames, mounts, strict=True)
    ]


class TfPublisher:
    """/tf (and, once, /tf_static) for one node; ``enabled`` False sends nothing."""

    def __init__(self, node: Node, enabled: bool = True) -> None:
        self.enabled = enabled
        self._node = node
        self._pub = node.create_publisher(TFMessage, "/tf", DYNAMIC_QOS) if enabled else None
        self._static = None

    def send(self, *transforms: TransformStamped) -> None:
        if self._pub is not None:
            self._pub.publish(TFMessage(transforms=list(transforms)))

    def send_static(self, transforms: Sequence[TransformStamped]) -> None:
        """Latched on /tf_static (transient-local): sent once, kept for late subscribers."""
        if not self.enabled:
            return
        if self._static is None:
            self._static = self._node.create_publisher(TFMessage, "/tf_static", STATIC_QOS)
        self._static.publish(TFMessage(transforms=list(transforms)))
