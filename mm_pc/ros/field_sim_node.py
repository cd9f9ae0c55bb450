"""mm-field-sim: replay the simulated lawn-mowing run of :mod:`mm_pc.sim.field_run` on ROS topics.

Simulates the run (``seed``) and publishes what each sensor reported, at the
time it reported it, ``speed`` times faster than real time; then exits 0.
Stamps are sensor time: the node's clock at the start plus the run's time
(at speed > 1 they run ahead of the wall clock, as in a fast bag replay).

  mm_odometry/odom   nav_msgs/Odometry   mouse odometry (20 Hz), odom -> base_link,
                     starting at the origin as mm-odometry does; not published
                     during ``mouse_dropout`` (lifted sensors: the counts of that
                     stretch are lost, the pose resumes where it stopped)
  /wheel/odom        nav_msgs/Odometry   wheel odometry (20 Hz), wheel_odom -> base_link
  /gps/fix           sensor_msgs/NavSatFix  2 Hz. As a GPS driver would: covariance
                     APPROXIMATED from HDOP, (HDOP * 2.5 m)^2 / 2 per axis; a fix with
                     fewer than 5 satellites or a non-position fix type goes out as
                     NO_FIX (NavSatFix has no satellite count)
  /beacons/<name>/range  sensor_msgs/Range  5 Hz per beacon (slant range)
  /imu/data          sensor_msgs/Imu     10 Hz, orientation only: the seed's compass
                     heading turned into a REP 103 yaw (compass_to_rep103); yaw variance
                     (2 deg)^2 + (1 deg bias)^2, roll/pitch 1e6, no rates/accelerations
  /compass/heading   std_msgs/Float64    the same heading unconverted (rad, 0 = north, CW)
  /perimeter/contact geometry_msgs/PointStamped when the robot's centre crosses a wire:
                     (NaN, NaN) = "a wire", as a robot knows it; with
                     ``perimeter_known_wire`` the wire's coordinate (other axis NaN)
  ~/truth            nav_msgs/Odometry   the true pose, map -> base_link (plot frame), every
                     ``truth_every`` requests and at the end

With ``wait_for_subscribers`` > 0 it waits (at most ``wait_timeout`` s) until
that many subscribers listen to the mouse odometry, so a fast replay does not
start before the fusion node is there.
"""

from __future__ import annotations

import math
import sys
import threading
import time

import numpy as np
import rclpy
from builtin_interfaces.msg import Time
from geometry_msgs.msg import PointStamped
from nav_msgs.msg import Odometry as OdometryMsg
from rclpy.node import Node
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import Imu, NavSatFix, NavSatStatus, Range
from std_msgs.msg import Float64

from mm_pc.core.angles import compass_to_rep103, yaw_to_quaternion
from mm_pc.core.fixes.gps import gps_accuracy_m
from mm_pc.core.fusion.inputs import seconds_to_stamp
from mm_pc.core.uncertainty import UNOBSERVED_VARIANCE, planar_covariance_6x6
from mm_pc.ros import spin as ros_spin
from mm_pc.ros.parameters import declare_all, float_range, int_range, read_only
from mm_pc.ros.tf import frame_ids_problem, frame_prefix_parameter, frame_prefix_problem, prefixed
from mm_pc.sim.field_run import FieldSim, simulate_field_run

GPS_MIN_SATELLITES = 5


