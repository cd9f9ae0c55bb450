"""mm-odometry: mouse odometry out as nav_msgs/Odometry and nav_msgs/Path.

A thin ROS node. At ``rate`` Hz it asks mm_beagle for the data of every
sensor (one request, asynchronous: the executor never waits), then (``per_poll``,
default) each sensor's single polls since its previous request (``get_samples``),
and integrates the pose poll by poll (:class:`mm_pc.core.polls.PollTracker`), so
``rate`` changes only how often the pose is published, never the pose. Polls that
are missing (ring overrun, a failed fetch) become one step from the monotone totals
for that interval, counted and reported on /diagnostics. With ``per_poll`` false it
integrates the totals' displacement per request. Either way it takes no counts away
from other clients, applies the calibration, runs the pose math of
:mod:`mm_pc.core.odometry` and publishes

  ~/odom (nav_msgs/Odometry): odom -> base_link pose and body twist (over the
          request's interval), with the covariance of :mod:`mm_pc.core.uncertainty`
          (plus the lift-fill variance of the filled counts the pose used,
          :mod:`mm_pc.core.fill_variance`)
  ~/path (nav_msgs/Path):    the poses so far (at most ``path_length``), at
          ``path_rate`` Hz
  /diagnostics:              "/NS/mm_odometry: pose" once a second: polls integrated,
          gap steps and the last reason (WARN after a new gap), requests sent/answered,
          the stamp of the last integrated poll; WARN "no reply from /NS/mm_beagle for N s"
          while replies are missing, ERROR past ``no_reply_error``
  /tf (publish_tf):          odom -> base_link, the same pose and stamp as ~/odom
  /tf_static (publish_tf):   base_link -> each sensor frame (``sensor_frames``) at its
          mount (the calibrated one where a calibration is loaded), and each sensor
          frame -> its ``_counts`` frame (yaw -pi/2: SensorData's axes and frame_id)
  ~/reset (std_srvs/Trigger): pose and covariance back to the start, path cleared

Frame ids, rates, method and geometry are parameters; ``LIVE`` ones take
``ros2 param set`` (checked: a refused value keeps the old one). ``beagle`` is
relative to the node's namespace (``-r __ns:=/robot1`` asks /robot1/mm_beagle).
A request without a reply after ``reply_timeout`` is given up and asked again at the
next tick (:class:`mm_pc.ros.deadline_client.DeadlineClient`): a lost get_sensor_data
reply costs one interval, never the stream; a lost get_samples reply is asked again
from the same poll with the next reply's totals (the polls are still in mm-beagle's
ring), so only polls that really left the ring (or :data:`POLL_RETRIES` losses in a
row) are stepped with the totals.
Header stamps follow the node clock (:func:`mm_pc.ros.clock.node_stamp`).
"""

from __future__ import annotations

import sys

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Odometry as OdometryMsg
from nav_msgs.msg import Path
from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node

from mm_interfaces.srv import GetSamples, GetSensorData
from mm_pc.core.calibration import Calibration
from mm_pc.core.fill_variance import FillVariance
from mm_pc.core.geometry import DEFAULT_MOUNTS, SensorMount
from mm_pc.core.odometry import METHODS, Odometry, Pose2D, Sample
from mm_pc.core.polls import PollBatch, PollTracker, SensorTotals, integrate_steps
from mm_pc.core.uncertainty import PoseUncertainty, calibration_se
from mm_pc.ros import spin as ros_spin
from mm_pc.ros.clock import ClockWatch, node_stamp
from mm_pc.ros.deadline_client import DeadlineClient
from mm_pc.ros.odometry_msgs import odometry_message
from mm_pc.ros.parameters import declare_all, float_range, int_range, mark_live, read_only
from mm_pc.ros.reset import create_reset_service
from mm_pc.ros.tf import (
    TfPublisher,
    frame_ids_problem,
    frame_prefix_parameter,
    frame_prefix_problem,
    mount_transforms,
    planar_transform,
    prefixed,
    sensor_frame_names,
)
from pln2033 import INCH_M

