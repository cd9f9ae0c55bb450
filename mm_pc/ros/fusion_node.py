"""mm-fusion: one pose estimate from mouse odometry and absolute fixes (an EKF).

A thin ROS node around :class:`mm_pc.core.fusion.ekf.PoseEKF`, fed in stamp order by
:class:`mm_pc.core.fusion.loop.FusionCore` (message meanings and checks are in
:mod:`mm_pc.core.fusion.inputs`). Inputs (each topic a parameter, '' = not used):

  mouse_odom_topic  nav_msgs/Odometry   mm_odometry/odom    the motion model
  wheel_odom_topic  nav_msgs/Odometry   /wheel/odom         motion model only while
                    the mouse odometry has been silent for > mouse_stale_timeout
                    (0.5 s of stamp time: lifted sensors, mm-odometry stopped)
  gps_topic         sensor_msgs/NavSatFix   /gps/fix        plot metres via LocalGrid
  beacon_topic      sensor_msgs/Range   /beacons/{name}/range, one per beacon_names
  compass_input     'imu': sensor_msgs/Imu on imu_topic (/imu/data), REP 103 yaw;
                    'heading': std_msgs/Float64 on heading_topic (/compass/heading),
                    the seed's compass heading (rad, 0 = north, clockwise); 'none'
  perimeter_topic   geometry_msgs/PointStamped  /perimeter/contact  (x or y NaN)

Outputs:

  ~/odom (nav_msgs/Odometry): map -> base_link pose with the EKF's covariance
          (x, y, yaw; z, roll, pitch 1e6), body twist of the last increment;
          at publish_rate Hz (wall clock) when the estimate changed, else 1 Hz
  ~/path (nav_msgs/Path): the estimate every path_spacing m, at path_rate Hz
  /tf (publish_tf): map -> odom (the mouse odometry's frame_id) with each ~/odom, at
          its stamp: map_T_odom = map_T_base * inverse(odom_T_base), odom_T_base the
          mouse pose the estimate is at, so odom -> base_link stays mm-odometry's and
          both chains coexist (REP 105); not sent while the wheels are the motion model
  ~/reset (std_srvs/Trigger): the estimate back to initial_pose / initial_sigma,
          the path cleared (the counts on /diagnostics go on)
  /diagnostics: per source accepted / rejected (gate) / invalid / unusable /
          stale / reacquired counts and the last reason; the estimate
          and the motion model in use

Every input is checked; a message that cannot be used is counted, logged with
a WARN at most once per 5 s per source and kind, and changes nothing. Inputs
are read with best-effort QoS, so sensor drivers publishing with either
reliability are heard. The plot defaults are the field simulator's
(mm-field-sim): set yours in the parameter file. The ``LIVE`` parameters take
``ros2 param set`` (checked; a refused value keeps the old one).
"""

from __future__ import annotations

import math
import sys
import time

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PointStamped, PoseStamped
from nav_msgs.msg import Odometry as OdometryMsg
from nav_msgs.msg import Path
from rcl_interfaces.msg import SetParametersResult
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import Imu, NavSatFix, Range
from std_msgs.msg import Float64

from mm_pc.core.angles import yaw_to_quaternion
from mm_pc.core.fixes.perimeter import rectangle_perimeter
from mm_pc.core.fusion.ekf import PoseEKF
from mm_pc.core.fusion.inputs import (
    InputError,
    PositionInput,
    gps_inflation,
    heading_input,
    imu_input,
    inflate_for_correlation,
    navsat_input,
    odometry_input,
    perimeter_input,
    range_input,
    seconds_to_stamp,
)
from mm_pc.core.fusion.loop import FusionCore, increment_noise
from mm_pc.core.maps.trilateration import Beacon
from mm_pc.core.odometry import Pose2D, compose, inverse
from mm_pc.core.throttle import WarnThrottle
from mm_pc.core.uncertainty import (
    UNOBSERVED_VARIANCE,
    planar_covariance_6x6,
)
from mm_pc.ros import spin as ros_spin
from mm_pc.ros.fusion_params import (
    COMPASS_INPUTS,
    PARAMETERS,
    beacons_from,
    grid_from,
    triple,
)
from mm_pc.ros.parameters import declare_all
from mm_pc.ros.reset import create_reset_service
from mm_pc.ros.tf import (
    TfPublisher,
    frame_ids_problem,
    frame_prefix_problem,
    planar_transform,
    prefixed,
)

#: Wall seconds without any odometry message after which fixes are applied on arrival.
IDLE_AFTER_S = 0.5


