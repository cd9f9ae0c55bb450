"""mm-odometry: mouse odometry out as nav_msgs/Odometry and nav_msgs/Path.

A thin ROS node. At ``rate`` Hz it asks mm_beagle for the data of every
sensor (one request, asynchronous: the executor never waits), takes the
displacement since its previous request from the monotone totals (so it
takes no counts away from other clients), applies the calibration, runs the
pose math of :mod:`mm_pc.core.odometry` and publishes

  ~/odom (nav_msgs/Odometry): odom -> base_link pose and body twist, with the
          covariance of :mod:`mm_pc.core.uncertainty`
  ~/path (nav_msgs/Path):    the poses so far (at most ``path_length``), at
          ``path_rate`` Hz

Frame ids, rates, method and geometry are parameters.
"""

from __future__ import annotations

import math
import sys

from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Odometry as OdometryMsg
from nav_msgs.msg import Path
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.node import Node

from mm_interfaces.srv import GetSensorData
from mm_pc.core.angles import yaw_to_quaternion
from mm_pc.core.calibration import Calibration
from mm_pc.core.geometry import DEFAULT_MOUNTS, SensorMount
from mm_pc.core.odometry import METHODS, Odometry, Pose2D, Sample
from mm_pc.core.uncertainty import PoseUncertainty, twist_covariance
from mm_pc.ros import spin as ros_spin


def _ro(desc: str, **kw) -> ParameterDescriptor:
    return ParameterDescriptor(description=desc, read_only=True, **kw)


PARAMETERS = {
    "beagle": ("/mm_beagle", _ro("namespace/name of the mm_beagle node to ask")),
    "rate": (
        15.0,
        _ro(
            "requests per second (Hz)",
            floating_point_range=[FloatingPointRange(from_value=1.0, to_value=500.0)],
        ),
    ),
    "method": ("exact", _ro(f"pose method: {', '.join(sorted(METHODS))}")),
    "sensor": (
        0,
        _ro(
            "which sensor the one-sensor methods use (index into devices)",
            integer_range=[IntegerRange(from_value=0, to_value=15, step=1)],
        ),
    ),
    "devices": (["/dev/spidev1.0", "/dev/spidev1.1"], _ro("sensor ids, in mount order")),
    "mounts": (
        [m for mount in DEFAULT_MOUNTS for m in (mount.x, mount.y, mount.yaw)],
        _ro("x, y, yaw (base_link m, rad) of each sensor, flattened"),
    ),
    "calibration_file": ("", _ro("YAML calibration to apply ('' = none)")),
    "use_lift_estimates": (True, _ro("add the node's estimates of counts lost to lifts")),
    "odom_frame": ("odom", _ro("frame_id of the odometry")),
    "base_frame": ("base_link", _ro("child_frame_id of the odometry")),
    "path_length": (
        10000,
        _ro("poses kept in the path", integer_range=[IntegerRange(from_value=2, to_value=10**6)]),
    ),
    "path_rate": (
        1.0,
        _ro(
            "path messages per second (Hz)",
            floating_point_range=[FloatingPointRange(from_value=0.1, to_value=100.0)],
        ),
    ),
}


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