PARAMETERS = {
    "beagle": (
        "mm_beagle",
        read_only(
            "the mm_beagle node to ask: relative to this node's namespace, or absolute (/...)"
        ),
    ),
    "rate": (
        15.0,
        read_only(
            "requests per second (Hz)",
            **float_range(1.0, 500.0),
        ),
    ),
    "method": ("exact", read_only(f"pose method: {', '.join(sorted(METHODS))}")),
    "sensor": (
        0,
        read_only(
            "which sensor the one-sensor methods use (index into devices)",
            **int_range(0, 15, 1),
        ),
    ),
    "devices": (["/dev/spidev1.0", "/dev/spidev1.1"], read_only("sensor ids, in mount order")),
    "mounts": (
        [m for mount in DEFAULT_MOUNTS for m in (mount.x, mount.y, mount.yaw)],
        read_only("x, y, yaw (base_link m, rad) of each sensor, flattened"),
    ),
    "calibration_file": ("", read_only("YAML calibration to apply ('' = none)")),
    "use_lift_estimates": (True, read_only("add the node's estimates of counts lost to lifts")),
    "per_poll": (True, read_only("integrate every single poll (get_samples); false = per request")),
    "odom_frame": ("odom", read_only("frame_id of the odometry (and parent of the TF)")),
    "base_frame": ("base_link", read_only("child_frame_id of the odometry (and of the TF)")),
    "publish_tf": (
        True,
        read_only(
            "broadcast odom -> base_link on /tf and the sensor mounts on /tf_static; this node "
            "normally owns odom -> base_link (keep mm-beagle's publish_tf false)"
        ),
    ),
    "sensor_frames": (
        [""],
        read_only("TF frame of each sensor, in device order ('' = mouse_ + the device name)"),
    ),
    "frame_prefix": frame_prefix_parameter(),
    "path_length": (
        10000,
        read_only("poses kept in the path", **int_range(2, 10**6)),
    ),
    "path_rate": (
        1.0,
        read_only(
            "path messages per second (Hz)",
            **float_range(0.1, 100.0),
        ),
    ),
    "reply_timeout": (
        1.0,
        read_only(
            "a request to mm_beagle unanswered this long (s) is given up and asked again",
            **float_range(0.05, 60.0),
        ),
    ),
    "no_reply_error": (
        5.0,
        read_only(
            "/diagnostics says ERROR after this long (s) without a reply (WARN before)",
            **float_range(0.1, 3600.0),
        ),
    ),
}

#: get_samples replies given up in a row for one interval before it is stepped with the
#: totals (each retry asks from the same poll; the ring holds ~65 s of polls)
POLL_RETRIES = 5

#: parameters that take ``ros2 param set`` while the node runs; the rest are read-only
LIVE = (
    "rate",
    "path_rate",
    "method",
    "odom_frame",
    "base_frame",
    "reply_timeout",
    "no_reply_error",
)
mark_live(PARAMETERS, LIVE)