PARAMETERS = {
    "seed": (
        1,
        read_only("random seed of the run", **int_range(0, 2**31)),
    ),
    "speed": (1.0, read_only("replay speed (x real time)", **float_range(0.01, 10000.0))),
    "duration": (
        0.0,
        read_only("replay only the first this many seconds (0 = all)", **float_range(0.0, 1e6)),
    ),
    "wait_for_subscribers": (
        0,
        read_only(
            "wait for this many subscribers of the mouse odometry before starting",
            **int_range(0, 100),
        ),
    ),
    "wait_timeout": (10.0, read_only("longest wait for them (s)", **float_range(0.0, 3600.0))),
    "linger": (
        0.5,
        read_only("seconds to stay up after the last message", **float_range(0.0, 60.0)),
    ),
    "truth_every": (
        1,
        read_only(
            "publish the truth every this many requests (and at the last)",
            **int_range(1, 10**6),
        ),
    ),
    "mouse_dropout": (
        [0.0, 0.0],
        read_only("no mouse odometry from start s for duration s (duration 0 = none)"),
    ),
    "perimeter_known_wire": (False, read_only("contacts name the wire's coordinate")),
    "mouse_odom_topic": (
        "mm_odometry/odom",
        read_only("mouse odometry topic (relative: mm-fusion's default in the same namespace)"),
    ),
    "wheel_odom_topic": ("/wheel/odom", read_only("wheel odometry topic")),
    "gps_topic": ("/gps/fix", read_only("GPS topic")),
    "imu_topic": ("/imu/data", read_only("compass (Imu) topic")),
    "heading_topic": ("/compass/heading", read_only("compass (Float64, seed convention) topic")),
    "perimeter_topic": ("/perimeter/contact", read_only("wire contact topic")),
    "beacon_topic": (
        "/beacons/{name}/range",
        read_only("range topic per beacon, {name} = its name"),
    ),
    "truth_topic": ("~/truth", read_only("ground truth topic")),
    "map_frame": ("map", read_only("frame of the truth and of wire coordinates")),
    "odom_frame": ("odom", read_only("frame of the mouse odometry")),
    "wheel_odom_frame": ("wheel_odom", read_only("frame of the wheel odometry")),
    "base_frame": ("base_link", read_only("robot frame")),
    "gps_frame": ("gps", read_only("frame_id of the NavSatFix")),
    "imu_frame": ("imu", read_only("frame_id of the Imu")),
    "range_frame": ("range_antenna", read_only("frame_id of the Range messages")),
    "frame_prefix": frame_prefix_parameter(),
    "queue_depth": (
        200,
        read_only("publisher queue depth", **int_range(1, 10**5)),
    ),
}


#: the frame parameters, each published after ``frame_prefix``
FRAMES = tuple(name for name in PARAMETERS if name.endswith("_frame"))


def relative_poses(poses: np.ndarray, start: np.ndarray) -> np.ndarray:
    """(N, 3) poses (x, y, yaw) expressed in the frame of the pose ``start``."""
    c, s = math.cos(start[2]), math.sin(start[2])
    dx, dy = poses[:, 0] - start[0], poses[:, 1] - start[1]
    return np.stack([c * dx + s * dy, -s * dx + c * dy, poses[:, 2] - start[2]], axis=1)