class FusionNode(Node):
    def __init__(self, **kwargs) -> None:
        super().__init__("mm_fusion", **kwargs)
        p = declare_all(self, PARAMETERS)
        self.p = p
        if p["compass_input"] not in COMPASS_INPUTS:
            raise ValueError(
                f"'compass_input' must be one of {COMPASS_INPUTS}, got '{p['compass_input']}'"
            )
        self.grid = grid_from(p)
        self.beacons = (
            beacons_from(p["beacon_names"], p["beacon_x"], p["beacon_y"], p["beacon_heights"])
            if p["beacon_topic"]
            else ()
        )
        if problem := frame_ids_problem(p, ("map_frame", "base_frame")) or frame_prefix_problem(
            p["frame_prefix"]
        ):
            raise ValueError(problem)
        x0 = triple("initial_pose", p["initial_pose"])
        s0 = triple("initial_sigma", p["initial_sigma"], positive=True)
        self.x0, self.s0 = x0, s0
        mouse_q = triple("mouse_noise", p["mouse_noise"])
        self.wheel_q = triple("wheel_noise", p["wheel_noise"])
        if min(mouse_q + self.wheel_q) < 0:
            raise ValueError("'mouse_noise' and 'wheel_noise' must be >= 0")
        self.mouse_q = mouse_q
        w, h = p["plot_width"], p["plot_height"]
        self.wires = rectangle_perimeter(w, h) if w > 0 and h > 0 else ()
        self.core = self._new_core()
        self.throttle = WarnThrottle(5.0)
        self._subscribe()
        self.odom_pub = self.create_publisher(OdometryMsg, "~/odom", 10)
        self.path_pub = self.create_publisher(Path, "~/path", 1)
        self.diag_pub = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self.tf = TfPublisher(self, p["publish_tf"])
        self.path = Path()
        self.path.header.frame_id = self.frame("map_frame")
        self._published_stamp: float | None = None
        self._published_wall = 0.0
        self._last_motion_wall = time.monotonic()
        self._diag_prev: dict[str, dict[str, int]] = {}
        self.hardware_id = self.get_fully_qualified_name()
        self._steady = Clock(clock_type=ClockType.STEADY_TIME)
        self._rate_timers = {
            name: self.create_timer(1.0 / p[name], callback, clock=self._steady)
            for name, callback in self._timed().items()
        }
        self.create_timer(0.1, self.check_idle, clock=self._steady)
        self.add_on_set_parameters_callback(self._on_set_parameters)
        create_reset_service(self, self.reset)
        self.get_logger().info(
            f"fusing {', '.join(self.inputs) or 'nothing'}; start pose {x0}; publishing "
            f"{self.get_fully_qualified_name()}/odom and /path in frame {self.frame('map_frame')}"
            + (
                f", TF {self.frame('map_frame')} -> the mouse odometry's frame"
                f" (its header.frame_id, e.g. {prefixed(p['frame_prefix'], 'odom')})"
                if p["publish_tf"]
                else ""
            )
        )

    def frame(self, name: str) -> str:
        """The frame id published (and required of odometry inputs) for the frame parameter
        ``name`` (map_frame, base_frame), after ``frame_prefix``."""
        return prefixed(self.p["frame_prefix"], self.p[name])

    def _timed(self) -> dict:
        """rate parameter -> the callback its steady-clock timer runs."""
        return {
            "publish_rate": self.publish_odometry,
            "path_rate": self.publish_path,
            "diagnostics_rate": self.publish_diagnostics,
        }

    def _new_core(self, counts=None) -> FusionCore:
        """A fresh filter at initial_pose / initial_sigma (``counts`` carried over)."""
        p = self.p
        ekf = PoseEKF(Pose2D(*self.x0), np.diag(np.square(self.s0)), *self.mouse_q)
        core = FusionCore(
            ekf,
            wheel_noise=self.wheel_q,
            stale_s=p["mouse_stale_timeout"],
            max_delay_s=p["max_delay"],
            reacquire_after=p["reacquire_after"],
            wires=self.wires,
            wire_var=p["wire_sigma"] ** 2,
            wire_max_distance=p["wire_max_distance"],
            max_speed=p["max_speed"],
        )
        if counts is not None:
            core.counts = counts
        return core

    def reset(self) -> str:
        """~/reset: the estimate back to the start, the path cleared; counts go on."""
        self.core = self._new_core(self.core.counts)
        self.path.poses.clear()
        self._published_stamp, self._published_wall = None, 0.0  # the start pose out at once
        return (
            f"estimate back to {self.x0} in {self.p['map_frame']} with sigma {self.s0}, "
            "path cleared; the next mouse odometry starts a new baseline"
        )

    def _on_set_parameters(self, params) -> SetParametersResult:
        """Apply ``ros2 param set`` on a LIVE parameter, or refuse it and keep the old value.

        rclpy has already checked the read-only flags and the ranges.
        """
        changes = {p.name: p.value for p in params}
        if problem := frame_ids_problem(changes, ("map_frame", "base_frame")):
            self.get_logger().warning(f"parameters not changed: {problem}")
            return SetParametersResult(successful=False, reason=problem)
        self.p.update(changes)
        for name, callback in self._timed().items():
            if name in changes:
                self.destroy_timer(self._rate_timers[name])
                self._rate_timers[name] = self.create_timer(
                    1.0 / changes[name], callback, clock=self._steady
                )
        if "map_frame" in changes:
            self.path.header.frame_id = self.frame("map_frame")
        for name, value in changes.items():
            self.get_logger().info(f"parameter {name} set to {value}")
        return SetParametersResult(successful=True)

    # -- inputs -----------------------------------------------------------------------------

    def _subscribe(self) -> None:
        p = self.p
        qos = QoSProfile(
            history=HistoryPolicy.KEEP_LAST,
            depth=p["queue_depth"],
            reliability=ReliabilityPolicy.BEST_EFFORT,
        )
        # read at each message: base_frame and map_frame are live
        gps_kw = {
            "default_sigma": p["gps_default_sigma"],
            "max_sigma": p["gps_max_sigma"],
            "frame": p["gps_frame"],
        }
        compass_var = p["compass_sigma"] ** 2
        offset = p["compass_offset"]
        subs = []
        if p["mouse_odom_topic"]:
            subs.append(
                (
                    OdometryMsg,
                    p["mouse_odom_topic"],
                    "mouse",
                    lambda m: odometry_input(m, "mouse", self.frame("base_frame")),
                )
            )
        if p["wheel_odom_topic"]:
            subs.append(
                (
                    OdometryMsg,
                    p["wheel_odom_topic"],
                    "wheel",
                    lambda m: odometry_input(m, "wheel", self.frame("base_frame")),
                )
            )
        if p["gps_topic"]:
            subs.append(
                (
                    NavSatFix,
                    p["gps_topic"],
                    "gps",
                    lambda m: self._gps(navsat_input(m, self.grid, **gps_kw)),
                )
            )
        if p["compass_input"] == "imu":
            subs.append(
                (
                    Imu,
                    p["imu_topic"],
                    "compass",
                    lambda m: imu_input(
                        m, default_var=compass_var, offset=offset, frame=p["imu_frame"]
                    ),
                )
            )
        elif p["compass_input"] == "heading":
            subs.append(
                (
                    Float64,
                    p["heading_topic"],
                    "compass",
                    lambda m: heading_input(m.data, var=compass_var, offset=offset),
                )
            )
        if p["perimeter_topic"]:
            subs.append(
                (
                    PointStamped,
                    p["perimeter_topic"],
                    "perimeter",
                    lambda m: perimeter_input(m, self.frame("map_frame")),
                )
            )
        for b in self.beacons:
            subs.append(
                (
                    Range,
                    p["beacon_topic"].format(name=b.name),
                    f"beacon/{b.name}",
                    self._range_converter(b),
                )
            )
        self.inputs = [f"{src} ({topic})" for _, topic, src, _ in subs]
        for msg_type, topic, source, convert in subs:
            self.create_subscription(msg_type, topic, self._callback(source, convert), qos)

    def _gps(self, fix: PositionInput) -> PositionInput:
        """Inflate a fix's covariance for the GPS error's correlation over gps_error_tau.

        A filter takes each fix as independent news; fixes every 0.5 s of an
        error that wanders over 30 s are not, and without this the filter
        believes it averaged the error away. Gated with the fix's own covariance
        (as :func:`mm_pc.sim.field_run.run_fusion` does).
        """
        tau = self.p["gps_error_tau"]
        interval = self.core.interval(fix.source)
        if tau <= 0 or not interval:
            return fix
        return inflate_for_correlation(fix, gps_inflation(interval, tau))

    def _range_converter(self, beacon: Beacon):
        p = self.p
        source = f"beacon/{beacon.name}"
        return lambda m: range_input(
            m, beacon, sigma=p["range_sigma"], frame=p["range_frame"], source=source
        )

    def _callback(self, source: str, convert):
        def on_message(msg) -> None:
            try:
                record = convert(msg)
            except InputError as exc:
                self.core.count(source, exc.kind, str(exc))
                self.core.heard(source, exc.stamp)  # the sensor ticked, without a reading
                self._warn(f"{source} {exc.kind}", f"{source}: ignored ({exc.kind}): {exc}")
                return
            except Exception as exc:  # a malformed message must never stop the node
                self.core.count(source, "invalid", f"{type(exc).__name__}: {exc}")
                self._warn(f"{source} invalid", f"{source}: ignored (invalid): {exc!r}")
                return
            if source in ("mouse", "wheel"):
                self._last_motion_wall = time.monotonic()
            try:
                self.core.push(record)
            except Exception as exc:  # a bug here must not stop the node either; it says so
                self.core.count(source, "invalid", f"{type(exc).__name__}: {exc}")
                self._warn(f"{source} error", f"{source}: not processed: {exc!r}", error=True)
            self._log_notices()

        return on_message

    def _warn(self, key: str, text: str, error: bool = False) -> None:
        held = self.throttle(key)
        if held is None:
            return
        more = f" ({held} more since the last such message)" if held else ""
        log = self.get_logger()
        (log.error if error else log.warning)(text + more)

    def _log_notices(self) -> None:
        notices, self.core.notices = self.core.notices, []
        for key, text in notices:
            if key == "motion":
                self.get_logger().info(text)
            else:
                self._warn(key, text)

    def check_idle(self) -> None:
        """No odometry for IDLE_AFTER_S wall seconds: stop waiting for it, fuse on arrival."""
        if time.monotonic() - self._last_motion_wall > IDLE_AFTER_S and not self.core.idle:
            self.core.flush()
            self._log_notices()

    # -- outputs ----------------------------------------------------------------------------

    def _stamp(self):
        t = self.core.stamp
        if t is None:
            return self.get_clock().now().to_msg()
        stamp = self.get_clock().now().to_msg()
        stamp.sec, stamp.nanosec = seconds_to_stamp(t)
        return stamp

    def odometry_message(self) -> OdometryMsg:
        """The estimate as nav_msgs/Odometry (map -> base_link)."""
        ekf = self.core.ekf
        pose = ekf.pose
        msg = OdometryMsg()
        msg.header.stamp = self._stamp()
        msg.header.frame_id = self.frame("map_frame")
        msg.child_frame_id = self.frame("base_frame")
        msg.pose.pose.position.x, msg.pose.pose.position.y = pose.x, pose.y
        o = msg.pose.pose.orientation
        o.x, o.y, o.z, o.w = yaw_to_quaternion(pose.yaw_wrapped)
        msg.pose.covariance = planar_covariance_6x6(ekf.covariance)
        inc = self.core.last_increment
        if inc is not None and inc[3] > 0:
            fwd, left, turn, dt = inc
            msg.twist.twist.linear.x, msg.twist.twist.linear.y = fwd / dt, left / dt
            msg.twist.twist.angular.z = turn / dt
            q = self.wheel_q if self.core.motion_source == "wheel" else self.mouse_q
            m = increment_noise(fwd, left, turn, *q) / (dt * dt)
            msg.twist.covariance = planar_covariance_6x6(m)
        else:  # no increment yet: the twist is unknown
            msg.twist.covariance = planar_covariance_6x6(np.eye(3) * UNOBSERVED_VARIANCE)
        return msg

    def publish_odometry(self) -> None:
        """Publish the fused estimate (nav_msgs/Odometry) when it moved on, else once a second."""
        now = time.monotonic()
        stamp = self.core.stamp
        if stamp == self._published_stamp and now - self._published_wall < 1.0:
            return
        msg = self.odometry_message()
        self.odom_pub.publish(msg)
        self._send_map_to_odom(msg)
        self._published_stamp, self._published_wall = stamp, now
        if stamp is not None:
            self._add_path_pose(msg)

    def _send_map_to_odom(self, msg: OdometryMsg) -> None:
        """map -> odom at ``msg``'s stamp: the estimate times inverse(the mouse odom pose)."""
        mouse = self.core.mouse_pose
        if mouse is None or not self.tf.enabled:
            return
        map_odom = compose(self.core.ekf.pose, inverse(mouse.pose))
        self.tf.send(
            planar_transform(
                msg.header.stamp, msg.header.frame_id, mouse.frame_id, map_odom.x, map_odom.y,
                map_odom.yaw,
            )
        )  # fmt: skip

    def _add_path_pose(self, msg: OdometryMsg) -> None:
        poses = self.path.poses
        pos = msg.pose.pose.position
        if poses:
            last = poses[-1].pose.position
            if math.hypot(pos.x - last.x, pos.y - last.y) < self.p["path_spacing"]:
                return
        ps = PoseStamped()
        ps.header = msg.header
        ps.pose = msg.pose.pose
        poses.append(ps)
        del poses[: -self.p["path_length"]]

    def publish_path(self) -> None:
        """Publish the fused path (timer callback)."""
        if self.path.poses:
            self.path.header.stamp = self.path.poses[-1].header.stamp
            self.path_pub.publish(self.path)

    def publish_diagnostics(self) -> None:
        """Publish the per-source counts and the estimate on /diagnostics (timer callback)."""
        arr = DiagnosticArray()
        arr.header.stamp = self.get_clock().now().to_msg()
        arr.status.append(self._estimate_status())
        for source, counts in sorted(self.core.counts.items()):
            now = counts.as_dict()
            prev = self._diag_prev.get(source, dict.fromkeys(now, 0))
            new = {k: now[k] - prev[k] for k in now}
            st = DiagnosticStatus(
                name=f"{self.hardware_id}: {source}", hardware_id=self.hardware_id
            )
            if sum(new.values()) and not new["accepted"]:
                st.level, st.message = DiagnosticStatus.WARN, f"nothing used: {counts.last_reason}"
            else:
                st.level, st.message = DiagnosticStatus.OK, f"{now['accepted']} used"
            st.values = [KeyValue(key=k, value=str(v)) for k, v in now.items()]
            st.values.append(KeyValue(key="last_reason", value=counts.last_reason))
            arr.status.append(st)
            self._diag_prev[source] = now
        self.diag_pub.publish(arr)

    def _estimate_status(self) -> DiagnosticStatus:
        ekf = self.core.ekf
        pose, cov = ekf.pose, ekf.covariance
        st = DiagnosticStatus(name=f"{self.hardware_id}: estimate", hardware_id=self.hardware_id)
        st.level = DiagnosticStatus.OK
        st.message = f"motion model: {self.core.motion_source or 'none yet'}"
        values = {
            "x": f"{pose.x:.4f}",
            "y": f"{pose.y:.4f}",
            "yaw": f"{pose.yaw_wrapped:.5f}",
            "sigma_x": f"{math.sqrt(cov[0, 0]):.4f}",
            "sigma_y": f"{math.sqrt(cov[1, 1]):.4f}",
            "sigma_yaw": f"{math.sqrt(cov[2, 2]):.5f}",
            "motion_source": self.core.motion_source or "",
            "pending": str(self.core.pending),
            "stamp": "" if self.core.stamp is None else f"{self.core.stamp:.3f}",
        }
        st.values = [KeyValue(key=k, value=v) for k, v in values.items()]
        return st

    def summary(self) -> str:
        """One line: per source, the counts that are not zero."""
        parts = []
        for source, c in sorted(self.core.counts.items()):
            nz = ", ".join(f"{k} {v}" for k, v in c.as_dict().items() if v)
            parts.append(f"{source}: {nz}")
        pose = self.core.ekf.pose
        return f"estimate ({pose.x:.3f}, {pose.y:.3f}, {pose.yaw_wrapped:.4f}); " + (
            "; ".join(parts) or "no input"
        )


def spin_fast(node: Node, stop) -> None:
    """:func:`mm_pc.ros.spin.spin_until` with rclpy's EventsExecutor where there is one.

    The default executor rebuilds its wait set (with every subscription's QoS
    event handlers) for each message: measured here at about 0.4 ms per
    message, which caps a 9-input node at a few thousand messages per second.
    The EventsExecutor must only be used from this (the main) thread.
    """
    try:
        from rclpy.experimental import EventsExecutor

        executor = EventsExecutor()
    except ImportError:
        executor = None
    ros_spin.spin_until(node, stop, executor)


def _run(node: FusionNode, stop) -> None:
    spin_fast(node, stop)
    node.get_logger().info(node.summary())


def main(argv: list[str] | None = None) -> int:
    """Entry point of mm-fusion; the exit status (2 for bad parameters)."""
    return ros_spin.run("mm-fusion", FusionNode, _run, argv)


if __name__ == "__main__":
    sys.exit(main())