class OdometryNode(Node):
    def __init__(self, **kwargs) -> None:
        super().__init__("mm_odometry", **kwargs)
        for name, (default, desc) in PARAMETERS.items():
            self.declare_parameter(name, default, desc)
        p = {name: self.get_parameter(name).value for name in PARAMETERS}
        self.p = p
        flat = list(p["mounts"])
        devices = list(p["devices"])
        if len(flat) != 3 * len(devices):
            raise ValueError(
                f"'mounts' needs x, y, yaw for each of the {len(devices)} devices, got {len(flat)}"
            )
        mounts = [SensorMount(*flat[i : i + 3]) for i in range(0, len(flat), 3)]
        self.devices = devices
        # a bad calibration file: OSError/ValueError naming it, exit 2; its fitted
        # sensor positions replace the configured mounts
        self.calibration = (
            Calibration.load(p["calibration_file"]) if p["calibration_file"] else Calibration()
        )
        mounts = self.calibration.mounts(devices, mounts)
        self.odometry = Odometry(mounts, method=p["method"], sensor=p["sensor"])
        self.uncertainty = PoseUncertainty()
        self.client = self.create_client(GetSensorData, f"{p['beagle']}/get_sensor_data")
        self.odom_pub = self.create_publisher(OdometryMsg, "~/odom", 10)
        self.path_pub = self.create_publisher(Path, "~/path", 1)
        self.path = Path()
        self.path.header.frame_id = p["odom_frame"]
        self._last: dict[str, tuple[float, float, int]] = {}  # id -> totals, stamp
        self._in_flight = False
        self.samples_used = 0
        self.create_timer(1.0 / p["rate"], self.request)
        self.create_timer(1.0 / p["path_rate"], self.publish_path)
        self.get_logger().info(
            f"odometry ({p['method']}) from {p['beagle']} at {p['rate']:g} Hz; "
            f"publishing {self.get_fully_qualified_name()}/odom and /path"
        )

    def request(self) -> None:
        """Ask mm-beagle for new sensor data (timer callback); one call in flight at a time."""
        if self._in_flight or not self.client.service_is_ready():
            return  # a slow reply is never doubled up: the totals cover any gap
        self._in_flight = True
        future = self.client.call_async(GetSensorData.Request(id=""))
        future.add_done_callback(self.on_reply)

    def _displacement(self, data) -> tuple[float, float, int] | None:
        """Metres since this sensor's previous reply, from the totals; None the first time."""
        x, y = data.x_total_disp, data.y_total_disp
        if self.p["use_lift_estimates"]:
            x += data.x_lift_est_total_disp
            y += data.y_lift_est_total_disp
        stamp = data.stamp.sec * 1_000_000_000 + data.stamp.nanosec
        prev = self._last.get(data.id)
        self._last[data.id] = (x, y, stamp)
        if prev is None:
            return None
        return x - prev[0], y - prev[1], stamp - prev[2]

    def on_reply(self, future) -> None:
        """Turn a get_sensor_data reply into a pose step and publish it; a failed call is logged."""
        self._in_flight = False
        res = future.result()
        if res is None or not res.success:
            return
        by_id = {d.id: d for d in res.data}
        if any(dev not in by_id for dev in self.devices):
            return  # a sensor is down; its totals still cover the gap next time
        steps = [self._displacement(by_id[dev]) for dev in self.devices]
        if any(s is None for s in steps):
            return
        dt = steps[self.p["sensor"]][2] / 1e9
        if dt <= 0:
            return
        d = [
            self.calibration.apply(dev, s[0], s[1])
            for dev, s in zip(self.devices, steps, strict=True)
        ]
        before = self.odometry.pose
        after = self.odometry.update(Sample.of(dt, *[(float(a), float(b)) for a, b in d]))
        self.samples_used += 1
        self.publish_odometry(before, after, dt, by_id[self.devices[self.p["sensor"]]])

    def publish_odometry(self, before: Pose2D, after: Pose2D, dt: float, data) -> None:
        """Publish nav_msgs/Odometry for the step ``before`` -> ``after`` over ``dt`` s."""
        msg = odometry_message(
            before,
            after,
            dt,
            data.stamp,
            data.cpi,
            self.uncertainty,
            self.p["odom_frame"],
            self.p["base_frame"],
        )
        self.odom_pub.publish(msg)
        ps = PoseStamped()
        ps.header = msg.header
        ps.pose = msg.pose.pose
        self.path.poses.append(ps)
        del self.path.poses[: -self.p["path_length"]]

    def publish_path(self) -> None:
        """Publish the path of the poses so far (timer callback)."""
        if self.path.poses:
            self.path.header.stamp = self.path.poses[-1].header.stamp
            self.path_pub.publish(self.path)


def main(argv: list[str] | None = None) -> int:
    """Entry point of mm-odometry; the exit status (2 for bad parameters)."""
    return ros_spin.run("mm-odometry", OdometryNode, ros_spin.spin_until, argv)


if __name__ == "__main__":
    sys.exit(main())