class OdometryNode(Node):
    def __init__(self, **kwargs) -> None:
        super().__init__("mm_odometry", **kwargs)
        p = declare_all(self, PARAMETERS)
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
        self.mounts = mounts
        self.odometry = Odometry(mounts, method=p["method"], sensor=p["sensor"])
        # the calibration's own standard errors: its term of the covariance (0 without;
        # the largest over the sensors, so a live method change keeps it honest)
        self.uncertainty = PoseUncertainty(**calibration_se(self.calibration, devices))
        if problem := frame_ids_problem(p, ("odom_frame", "base_frame")) or frame_prefix_problem(
            p["frame_prefix"]
        ):
            raise ValueError(problem)
        self.sensor_frames = sensor_frame_names(devices, p["sensor_frames"], p["frame_prefix"])
        self.client = DeadlineClient(
            self.create_client(GetSensorData, f"{p['beagle']}/get_sensor_data"),
            p["reply_timeout"],
        )
        self.samples_client = DeadlineClient(
            self.create_client(GetSamples, f"{p['beagle']}/get_samples"), p["reply_timeout"]
        )
        #: the mm_beagle node asked, fully qualified (``beagle`` resolved in this namespace)
        self.beagle = self.resolve_service_name(p["beagle"])
        self.tracker = PollTracker(len(devices), p["use_lift_estimates"])
        # the lift-fill variance of the filled counts the pose used (per_poll)
        self.fill_variance = FillVariance(len(devices))
        self._fetch: dict | None = None  # the reply waiting for its polls
        self._poll_retries = 0  # get_samples replies lost in a row for the current interval
        self._reported_polls_lost = 0
        self._reported_gaps = 0
        self._reported_abandoned = 0
        self._last_stamp = None  # header stamp of the last integrated poll
        self.diag_pub = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self.create_timer(1.0, self.publish_diagnostics)
        self.odom_pub = self.create_publisher(OdometryMsg, "~/odom", 10)
        self.path_pub = self.create_publisher(Path, "~/path", 1)
        self.path = Path()
        self.path.header.frame_id = self.frame("odom_frame")
        self._last: dict[str, tuple[float, float, int]] = {}  # id -> totals, stamp
        self.samples_used = 0
        self.tf = TfPublisher(self, p["publish_tf"])
        self.send_static_frames()
        self._request_timer = self.create_timer(1.0 / p["rate"], self.request)
        self._path_timer = self.create_timer(1.0 / p["path_rate"], self.publish_path)
        self.add_on_set_parameters_callback(self._on_set_parameters)
        create_reset_service(self, self.reset)
        self.clock_watch = ClockWatch(self)
        self.get_logger().info(
            f"odometry ({p['method']}) from {self.beagle} at {p['rate']:g} Hz; "
            f"publishing {self.get_fully_qualified_name()}/odom and /path"
            + (
                f", TF {self.frame('odom_frame')} -> {self.frame('base_frame')}"
                if p["publish_tf"]
                else ""
            )
        )

    def frame(self, name: str) -> str:
        """The frame id published for the frame parameter ``name`` (after ``frame_prefix``)."""
        return prefixed(self.p["frame_prefix"], self.p[name])

    def send_static_frames(self) -> None:
        """base_link -> each sensor frame at its mount (and its ``_counts`` child), latched
        on /tf_static."""
        self.tf.send_static(
            mount_transforms(
                self.get_clock().now().to_msg(), self.frame("base_frame"), self.sensor_frames,
                self.mounts,
            )
        )  # fmt: skip

    def reset(self) -> str:
        """~/reset: pose back to the origin, covariance to zero, the path cleared."""
        self.odometry.reset()
        self.uncertainty.reset()
        self.fill_variance.total_var_m2 = 0.0
        self.path.poses.clear()
        return (
            f"pose back to (0, 0, 0) in {self.frame('odom_frame')}, covariance cleared, path "
            "cleared (polls not yet integrated, at most one request interval, count after it)"
        )

    def _on_set_parameters(self, params) -> SetParametersResult:
        """Apply ``ros2 param set`` on a LIVE parameter, or refuse it and keep the old value.

        rclpy has already checked the read-only flags and the ranges.
        """
        changes = {p.name: p.value for p in params}
        problem = frame_ids_problem(changes, ("odom_frame", "base_frame"))
        if "method" in changes and changes["method"] not in METHODS:
            problem = f"unknown method '{changes['method']}'; known: {', '.join(sorted(METHODS))}"
        if problem:
            self.get_logger().warning(f"parameters not changed: {problem}")
            return SetParametersResult(successful=False, reason=problem)
        if "method" in changes:  # the new method goes on from the current pose
            self.odometry = Odometry(
                self.mounts, method=changes["method"], sensor=self.p["sensor"],
                pose=self.odometry.pose,
            )  # fmt: skip
        if "rate" in changes:
            self.destroy_timer(self._request_timer)
            self._request_timer = self.create_timer(1.0 / changes["rate"], self.request)
        if "path_rate" in changes:
            self.destroy_timer(self._path_timer)
            self._path_timer = self.create_timer(1.0 / changes["path_rate"], self.publish_path)
        if "reply_timeout" in changes:
            self.client.timeout_s = self.samples_client.timeout_s = changes["reply_timeout"]
        self.p.update(changes)
        if "odom_frame" in changes:
            self.path.header.frame_id = self.frame("odom_frame")
        if "base_frame" in changes:
            self.send_static_frames()
        for name, value in changes.items():
            self.get_logger().info(f"parameter {name} set to {value}")
        return SetParametersResult(successful=True)

    def request(self) -> None:
        """Ask mm-beagle for new sensor data (timer callback); one call in flight at a time.

        Calls past ``reply_timeout`` are given up first: a lost get_sensor_data reply is
        asked again now, polls that did not come are asked again from the same poll with
        this request's totals (:meth:`_on_polls`).
        """
        if self.client.expire():
            self.get_logger().warning(
                f"no reply from {self.beagle}/get_sensor_data within "
                f"{self.client.timeout_s:g} s: asking again",
                throttle_duration_sec=5.0,
            )
        self.samples_client.expire()
        if self.client.busy or self._fetch is not None:
            return  # a slow reply is never doubled up: the totals cover any gap
        self.client.call(GetSensorData.Request(id=""), self.on_reply)

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

    def on_reply(self, res) -> None:
        """Turn a get_sensor_data reply into a pose step and publish it (None: given up)."""
        if res is None or not res.success:
            return
        by_id = {d.id: d for d in res.data}
        if any(dev not in by_id for dev in self.devices):
            return  # a sensor is down; its totals still cover the gap next time
        if self.p["per_poll"]:
            self._start_fetch(by_id)
            return
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

    # -- per poll ---------------------------------------------------------------------------

    def _start_fetch(self, by_id: dict) -> None:
        """Ask every sensor's polls since the previous reply up to this reply's totals."""
        data = [by_id[dev] for dev in self.devices]
        totals = [SensorTotals.from_msg(d) for d in data]
        t = self.tracker
        restart = t.restart_in(totals)
        if not t.started or restart:
            if t.started:
                self.get_logger().warning(f"mm-beagle restarted ({restart}): new baseline")
            t.baseline(totals)
            self.fill_variance.reset()
            return
        fetch = {"data": data, "totals": totals, "polls": [None] * len(self.devices),
                 "waiting": 0, "retries": self._poll_retries}  # fmt: skip
        self._fetch = fetch
        for i, (dev, x) in enumerate(zip(self.devices, totals, strict=True)):
            want = x.seq - t.cursor(i)
            if want == 0:
                continue
            req = GetSamples.Request(id=dev, since_seq=t.cursor(i), max_samples=want)
            fetch["waiting"] += 1
            if not self.samples_client.call(
                req, lambda res, i=i, fetch=fetch: self._on_polls(fetch, i, res)
            ):
                fetch["waiting"] -= 1  # not offered: a gap, stepped with the totals
        if fetch["waiting"] == 0:
            self._finish_fetch()

    def _on_polls(self, fetch: dict, i: int, res) -> None:
        """One sensor's get_samples reply (None: given up).

        A reply given up drops the whole fetch: the next request asks every sensor again
        from the same poll (the tracker's cursors did not move) up to its newer totals,
        so the polls still in the ring are integrated one by one and nothing is stepped
        with the totals; only after :data:`POLL_RETRIES` losses in a row does the
        interval become a gap step."""
        if fetch is not self._fetch:
            return  # given up on
        if res is None and fetch["retries"] < POLL_RETRIES:
            self._fetch = None
            self._poll_retries = fetch["retries"] + 1
            self.get_logger().warning(
                f"no get_samples reply for {self.devices[i]} within "
                f"{self.samples_client.timeout_s:g} s: asking again from seq "
                f"{self.tracker.cursor(i)}",
                throttle_duration_sec=5.0,
            )
            return
        if res is not None and res.success:
            try:
                fetch["polls"][i] = PollBatch.from_reply(res)
            except ValueError as e:
                self.get_logger().warning(f"{self.devices[i]}: bad get_samples reply: {e}")
        fetch["waiting"] -= 1
        if fetch["waiting"] == 0:
            self._finish_fetch()

    def _finish_fetch(self) -> None:
        fetch, self._fetch = self._fetch, None
        self._poll_retries = 0
        steps = self.tracker.step(fetch["totals"], fetch["polls"])
        for why in self.tracker.gap_reasons[len(self.tracker.gap_reasons) - int(steps.gap.sum()) :]:
            self.get_logger().warning(f"gap in the single polls: {why}; stepped with the totals")
        if not len(steps):
            return
        d = steps.d.copy()
        for k, dev in enumerate(self.devices):
            d[:, k, 0], d[:, k, 1] = self.calibration.apply(dev, d[:, k, 0], d[:, k, 1])
        before = self.odometry.pose
        unit_m = [INCH_M / max(int(x.cpi), 1) for x in fetch["data"]]
        fill = self.fill_variance.of_steps(steps, self.odometry.body_map, unit_m)
        if fill.any():  # the filled counts' uncertainty, before this interval's motion
            self.uncertainty.add(0.0, 0.0, heading=before.yaw, fill_var_m2=fill)
        integrate_steps(self.odometry, steps, d)
        after = self.odometry.pose
        self.samples_used += len(steps)
        data = fetch["data"][self.p["sensor"]]
        stamp = int(steps.stamp_ns[-1])
        data_stamp = type(data.stamp)(sec=stamp // 1_000_000_000, nanosec=stamp % 1_000_000_000)
        self.publish_odometry(before, after, float(steps.dt.sum()), data, data_stamp)

    def publish_diagnostics(self) -> None:
        """/diagnostics: replies missing (WARN, ERROR past ``no_reply_error``), requests given
        up since the last round (WARN), polls integrated and the gaps in them (WARN after a
        new gap), the stamp of the last integrated poll."""
        t, c = self.tracker, self.client
        new = t.gaps - self._reported_gaps
        self._reported_gaps = t.gaps
        lost = c.abandoned - self._reported_abandoned
        self._reported_abandoned = c.abandoned
        polls_lost = self.samples_client.abandoned - self._reported_polls_lost
        self._reported_polls_lost = self.samples_client.abandoned
        silent, longest = c.silent_s(), c.take_silence()  # now; the longest this round
        level, problems = DiagnosticStatus.OK, []
        if longest > c.timeout_s:
            too_long = silent > self.p["no_reply_error"]
            level = DiagnosticStatus.ERROR if too_long else DiagnosticStatus.WARN
            offered = "" if c.ready() else f" ({self.beagle}/get_sensor_data not offered)"
            problems.append(f"no reply from {self.beagle} for {longest:.1f} s{offered}")
        elif lost:
            level = DiagnosticStatus.WARN
            problems.append(f"{lost} request(s) unanswered within {c.timeout_s:g} s, asked again")
        if polls_lost:
            level = level if level == DiagnosticStatus.ERROR else DiagnosticStatus.WARN
            problems.append(
                f"{polls_lost} get_samples request(s) unanswered within "
                f"{self.samples_client.timeout_s:g} s, asked again from the same poll"
            )
        if new and self.p["per_poll"]:
            level = level if level == DiagnosticStatus.ERROR else DiagnosticStatus.WARN
            problems.append(f"{new} gap(s) in the single polls: {t.gap_reasons[-1]}")
        mode = "per poll" if self.p["per_poll"] else "per request (per_poll false)"
        text = "; ".join(problems) or mode
        stamp = self._last_stamp
        values = {
            "polls_integrated": sum(t.polls_used),
            "gaps": t.gaps,
            "last_gap": t.gap_reasons[-1] if t.gap_reasons else "",
            "steps_used": self.samples_used,
            "lifted_steps": self.odometry.lifted_samples,
            "switched_steps": self.odometry.switched_samples,
            "lift_fill_sigma_m": f"{self.fill_variance.total_var_m2 ** 0.5:.6f}",
            "method": self.p["method"],
            "requests_sent": c.sent,
            "replies": c.answered,
            "requests_unanswered": c.abandoned,
            "polls_requests_unanswered": self.samples_client.abandoned,
            "s_since_reply": f"{silent:.3f}",
            "last_poll_stamp": f"{stamp.sec}.{stamp.nanosec:09d}" if stamp else "",
        }
        arr = DiagnosticArray()
        arr.header.stamp = self.get_clock().now().to_msg()
        arr.status.append(DiagnosticStatus(
            level=level, name=f"{self.get_fully_qualified_name()}: pose", message=text,
            hardware_id=self.beagle,
            values=[KeyValue(key=k, value=str(v)) for k, v in values.items()],
        ))  # fmt: skip
        self.diag_pub.publish(arr)

    def publish_odometry(self, before: Pose2D, after: Pose2D, dt: float, data, stamp=None) -> None:
        """Publish nav_msgs/Odometry for the step ``before`` -> ``after`` over ``dt`` s."""
        poll = data.stamp if stamp is None else stamp
        msg = odometry_message(
            before,
            after,
            dt,
            node_stamp(self, poll.sec * 1_000_000_000 + poll.nanosec),
            data.cpi,
            self.uncertainty,
            self.frame("odom_frame"),
            self.frame("base_frame"),
        )
        self.odom_pub.publish(msg)
        self._last_stamp = msg.header.stamp
        self.tf.send(
            planar_transform(
                msg.header.stamp, msg.header.frame_id, msg.child_frame_id, after.x, after.y,
                after.yaw,
            )
        )  # fmt: skip
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
