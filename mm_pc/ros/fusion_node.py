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
from mm_pc.core.fixes.gps import LocalGrid
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
from mm_pc.core.uncertainty import (
    Q_POS,
    Q_YAW_DIST,
    Q_YAW_TURN,
    UNOBSERVED_VARIANCE,
    planar_covariance_6x6,
)
from mm_pc.ros import spin as ros_spin
from mm_pc.ros.parameters import declare_all, float_range, int_range, mark_live, read_only
from mm_pc.ros.reset import create_reset_service
from mm_pc.ros.tf import (
    TfPublisher,
    frame_ids_problem,
    frame_prefix_parameter,
    frame_prefix_problem,
    planar_transform,
    prefixed,
)
from mm_pc.ros.throttle import WarnThrottle

COMPASS_INPUTS = ("imu", "heading", "none")
GPS_SCALES = ("wgs84", "plot")


PARAMETERS = {
    "mouse_odom_topic": (
        "mm_odometry/odom",
        read_only("mouse odometry (nav_msgs/Odometry), relative to the namespace; '' = off"),
    ),
    "wheel_odom_topic": ("/wheel/odom", read_only("wheel odometry (nav_msgs/Odometry); ''=off")),
    "gps_topic": ("/gps/fix", read_only("GPS (sensor_msgs/NavSatFix); '' = off")),
    "compass_input": ("imu", read_only(f"compass input: {', '.join(COMPASS_INPUTS)}")),
    "imu_topic": ("/imu/data", read_only("compass as sensor_msgs/Imu (REP 103 yaw)")),
    "heading_topic": (
        "/compass/heading",
        read_only("compass as std_msgs/Float64: rad, 0 = north, clockwise (seed 004)"),
    ),
    "perimeter_topic": (
        "/perimeter/contact",
        read_only("wire contacts (geometry_msgs/PointStamped, unmeasured axis NaN); '' = off"),
    ),
    "beacon_topic": (
        "/beacons/{name}/range",
        read_only("sensor_msgs/Range topic per beacon, {name} = beacon name; '' = off"),
    ),
    "beacon_names": (["SW", "SE", "NE", "NW"], read_only("beacon names")),
    "beacon_x": ([0.0, 20.0, 20.0, 0.0], read_only("beacon x (m, map frame)")),
    "beacon_y": ([0.0, 0.0, 10.0, 10.0], read_only("beacon y (m, map frame)")),
    "beacon_heights": (
        [1.0, 1.0, 1.0, 1.0],
        read_only("beacon heights above the robot's range antenna (m)"),
    ),
    "range_sigma": (0.05, read_only("beacon range noise (m)", **float_range(1e-4, 100.0))),
    "map_frame": ("map", read_only("frame of the estimate (and of wire coordinates)")),
    "base_frame": ("base_link", read_only("robot frame; odometry inputs must use it as child")),
    "gps_frame": ("", read_only("required NavSatFix frame_id ('' = any)")),
    "imu_frame": ("", read_only("required Imu frame_id ('' = any)")),
    "range_frame": ("", read_only("required Range frame_id ('' = any)")),
    # map_frame and base_frame only: the required input frames above are taken as given
    "frame_prefix": frame_prefix_parameter(),
    "gps_origin_lat": (48.2, read_only("latitude of the plot's south-west corner (deg)")),
    "gps_origin_lon": (16.37, read_only("longitude of the plot's south-west corner (deg)")),
    "gps_scale": (
        "wgs84",
        read_only("metres per degree: 'wgs84' (at the origin) or 'plot' (plot size / NE corner)"),
    ),
    "gps_ne_lat": (0.0, read_only("latitude of the plot's NE corner (deg; gps_scale 'plot')")),
    "gps_ne_lon": (0.0, read_only("longitude of the plot's NE corner (deg; gps_scale 'plot')")),
    "plot_width": (
        20.0,
        read_only("plot west-east size (m); wires on its edges", **float_range(0.0, 1e4)),
    ),
    "plot_height": (
        10.0,
        read_only("plot south-north size (m); 0 x 0 = no wires", **float_range(0.0, 1e4)),
    ),
    "gps_default_sigma": (
        2.5,
        read_only(
            "GPS sigma per axis (m) when the fix gives no covariance", **float_range(0.01, 1e3)
        ),
    ),
    "gps_max_sigma": (
        3.55,
        read_only(
            "fixes with a larger sigma (m) are not used (HDOP 2 x 2.5 m / sqrt 2)",
            **float_range(0.01, 1e3),
        ),
    ),
    "gps_error_tau": (
        30.0,
        read_only(
            "correlation time of the GPS error (s): fixes are weighted as what a stream "
            "of them is worth (0 = independent fixes)",
            **float_range(0.0, 1e5),
        ),
    ),
    "compass_sigma": (
        math.radians(math.hypot(2.0, 1.0)),
        read_only("compass sigma (rad) when the message gives none", **float_range(1e-5, math.pi)),
    ),
    "compass_offset": (
        0.0,
        read_only(
            "added to every compass yaw (rad): declination, mounting", **float_range(-7.0, 7.0)
        ),
    ),
    "wire_sigma": (0.03, read_only("wire contact position sigma (m)", **float_range(1e-4, 10.0))),
    "wire_max_distance": (
        2.0,
        read_only(
            "an unnamed contact takes the nearest wire within this (m)", **float_range(0.0, 1e3)
        ),
    ),
    "initial_pose": ([2.0, -1.0, math.pi / 2], read_only("start pose x, y (m), yaw (rad) in map")),
    "initial_sigma": ([0.01, 0.01, 0.01], read_only("start sigma x, y (m), yaw (rad), each > 0")),
    "mouse_noise": (
        [Q_POS, Q_YAW_DIST, Q_YAW_TURN],
        read_only(
            "mouse increment noise q_pos (m^2/m), q_yaw_dist (rad^2/m), q_yaw_turn (rad^2/rad)"
        ),
    ),
    "wheel_noise": (
        [0.03**2, 0.03**2, 0.03**2],
        read_only("wheel increment noise, as mouse_noise"),
    ),
    "mouse_stale_timeout": (
        0.5,
        read_only(
            "mouse odometry silent this long (s, stamps) -> wheels", **float_range(0.01, 60.0)
        ),
    ),
    "max_delay": (
        1.0,
        read_only(
            "a quiet source is waited for this long (s, stamps); later fixes are dropped",
            **float_range(0.01, 3600.0),
        ),
    ),
    "max_speed": (
        5.0,
        read_only(
            "odometry faster than this (m/s) is a reset or corrupt", **float_range(0.01, 1000.0)
        ),
    ),
    "reacquire_after": (
        10,
        read_only(
            "gate rejections in a row before a source's next fix is applied ungated (0 = never)",
            **int_range(0, 10**6),
        ),
    ),
    "queue_depth": (
        200,
        read_only("subscription queue depth", **int_range(1, 10**5)),
    ),
    "publish_rate": (
        20.0,
        read_only("~/odom messages per second (Hz)", **float_range(0.1, 1000.0)),
    ),
    "path_rate": (1.0, read_only("~/path messages per second (Hz)", **float_range(0.01, 100.0))),
    "path_spacing": (
        0.05,
        read_only("a path pose every this many metres", **float_range(0.0, 100.0)),
    ),
    "path_length": (
        10000,
        read_only("poses kept in the path", **int_range(2, 10**6)),
    ),
    "diagnostics_rate": (
        1.0,
        read_only("/diagnostics messages per second (Hz)", **float_range(0.01, 100.0)),
    ),
    "publish_tf": (
        True,
        read_only(
            "broadcast map -> odom on /tf (from the estimate and the mouse odometry's pose); "
            "odom -> base_link stays mm-odometry's"
        ),
    ),
}