def compose(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Pose ``b`` (N, 3) given in the frame of pose ``a`` (3,), expressed in a's parent."""
    c, s = math.cos(a[2]), math.sin(a[2])
    return np.stack(
        [a[0] + c * b[:, 0] - s * b[:, 1], a[1] + s * b[:, 0] + c * b[:, 1], a[2] + b[:, 2]],
        axis=1,
    )


def mouse_with_dropout(raw: np.ndarray, t: np.ndarray, start: float, duration: float):
    """Mouse odometry poses with a lift over [start, start + duration) s: (poses, published?).

    While lifted nothing is published and nothing counted: after the gap the
    pose continues from where it stopped, so it lacks the stretch driven blind.
    """
    published = np.ones(t.size, dtype=bool)
    if duration <= 0:
        return raw, published
    lifted = (t >= start) & (t < start + duration)
    published[lifted] = False
    after = np.flatnonzero(t >= start + duration)
    before = np.flatnonzero(t < start)
    if after.size == 0 or before.size == 0:
        return raw, published
    out = raw.copy()
    k0, k1 = before[-1], after[0]
    out[k1:] = compose(raw[k0], relative_poses(raw[k1:], raw[k1]))
    return out, published


def _check_dropout(values) -> tuple[float, float]:
    v = [float(x) for x in values]
    if len(v) != 2 or not all(math.isfinite(x) and x >= 0 for x in v):
        raise ValueError(f"'mouse_dropout' needs [start s, duration s], both >= 0, got {values}")
    return v[0], v[1]


class FieldSimNode(Node):
    def __init__(self, **kwargs) -> None:
        super().__init__("field_sim", **kwargs)
        p = declare_all(self, PARAMETERS)
        if problem := frame_ids_problem(p, FRAMES) or frame_prefix_problem(p["frame_prefix"]):
            raise ValueError(problem)
        p.update({name: prefixed(p["frame_prefix"], p[name]) for name in FRAMES})  # read-only
        self.p = p
        self.dropout = _check_dropout(p["mouse_dropout"])
        self.sim: FieldSim = simulate_field_run(int(p["seed"]))
        qos = QoSProfile(
            history=HistoryPolicy.KEEP_LAST,
            depth=p["queue_depth"],
            reliability=ReliabilityPolicy.RELIABLE,
        )
        pub = self.create_publisher
        self.mouse_pub = pub(OdometryMsg, p["mouse_odom_topic"], qos)
        self.wheel_pub = pub(OdometryMsg, p["wheel_odom_topic"], qos)
        self.truth_pub = pub(OdometryMsg, p["truth_topic"], qos)
        self.gps_pub = pub(NavSatFix, p["gps_topic"], qos)
        self.imu_pub = pub(Imu, p["imu_topic"], qos)
        self.heading_pub = pub(Float64, p["heading_topic"], qos)
        self.contact_pub = pub(PointStamped, p["perimeter_topic"], qos)
        self.range_pubs = [
            pub(Range, p["beacon_topic"].format(name=b.name), qos) for b in self.sim.beacons
        ]
        self._prepare()
        self.get_logger().info(
            f"field run seed {p['seed']}: {self.sim.run_length_m:.1f} m in "
            f"{self.sim.t[-1]:.1f} s; replay at {p['speed']:g}x"
        )

    def _prepare(self) -> None:
        sim = self.sim
        start = sim.truth[0]
        mouse = relative_poses(sim.raw, start)
        self.mouse, self.mouse_published = mouse_with_dropout(mouse, sim.t, *self.dropout)
        self.wheels = relative_poses(sim.raw_wheels, start)
        self.events: dict[int, list] = {}
        for kind, readings in (
            ("compass", sim.compass),
            ("ranges", sim.ranges),
            ("gps", sim.gps),
            ("contact", sim.contacts),
        ):
            for r in readings:
                self.events.setdefault(r.k, []).append((kind, r))
        self._planar_cov = np.array(planar_covariance_6x6(np.zeros((3, 3))))
        ori = np.zeros(9)
        ori[0] = ori[4] = UNOBSERVED_VARIANCE
        ori[8] = sim.compass_var
        self._imu_cov = ori

    # -- messages -------------------------------------------------------------------------------

    def _odom(self, stamp: Time, frame: str, poses: np.ndarray, k: int) -> OdometryMsg:
        msg = OdometryMsg()
        msg.header.stamp = stamp
        msg.header.frame_id = frame
        msg.child_frame_id = self.p["base_frame"]
        x, y, yaw = poses[k]
        msg.pose.pose.position.x, msg.pose.pose.position.y = float(x), float(y)
        o = msg.pose.pose.orientation
        o.x, o.y, o.z, o.w = yaw_to_quaternion(float(yaw))
        msg.pose.covariance = self._planar_cov
        if k > 0:
            dt = float(self.sim.t[k] - self.sim.t[k - 1])
            c, s = math.cos(poses[k - 1, 2]), math.sin(poses[k - 1, 2])
            dx, dy = poses[k, 0] - poses[k - 1, 0], poses[k, 1] - poses[k - 1, 1]
            msg.twist.twist.linear.x = float(c * dx + s * dy) / dt
            msg.twist.twist.linear.y = float(-s * dx + c * dy) / dt
            msg.twist.twist.angular.z = float(poses[k, 2] - poses[k - 1, 2]) / dt
        msg.twist.covariance = self._planar_cov
        return msg

    def _gps(self, stamp: Time, r) -> NavSatFix:
        msg = NavSatFix()
        msg.header.stamp = stamp
        msg.header.frame_id = self.p["gps_frame"]
        q = r.quality
        usable = q.fix_type in (1, 2, 3, 4, 5) and q.satellites >= GPS_MIN_SATELLITES
        msg.status.status = NavSatStatus.STATUS_FIX if usable else NavSatStatus.STATUS_NO_FIX
        msg.status.service = NavSatStatus.SERVICE_GPS
        msg.latitude, msg.longitude, msg.altitude = r.lat, r.lon, math.nan
        var = gps_accuracy_m(q) ** 2 / 2
        msg.position_covariance = [var, 0.0, 0.0, 0.0, var, 0.0, 0.0, 0.0, 8 * var]
        msg.position_covariance_type = NavSatFix.COVARIANCE_TYPE_APPROXIMATED
        return msg

    def _imu(self, stamp: Time, heading: float) -> Imu:
        msg = Imu()
        msg.header.stamp = stamp
        msg.header.frame_id = self.p["imu_frame"]
        o = msg.orientation
        o.x, o.y, o.z, o.w = yaw_to_quaternion(float(compass_to_rep103(heading)))
        msg.orientation_covariance = self._imu_cov
        msg.angular_velocity_covariance[0] = -1.0
        msg.linear_acceleration_covariance[0] = -1.0
        return msg

    def _range(self, stamp: Time, value: float) -> Range:
        msg = Range()
        msg.header.stamp = stamp
        msg.header.frame_id = self.p["range_frame"]
        msg.radiation_type = Range.ULTRASOUND
        msg.field_of_view = 2 * math.pi
        msg.min_range, msg.max_range = 0.1, 100.0
        msg.range = float(value)
        return msg

    def _contact(self, stamp: Time, contact) -> PointStamped:
        msg = PointStamped()
        msg.header.stamp = stamp
        msg.header.frame_id = self.p["map_frame"]
        msg.point.x = msg.point.y = math.nan
        if self.p["perimeter_known_wire"]:
            wire = contact.wire
            if wire.axis == "x":
                msg.point.x = wire.value
            else:
                msg.point.y = wire.value
        return msg

    # -- the replay -------------------------------------------------------------------------------

    def wait_for_listeners(self, stop: threading.Event) -> bool:
        """True once ``wait_for_subscribers`` listen to the mouse odometry (or none needed)."""
        need = self.p["wait_for_subscribers"]
        deadline = time.monotonic() + self.p["wait_timeout"]
        while self.mouse_pub.get_subscription_count() < need:
            if stop.is_set() or time.monotonic() > deadline:
                return False
            time.sleep(0.05)
        return True

    def publish_request(self, k: int, stamp: Time) -> int:
        """Everything the sensors reported at request end ``k``; the number of messages."""
        n = 0
        if k % self.p["truth_every"] == 0 or k == self.sim.t.size - 1:
            self.truth_pub.publish(self._odom(stamp, self.p["map_frame"], self.sim.truth, k))
            n += 1
        if self.mouse_published[k]:
            self.mouse_pub.publish(self._odom(stamp, self.p["odom_frame"], self.mouse, k))
            n += 1
        self.wheel_pub.publish(self._odom(stamp, self.p["wheel_odom_frame"], self.wheels, k))
        n += 1
        for kind, r in self.events.get(k, ()):
            if kind == "compass":
                self.imu_pub.publish(self._imu(stamp, r.heading))
                self.heading_pub.publish(Float64(data=float(r.heading)))
                n += 2
            elif kind == "ranges":
                for pub, value in zip(self.range_pubs, r.ranges, strict=True):
                    pub.publish(self._range(stamp, value))
                n += len(r.ranges)
            elif kind == "gps":
                self.gps_pub.publish(self._gps(stamp, r))
                n += 1
            else:
                self.contact_pub.publish(self._contact(stamp, r))
                n += 1
        return n

    def replay(self, stop: threading.Event) -> bool:
        """Publish the run in time; False if stopped early."""
        t = self.sim.t
        last = (
            t.size
            if self.p["duration"] <= 0
            else int(np.searchsorted(t, self.p["duration"], "right"))
        )
        speed = self.p["speed"]
        t0 = self.get_clock().now().nanoseconds * 1e-9
        wall0 = time.monotonic()
        worst_lag = 0.0
        sent = 0
        for k in range(last):
            if stop.is_set() or not rclpy.ok():
                return False
            ahead = wall0 + t[k] / speed - time.monotonic()
            if ahead > 0:
                time.sleep(ahead)
            else:
                worst_lag = max(worst_lag, -ahead)
            sec, nsec = seconds_to_stamp(t0 + float(t[k]))
            sent += self.publish_request(k, Time(sec=sec, nanosec=nsec))
        wall = time.monotonic() - wall0
        self.get_logger().info(
            f"replayed {t[last - 1]:.1f} s of the run ({last} requests, {sent} messages) in "
            f"{wall:.2f} s wall; worst lag behind schedule {worst_lag * 1e3:.0f} ms"
        )
        return True


def _run(node: FieldSimNode, stop) -> None:
    # the replay paces itself on this thread; another serves the node's services meanwhile
    # (its parameter services went unanswered: ``ros2 param get /field_sim`` waited forever)
    served = threading.Event()
    spinner = threading.Thread(target=ros_spin.spin_until, args=(node, served), daemon=True)
    spinner.start()
    try:
        _replay(node, stop)
    finally:
        served.set()
        spinner.join(5.0)


def _replay(node: FieldSimNode, stop) -> None:
    if not node.wait_for_listeners(stop) and not stop.is_set():
        node.get_logger().warning(
            f"fewer than {node.p['wait_for_subscribers']} subscribers after "
            f"{node.p['wait_timeout']:g} s; replaying anyway"
        )
    if not stop.is_set() and node.replay(stop):
        stop.wait(node.p["linger"])


def main(argv: list[str] | None = None) -> int:
    """Entry point of mm-field-sim; the exit status (2 for bad parameters)."""
    return ros_spin.run("mm-field-sim", FieldSimNode, _run, argv)


if __name__ == "__main__":
    sys.exit(main())
