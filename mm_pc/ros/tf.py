"""TF for the nodes: planar transforms on /tf, the sensor mounts on /tf_static.

tf2_ros is not among the PyPI Jazzy wheels, so the nodes publish
``tf2_msgs/msg/TFMessage`` themselves with the QoS tf2_ros's broadcasters use
(RViz, Nav2 and robot_localization cannot tell the difference): /tf reliable,
volatile, depth 100; /tf_static reliable, transient-local, depth 1 (a late
subscriber still gets the mounts). Subscribers to /tf_static use tf2_ros's listener
depth of 100 (:data:`STATIC_LISTENER_QOS`): with depth 1 a reader keeps only the last of
several publishers' latched messages that arrive together and loses the others' frames.
./compile builds tf2_msgs where no system ROS provides it (mm_interfaces/vendor/tf2_msgs,
same type hash as Jazzy's).

Frames: REP 103/105 (odom -> base_link, map -> odom); poses in metres and rad.
Many robots on one /tf: every node that names frames takes ``frame_prefix`` (as
robot_state_publisher's: put before every frame id it publishes, '' = none), so robot
r1's tree is r1/odom -> r1/base_link -> r1/mouse_*; :func:`prefixed` is the one rule.
Each sensor frame ``mouse_X`` (REP 103 axes: x forward when ideally mounted) has a fixed
child ``mouse_X_counts`` (:func:`counts_frame`): the axes ``SensorData`` counts in
(x to the robot's right, y forward), ``mouse_X`` turned by -90 deg about z; it is
``SensorData``'s ``header.frame_id``, so tf2 takes its numbers into base_link.
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence

from geometry_msgs.msg import TransformStamped
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from tf2_msgs.msg import TFMessage

from mm_pc.core.angles import yaw_to_quaternion
from mm_pc.core.geometry import SensorMount
from mm_pc.ros.parameters import read_only

__all__ = [
    "COUNTS_SUFFIX",
    "COUNTS_YAW",
    "DYNAMIC_QOS",
    "STATIC_LISTENER_QOS",
    "STATIC_QOS",
    "TfPublisher",
    "counts_frame",
    "frame_id_problem",
    "frame_ids_problem",
    "frame_prefix_parameter",
    "frame_prefix_problem",
    "mount_transforms",
    "planar_transform",
    "prefixed",
    "sensor_frame_names",
]

DYNAMIC_QOS = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
STATIC_QOS = QoSProfile(
    depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL
)
#: a /tf_static subscription's (tf2_ros's StaticListenerQoS): room for every publisher's mounts
STATIC_LISTENER_QOS = QoSProfile(
    depth=100, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL
)


#: the counting-axes frame of sensor frame F is F + this (``SensorData.header.frame_id``)
COUNTS_SUFFIX = "_counts"
#: its yaw in the sensor frame (rad): counts x = the sensor's right, y = its forward
COUNTS_YAW = -math.pi / 2

_FRAME_ID = re.compile(r"[A-Za-z_][A-Za-z0-9_./-]*")


def frame_id_problem(name: str, value: object) -> str:
    """'' if ``value`` can be a TF frame id (tf2: no leading '/', no spaces), else why not.

    ``name`` is the parameter's name, for the message.
    """
    v = str(value)
    if not v:
        return f"'{name}' must not be empty"
    if v.startswith("/"):
        return f"'{name}' is '{v}': TF frame ids have no leading '/' (tf2 rejects them)"
    if not _FRAME_ID.fullmatch(v):
        return (
            f"'{name}' is '{v}': a TF frame id starts with a letter or '_' and holds only "
            "letters, digits, '_', '.', '/', '-'"
        )
    return ""


def frame_ids_problem(values: dict, names: tuple[str, ...]) -> str:
    """The first :func:`frame_id_problem` among ``names`` present in ``values`` (a node's
    parameters, or the changes of one ``ros2 param set``), else ''."""
    for name in names:
        if name in values and (problem := frame_id_problem(name, values[name])):
            return problem
    return ""


def frame_prefix_parameter() -> tuple[str, object]:
    """The ``frame_prefix`` entry of a node's parameter table (read-only, '' = none)."""
    return (
        "",
        read_only(
            "put before every frame id this node publishes, as robot_state_publisher's "
            "frame_prefix: 'r1/' makes odom r1/odom (many robots on one /tf); '' = none"
        ),
    )


def frame_prefix_problem(value: object) -> str:
    """'' if ``value`` can go before frame ids ('' or e.g. 'r1/'), else why not."""
    return frame_id_problem("frame_prefix", value) if str(value) else ""


def prefixed(prefix: str, frame: str) -> str:
    """``frame`` as published under ``prefix`` (plain concatenation, as robot_state_publisher)."""
    return f"{prefix}{frame}"


def sensor_frame_names(
    devices: Sequence[str], given: Sequence[str] = (), prefix: str = ""
) -> list[str]:
    """One TF frame per sensor: ``given`` (checked) or derived from the device names,
    each after ``prefix`` (see :func:`prefixed`).

    Derived: ``mouse_`` + the last path part with every other character as '_'
    ('/dev/spidev1.0' -> 'mouse_spidev1_0'). ValueError says what is wrong.
    """
    names = [str(g) for g in given if str(g)]
    if not names:
        names = ["mouse_" + re.sub(r"[^A-Za-z0-9_]", "_", d.rstrip("/").rsplit("/", 1)[-1])
                 for d in devices]  # fmt: skip
    if len(names) != len(devices):
        raise ValueError(
            f"'sensor_frames' names {len(names)} frames for {len(devices)} devices; give one each"
        )
    if len(set(names)) != len(names):
        raise ValueError(f"'sensor_frames' must be distinct, got {names}")
    for n in names:
        problem = frame_id_problem("sensor_frames", n)
        if problem:
            raise ValueError(problem)
    if problem := frame_prefix_problem(prefix):
        raise ValueError(problem)
    return [prefixed(prefix, n) for n in names]


def counts_frame(sensor_frame: str) -> str:
    """The counting-axes frame of ``sensor_frame`` (as published, prefix included):
    'r1/mouse_spidev1_0' -> 'r1/mouse_spidev1_0_counts'."""
    return f"{sensor_frame}{COUNTS_SUFFIX}"


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
    """base_link -> each sensor frame at its mount (position; yaw = the mounting error),
    then each sensor frame -> its counting-axes frame (:func:`counts_frame`, yaw -pi/2).

    The sensor frame's axes are REP 103's for the sensor (x = the robot's forward
    direction when ideally mounted); the ``_counts`` child has the seed's sensor axes
    (X right, Y forward) that ``SensorData`` is given in.
    """
    if len(sensor_frames) != len(mounts):
        raise ValueError(
            f"{len(sensor_frames)} sensor frame names for {len(mounts)} sensors; give one each"
        )
    return [
        planar_transform(stamp, base_frame, name, m.x, m.y, m.yaw)
        for name, m in zip(sensor_frames, mounts, strict=True)
    ] + [
        planar_transform(stamp, name, counts_frame(name), 0.0, 0.0, COUNTS_YAW)
        for name in sensor_frames
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