#: parameters that take ``ros2 param set`` while the node runs; the rest are read-only
LIVE = ("publish_rate", "path_rate", "diagnostics_rate", "map_frame", "base_frame")
mark_live(PARAMETERS, LIVE)

#: Wall seconds without any odometry message after which fixes are applied on arrival.
IDLE_AFTER_S = 0.5


def _triple(name: str, values, positive: bool = False) -> list[float]:
    v = [float(x) for x in values]
    ok = len(v) == 3 and all(math.isfinite(x) and (x > 0 if positive else True) for x in v)
    if not ok:
        need = "three finite numbers" + (" > 0" if positive else "")
        raise ValueError(f"'{name}' needs {need}, got {list(values)}")
    return v


def beacons_from(names, xs, ys, heights) -> tuple[Beacon, ...]:
    """Beacons from the four parallel parameter lists (lengths must agree)."""
    n = len(names)
    if not (len(xs) == len(ys) == len(heights) == n):
        raise ValueError(
            f"'beacon_names', 'beacon_x', 'beacon_y', 'beacon_heights' must have the same "
            f"length, got {n}, {len(xs)}, {len(ys)}, {len(heights)}"
        )
    if len(set(names)) != n or not all(names):
        raise ValueError(f"'beacon_names' must be distinct and non-empty, got {list(names)}")
    return tuple(
        Beacon(float(x), float(y), float(h), str(name))
        for name, x, y, h in zip(names, xs, ys, heights, strict=True)
    )


def grid_from(p: dict) -> LocalGrid:
    """The GPS LocalGrid from the parameters."""
    if p["gps_scale"] not in GPS_SCALES:
        raise ValueError(f"'gps_scale' must be one of {GPS_SCALES}, got '{p['gps_scale']}'")
    if p["gps_scale"] == "wgs84":
        return LocalGrid(p["gps_origin_lat"], p["gps_origin_lon"])
    return LocalGrid.from_plot(
        p["gps_origin_lat"],
        p["gps_origin_lon"],
        p["gps_ne_lat"],
        p["gps_ne_lon"],
        p["plot_width"],
        p["plot_height"],
    )


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
        x0 = _triple("initial_pose", p["initial_pose"])
        s0 = _triple("initial_sigma", p["initial_sigma"], positive=True)
        self.x0, self.s0 = x0, s0
        mouse_q = _triple("mouse_noise", p["mouse_noise"])
        self.wheel_q = _triple("wheel_noise", p["wheel_noise"])
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
            + (f", TF {self.frame('map_frame')} -> odom" if p["publish_tf"] else "")
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
