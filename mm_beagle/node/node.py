"""mm-beagle: the sensor node. Thin: the poller process (or the board's agent) does the work.

``backend`` spidev|sim spawns the 1 kHz poller here; ``remote`` reads the same
shared state from an mm-beagle-agent over zenoh (:mod:`mm_beagle.link.remote`), so
everything below is one implementation for both.

Services (private namespace, so /mm_beagle/... by default):
  ~/get_sensor_data      read-and-clear sums (empty id = every sensor that is up),
                         with the single polls when asked (polls_ids)
  ~/get_sensor_settings  all registers of one sensor, without losing counts
  ~/set_resolution       CPI of one sensor (X and Y)
  ~/get_samples          single polls from the ring buffer
Topics: ~/sensor_data (SensorData, sensor-data QoS, `publish_rate` Hz) and
/diagnostics (one status per sensor every `diagnostics_period` s).
"""

from __future__ import annotations

import contextlib
import sys
import threading
import time

import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rcl_interfaces.msg import SetParametersResult
from rclpy.event_handler import PublisherEventCallbacks
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data

from mm_beagle.link.remote import RemoteAgent
from mm_beagle.node import health, messages
from mm_beagle.node.params import NodeSettings, declare
from mm_beagle.poller import chip_config
from mm_beagle.poller import shared_state as ss
from mm_beagle.poller.poller_client import PollerClient, PollerError
from mm_beagle.poller.read_and_clear import ClientCursors
from mm_interfaces.msg import SensorData
from mm_pc.ros import spin as ros_spin
from mm_pc.ros.clock import ClockWatch, node_stamp
from mm_pc.ros.services import service_types
from mm_pc.ros.tf import frame_ids_problem

NODE_NAME = "mm_beagle"

# A local poller whose poll count has not moved for this long (s) while its
# process lives is stuck (stopped, or hung mid-write): reported on /diagnostics
# as ERROR and restarted. Longer than any stall the diagnostics should report
# as a stall (a 4 s stop still gets its counter-wrap ERROR first).
POLLER_STUCK_S = 5.0


class StartupError(RuntimeError):
    """The poller could not start (its message says why)."""


class BeagleNode(Node):
    def __init__(self, **kwargs) -> None:
        super().__init__(NODE_NAME, **kwargs)
        self.settings: NodeSettings = declare(self)
        cfg = self.settings.poller
        self.devices = cfg.devices
        self.chips = chip_config.resolve_chips(cfg.chips, cfg.devices)
        for dev, opts in cfg.device_options.items():
            self.get_logger().info(
                f"{dev}: from calibration_file, written at every start: "
                + ", ".join(f"{k} {v}" for k, v in opts.items())
            )
        if cfg.backend == "remote":
            r = self.settings.remote
            self.poller: PollerClient | RemoteAgent = RemoteAgent(
                cfg, r.agent, r.name, r.credentials, r.clock_sync
            )
        else:
            self.poller = PollerClient(cfg)
        # Drawn per start: every SensorData and get_samples reply carries it, so a
        # client sees a restart even when the new node's seq is past the old one's.
        self.instance_id = messages.new_instance_id()
        start = ss.Totals.zero(time.time_ns())
        # Read-and-clear cursors: one for the services, one for the topic.
        self._served = [start] * len(self.devices)
        self._published = [start] * len(self.devices)
        self._client_cursors = ClientCursors(len(self.devices), start)  # request.client
        self._lock = threading.Lock()
        self._diag_last: tuple[float, list[int], int] | None = None
        self._states = [ss.STATE_STARTING] * len(self.devices)
        self._last_errors = [""] * len(self.devices)
        self.fatal = ""
        self._diag_errors = [(0, 0)] * len(self.devices)
        self._diag_stamp = [0] * len(self.devices)  # newest poll seen by the last round (ns)
        self._diag_overruns = 0
        self._progress = (-1, time.monotonic())  # (G_POLLS, when it last changed)
        self.stuck = ""  # why the poller counts as stuck, '' while it polls
        self.poller.start()
        self._wait_for_first_bring_up(timeout=10.0)

        handlers = {
            "get_sensor_data": self.on_get_sensor_data,
            "get_sensor_settings": self.on_get_settings,
            "set_resolution": self.on_set_resolution,
            "get_samples": self.on_get_samples,
        }
        for name, srv_type in service_types().items():
            self.create_service(srv_type, f"~/{name}", handlers[name])
        self._data_timer = None
        self.data_pub = self.create_publisher(
            SensorData,
            "~/sensor_data",
            qos_profile_sensor_data,
            event_callbacks=PublisherEventCallbacks(matched=self._on_matched),
        )
        self.diag_pub = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self._diag_timer = self.create_timer(
            self.settings.diagnostics_period, self.publish_diagnostics
        )
        self.onboard = None
        if self.settings.odometry.rate > 0:
            self._start_onboard_odometry()
        self._start_chip_odometry()
        self.create_timer(0.2, self.relay_poller_events)
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.clock_watch = ClockWatch(self)
        where = (
            f"read from the agent at {self.settings.remote.agent}"
            if cfg.backend == "remote"
            else f"polled at {cfg.poll_rate:g} Hz (backend {cfg.backend}, {cfg.cpi} CPI)"
        )
        self.get_logger().info(
            f"sensors {', '.join(self.devices)} {where}; "
            f"services under {self.get_fully_qualified_name()}/"
        )

    # --- helpers -------------------------------------------------------------------------

    def _on_matched(self, info) -> None:
        """Run the sensor_data timer only while someone subscribes."""
        rate = self.settings.publish_rate
        if info.current_count > 0 and self._data_timer is None and rate > 0:
            self._data_timer = self.create_timer(1.0 / rate, self.publish_data)
        elif info.current_count == 0 and self._data_timer is not None:
            self.destroy_timer(self._data_timer)
            self._data_timer = None

    def _wait_for_first_bring_up(self, timeout: float) -> None:
        """Advertise the services only once every sensor is up or has failed once.

        With the remote backend an unreachable agent does not stop the node:
        the services say so until the link comes up.
        """
        ints = self.poller.state.ints
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline and self.poller.alive:
            if all(int(ints[i][ss.I_STATE]) != ss.STATE_STARTING for i in range(len(self.devices))):
                break
            time.sleep(0.02)
        if isinstance(self.poller, RemoteAgent) and self.poller.unavailable():
            self.get_logger().warning(f"{self.poller.unavailable()}; serving that until it is")
        for event in self.poller.drain_events():
            if event[0] == "fatal":  # e.g. an unreadable patch file or register map
                self.poller.stop()
                raise StartupError(str(event[1]))
            self._relay(event)
        if not self.poller.alive:
            raise StartupError("the poller process died while starting")

    def _unknown_id(self, sensor_id: str) -> str:
        known = ", ".join(self.devices)
        if not sensor_id:
            return f"this service needs a sensor id; known: {known}"
        return f"unknown sensor id '{sensor_id}'; known: {known}"

    def _is_up(self, i: int) -> bool:
        return int(self.poller.state.ints[i][ss.I_STATE]) == ss.STATE_UP

    def _unavailable(self, res) -> bool:
        """True (and ``res`` says why) while the remote agent cannot be reached."""
        problem = self.poller.unavailable()
        if problem:
            res.success, res.message = False, problem
        return bool(problem)

    def _down_message(self, i: int) -> str:
        why = self._last_errors[i] or "starting up"
        return f"sensor {self.devices[i]} is down ({why})"

    # --- live parameters (params.LIVE) ----------------------------------------------------

    def _on_set_parameters(self, params) -> SetParametersResult:
        """Apply ``ros2 param set`` on a live parameter, or refuse it and keep the old value.

        rclpy has already checked read-only flags and ranges. A new ``cpi`` goes to
        every sensor like ``set_resolution`` (same checks, counts drained at the old
        CPI); it is refused as a whole if a sensor is down or refuses it.
        """
        changes = {p.name: p.value for p in params}
        if problem := frame_ids_problem(changes, ("odom_frame", "base_frame")):
            self.get_logger().warning(f"parameters not changed: {problem}")
            return SetParametersResult(successful=False, reason=problem)
        if "cpi" in changes:
            problem = self._set_cpi_everywhere(int(changes["cpi"]))
            if problem:
                self.get_logger().warning(f"parameter cpi not changed: {problem}")
                return SetParametersResult(successful=False, reason=problem)
        if "publish_rate" in changes:
            self.settings.publish_rate = float(changes["publish_rate"])
            if self._data_timer is not None:  # restart it at the new rate (or stop it at 0)
                self.destroy_timer(self._data_timer)
                self._data_timer = None
                if self.settings.publish_rate > 0:
                    self._data_timer = self.create_timer(
                        1.0 / self.settings.publish_rate, self.publish_data
                    )
        if "diagnostics_period" in changes:
            self.settings.diagnostics_period = float(changes["diagnostics_period"])
            self.destroy_timer(self._diag_timer)
            self._diag_timer = self.create_timer(
                self.settings.diagnostics_period, self.publish_diagnostics
            )
        for frame in ("odom_frame", "base_frame"):
            if frame in changes:
                setattr(self.settings.odometry, frame, str(changes[frame]))
        if "base_frame" in changes and self.onboard is not None:
            self._send_static_frames()
        for name, value in changes.items():
            if name != "cpi":  # set_cpi logs its own line per sensor
                self.get_logger().info(f"parameter {name} set to {value}")
        return SetParametersResult(successful=True)

    def _set_cpi_everywhere(self, cpi: int) -> str:
        """Set every sensor to ``cpi``; '' on success, else why nothing changed."""
        problem = self.poller.unavailable()
        if problem:
            return problem
        down = [self._down_message(i) for i in range(len(self.devices)) if not self._is_up(i)]
        if down:
            return "; ".join(down)
        before = [int(self.poller.state.ints[i][ss.I_CPI_Y]) for i in range(len(self.devices))]
        fixed = [chip_config.chip_info_for(c).cpi.fixed for c in self.chips]
        for i, dev in enumerate(self.devices):
            if fixed[i]:  # optical flow: its resolution follows its height
                self.get_logger().info(
                    f"{dev} ({self.chips[i]}) keeps its fixed {before[i]} CPI (parameter cpi)"
                )
                continue
            try:
                status, payload = self.poller.command("set_cpi", i, cpi)
            except PollerError as exc:
                status, payload = "error", str(exc)
            if status != "ok":
                for k in range(i):  # put back the sensors already changed
                    if fixed[k]:
                        continue
                    with contextlib.suppress(PollerError):
                        self.poller.command("set_cpi", k, before[k])
                return f"{dev}: {payload}"
            self.get_logger().info(f"{dev} set to {cpi} CPI (parameter cpi)")
        return ""

    # --- services ------------------------------------------------------------------------

    def on_get_sensor_data(self, req, res):
        """Read-and-clear sums since this service's previous call, per sensor.

        With ``req.client`` set: since that client's acknowledged ``ack_seq``
        (:mod:`mm_beagle.poller.read_and_clear`; a repeated ack gets the same interval).
        """
        if self._unavailable(res):
            return res
        if req.id:
            i = self.poller.index(req.id)
            if i is None:
                res.success, res.message = False, self._unknown_id(req.id)
                return res
            if not self._is_up(i):
                res.success, res.message = False, self._down_message(i)
                return res
            wanted = [i]
        else:
            wanted = [i for i in range(len(self.devices)) if self._is_up(i)]
            down = [self.devices[i] for i in range(len(self.devices)) if i not in wanted]
            if not wanted:
                res.success, res.message = (
                    False,
                    "no sensor is up: "
                    + "; ".join(self._down_message(i) for i in range(len(self.devices))),
                )
                return res
            res.message = f"down: {', '.join(down)}" if down else ""
        polls_wanted, problem = self._polls_request(req, wanted)
        if problem:
            res.success, res.message = False, problem
            return res
        data = []
        ends: dict[int, int] = {}
        with self._lock:
            # every snapshot before any cursor moves: a busy poller changes nothing
            # (ClientCursors.serve also takes its snapshots before it changes a cursor)
            try:
                if req.client or len(req.ack_seq):
                    intervals, problem = self._client_cursors.serve(
                        req.client,
                        wanted,
                        list(req.ack_seq),
                        self.poller.state.snapshot,
                        one_id=bool(req.id),
                    )
                    if problem:
                        res.success, res.message = False, problem
                        return res
                else:
                    nows = [self.poller.state.snapshot(i) for i in wanted]
                    intervals = []
                    for i, now in zip(wanted, nows, strict=True):
                        intervals.append((self._served[i], now))
                        self._served[i] = now
            except ss.PollerBusyError:
                res.success, res.message = False, ss.BUSY_MESSAGE
                return res
            for i, (prev, now) in zip(wanted, intervals, strict=True):
                data.append(
                    messages.sensor_data(
                        self.devices[i], prev, now, self.instance_id, self.chips[i]
                    )
                )
                ends[i] = now.seq
        res.data = data
        res.polls, busy = self._polls_for(polls_wanted, ends)
        if busy:
            note = f"no polls for {', '.join(busy)}: {ss.BUSY_MESSAGE} (ask get_samples)"
            res.message = f"{res.message}; {note}" if res.message else note
        res.success = True
        return res

    def _polls_request(self, req, wanted: list[int]) -> tuple[list[tuple[int, int]], str]:
        """``req.polls_ids``/``polls_since_seq`` checked: ([(index, since_seq)], '') for the
        sensors of ``wanted`` (a down sensor named there is left out: it has no data either),
        or ([], why not) -- checked before any cursor moves, so a bad request changes nothing."""
        ids, sinces = list(req.polls_ids), [int(s) for s in req.polls_since_seq]
        if len(ids) != len(sinces):
            return [], (
                f"polls_ids has {len(ids)} entries and polls_since_seq {len(sinces)}; "
                "give one since_seq per sensor id (both empty for no polls)"
            )
        out: list[tuple[int, int]] = []
        seen: set[int] = set()
        for dev, since in zip(ids, sinces, strict=True):
            i = self.poller.index(dev)
            if i is None:
                return [], f"polls_ids: {self._unknown_id(dev)}"
            if i in seen:
                return [], f"polls_ids names {dev} twice; name each sensor at most once"
            seen.add(i)
            if req.id and dev != req.id:
                return [], (
                    f"polls_ids names {dev}, but this request reads only {req.id}; "
                    "ask for the polls of the sensors you read"
                )
            seq_now = int(self.poller.state.ints[i][ss.I_SEQ])
            if since > seq_now:
                return [], (
                    f"polls_since_seq {since} for {dev} is ahead of the newest poll "
                    f"({seq_now}); ask with the next_seq of the previous polls "
                    "(or 0 for the oldest stored), and after a node restart without polls once"
                )
            if i in wanted:
                out.append((i, since))
        return out, ""

    def _polls_for(self, wanted: list[tuple[int, int]], ends: dict[int, int]):
        """([SensorPolls], [devices whose ring was busy]): each sensor's polls from its
        since_seq up to ``ends[i]``, the seq of its SensorData in this reply."""
        polls, busy = [], []
        state = self.poller.state
        for i, since in wanted:
            end = ends[i]
            cpi_now = int(state.ints[i][ss.I_CPI_Y])
            if end <= since:  # nothing new (or an interval served again after a lost reply)
                fields = ("stamp_ns", "dx", "dy", "status", "cpi", "flags", "quality")
                empty = {k: () for k in fields}
                dev = self.devices[i]
                polls.append(messages.sensor_polls(dev, since, since, 0, empty, cpi_now))
                continue
            try:
                first, nxt, dropped, arr = state.samples(i, since, end - since)
            except ss.PollerBusyError:
                busy.append(self.devices[i])
                continue
            if nxt > end:  # since_seq had left the ring: stop at this reply's seq all the same
                keep = max(0, end - first)
                arr, nxt = {k: v[:keep] for k, v in arr.items()}, first + keep
            polls.append(messages.sensor_polls(self.devices[i], first, nxt, dropped, arr, cpi_now))
        return polls, busy

    def _poller_command(self, res, sensor_id: str, kind: str, *args) -> tuple[int, object]:
        """Run a poller command for one sensor id: (index, payload), or (-1, None) on failure.

        On failure ``res`` already carries success=false and the reason.
        """
        i = self.poller.index(sensor_id)
        if i is None:
            res.success, res.message = False, self._unknown_id(sensor_id)
            return -1, None
        try:
            status, payload = self.poller.command(kind, i, *args)
        except PollerError as exc:
            res.success, res.message = False, str(exc)
            return -1, None
        if status != "ok":
            res.success, res.message = False, str(payload)
            return -1, None
        return i, payload

    def on_get_settings(self, req, res):
        """All registers of one sensor; the displacement that read cleared is kept."""
        i, payload = self._poller_command(res, req.id, "settings")
        if i >= 0:
            res.settings = messages.sensor_settings(self.devices[i], payload)  # type: ignore[arg-type]
            res.success = True
        return res

    def on_set_resolution(self, req, res):
        """Set one sensor's CPI (X and Y); ``res.cpi`` is the CPI in force afterwards."""
        i, _ = self._poller_command(res, req.id, "set_cpi", int(req.cpi))
        known = self.poller.index(req.id)
        if known is not None:  # the CPI in force, whether or not the request succeeded
            res.cpi = int(self.poller.state.ints[known][ss.I_CPI_Y])
        if i >= 0:
            res.success = True
            res.message = f"{self.devices[i]} set to {res.cpi} CPI"
            self.get_logger().info(res.message)
        return res

    def on_get_samples(self, req, res):
        """Single polls from the ring, since ``since_seq`` (chained by ``next_seq``)."""
        if self._unavailable(res):
            return res
        i = self.poller.index(req.id)
        if i is None:
            res.success, res.message = False, self._unknown_id(req.id)
            return res
        seq_now = int(self.poller.state.ints[i][ss.I_SEQ])
        if req.since_seq > seq_now:
            res.success = False
            res.message = f"since_seq {req.since_seq} is ahead of the newest poll ({seq_now})"
            return res
        try:
            first, nxt, dropped, arr = self.poller.state.samples(i, req.since_seq, req.max_samples)
        except ss.PollerBusyError:
            res.success, res.message = False, ss.BUSY_MESSAGE
            return res
        messages.fill_polls(
            res, first, nxt, dropped, arr, int(self.poller.state.ints[i][ss.I_CPI_Y])
        )
        res.instance_id = self.instance_id
        res.success = True
        if dropped:
            res.message = f"{dropped} polls had already left the ring buffer"
        return res

    # --- periodic work -----------------------------------------------------------------------

    def publish_data(self) -> None:
        """One SensorData per sensor that is up, since the previous publication."""
        if self.data_pub.get_subscription_count() == 0 or self.poller.unavailable():
            return  # nobody listens or nothing to say: the cursor keeps the interval exact
        with self._lock:
            for i, dev in enumerate(self.devices):
                if not self._is_up(i):
                    continue
                try:
                    now = self.poller.state.snapshot(i)
                except ss.PollerBusyError:
                    continue  # this round skipped: the cursor keeps the next interval exact
                msg = messages.sensor_data(
                    dev, self._published[i], now, self.instance_id, self.chips[i]
                )
                self._published[i] = now
                self.data_pub.publish(msg)

    def _start_onboard_odometry(self) -> None:
        """Optional: integrate every 1 kHz poll here and publish ~/odom (same math, same msg).

        With ``publish_tf`` also odom -> base_link on /tf and the mounts on /tf_static;
        ``~/reset`` (std_srvs/Trigger) puts the pose and its covariance back to the start.
        """
        from nav_msgs.msg import Odometry as OdometryMsg

        from mm_beagle.node.onboard_odometry import OnboardOdometry
        from mm_pc.core.uncertainty import PoseUncertainty
        from mm_pc.ros.odometry_msgs import odometry_message
        from mm_pc.ros.reset import create_reset_service
        from mm_pc.ros.tf import TfPublisher, planar_transform, sensor_frame_names

        o = self.settings.odometry
        self.onboard = OnboardOdometry(o, self.devices, self.poller.state)
        self.sensor_frames = sensor_frame_names(self.devices, o.sensor_frames)
        self.uncertainty = PoseUncertainty()
        self.tf = TfPublisher(self, o.publish_tf)
        self._send_static_frames()
        pub = self.create_publisher(OdometryMsg, "~/odom", 10)

        def tick() -> None:
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
                node_stamp(self, stamp_ns),
                cpi,
                self.uncertainty,
                o.odom_frame,
                o.base_frame,
            )
            pub.publish(msg)
            self.tf.send(
                planar_transform(
                    msg.header.stamp, o.odom_frame, o.base_frame, after.x, after.y, after.yaw
                )
            )

        def reset() -> str:
            self.onboard.reset()
            self.uncertainty.reset()
            return f"onboard odometry back to (0, 0, 0) in {o.odom_frame}, covariance cleared"

        create_reset_service(self, reset)
        self.create_timer(1.0 / o.rate, tick)

    def _start_chip_odometry(self) -> None:
        """The OTOS's on-chip pose as a second nav_msgs/Odometry (issue 15 part 5).

        One topic per OTOS device: ``~/otos/odom`` for the first, ``~/otos/odom_<index>``
        (its index in ``devices``) for any further one; frame ids as the onboard odometry's
        (``odom_frame``, ``base_frame``); at ``publish_rate`` (0: none), a message only when
        the chip's pose is newer than the last one sent. The chip gives no covariance: the
        first element of each matrix is -1 (unknown), the rest 0; do not fuse it as is.
        """
        rate = self.settings.publish_rate
        otos = [i for i, c in enumerate(self.chips) if c == "otos"]
        if not otos or rate <= 0:
            return
        from nav_msgs.msg import Odometry as OdometryMsg

        from mm_pc.ros.odometry_msgs import chip_odometry

        pubs = {
            i: self.create_publisher(
                OdometryMsg, "~/otos/odom" if k == 0 else f"~/otos/odom_{i}", 10
            )
            for k, i in enumerate(otos)
        }
        sent = dict.fromkeys(otos, 0)

        def tick() -> None:
            o = self.settings.odometry
            for i, pub in pubs.items():
                try:
                    t = self.poller.state.snapshot(i)
                except ss.PollerBusyError:
                    continue
                if t.chip_pose_ns == sent[i] or t.state != ss.STATE_UP:
                    continue
                sent[i] = t.chip_pose_ns
                pub.publish(
                    chip_odometry(
                        (t.chip_x, t.chip_y, t.chip_yaw),
                        (t.chip_vx, t.chip_vy, t.chip_wz),
                        node_stamp(self, t.chip_pose_ns),
                        o.odom_frame,
                        o.base_frame,
                    )
                )

        self.create_timer(1.0 / rate, tick)
        self.get_logger().info(
            "OTOS on-chip pose on "
            + ", ".join(f"{pub.topic_name} ({self.devices[i]})" for i, pub in pubs.items())
        )

    def _send_static_frames(self) -> None:
        """base_link -> each sensor frame at its (calibrated) mount, latched on /tf_static."""
        from mm_pc.ros.tf import mount_transforms

        self.tf.send_static(
            mount_transforms(
                self.get_clock().now().to_msg(),
                self.settings.odometry.base_frame,
                self.sensor_frames,
                self.onboard.odometry.mounts,
            )
        )

    def relay_poller_events(self) -> None:
        """Log what the poller reported; restart a stuck one; stop the node if it is gone."""
        for event in self.poller.drain_events():
            self._relay(event)
        self._check_progress()
        if not self.poller.alive:
            # Without the poller the node has nothing to serve: stop, exit non-zero.
            self.fatal = self.fatal or "the poller process is gone"
            self.get_logger().fatal(f"{self.fatal}; shutting down")
            self.context.try_shutdown()

    def _check_progress(self) -> None:
        """Restart a local poller whose poll count stood still for POLLER_STUCK_S."""
        if not isinstance(self.poller, PollerClient) or not self.poller.alive:
            return
        polls, now = int(self.poller.state.glob[ss.G_POLLS]), time.monotonic()
        if polls != self._progress[0]:
            self._progress = (polls, now)
            return
        if now - self._progress[1] < POLLER_STUCK_S:
            return
        self.stuck = (
            f"poller stuck: no poll for {now - self._progress[1]:.1f} s "
            f"(limit {POLLER_STUCK_S:g} s); restarted it"
        )
        self.get_logger().error(self.stuck)
        self.publish_diagnostics()  # the ERROR goes out before the restart
        self.poller.restart()
        self._progress = (-1, time.monotonic())

    def _relay(self, event: tuple) -> None:
        """Log one poller event and keep what the services need from it."""
        log = self.get_logger()
        kind = event[0]
        if kind == "up":
            i = self.poller.index(event[1])
            if i is not None:
                self._last_errors[i] = ""
            log.info(f"sensor {event[1]} up: {event[2]}")
        elif kind == "down":
            i = self.poller.index(event[1])
            if i is not None:
                self._last_errors[i] = event[2]
            log.error(f"sensor {event[1]} down: {event[2]}")
        elif kind == "fatal":
            log.fatal(f"poller stopped: {event[1]}")
            self.fatal = str(event[1])
        else:
            log.info(str(event[1]))

    def publish_diagnostics(self) -> None:
        """One DiagnosticStatus per sensor: state, rates, errors, totals (and the link)."""
        state = self.poller.state
        glob = state.glob
        try:
            snaps = [state.snapshot(i) for i in range(len(self.devices))]
        except ss.PollerBusyError:
            if self.stuck:
                self._publish_stuck()
            return  # a brief stall mid-write: this round skipped
        wall = time.monotonic()
        seqs = [t.seq for t in snaps]
        polls = int(glob[ss.G_POLLS])
        last, self._diag_last = self._diag_last, (wall, seqs, polls)
        overruns = int(glob[ss.G_OVERRUNS])
        overruns_grew = overruns - self._diag_overruns if last else 0
        self._diag_overruns = overruns
        now_ns = time.time_ns()
        p50, p99 = state.period_percentiles(0.5, 0.99)
        cpu = self.poller.cpu_percent()
        link = self.poller.link_values()
        unavailable = self.poller.unavailable()
        arr = DiagnosticArray()
        arr.header.stamp = self.get_clock().now().to_msg()
        for i, dev in enumerate(self.devices):
            t = snaps[i]
            rate = (
                (seqs[i] - last[1][i]) / (wall - last[0])
                if last and wall > last[0]
                else float("nan")
            )
            values = {
                "chip": self.chips[i],
                "state": ss.STATE_NAMES.get(t.state, "?"),
                "polls": t.seq,
                "achieved_rate_hz": f"{rate:.1f}",
                "period_p50_us": f"{p50:.0f}",
                "period_p99_us": f"{p99:.0f}",
                "late_polls": int(glob[ss.G_LATE]),
                "overruns": int(glob[ss.G_OVERRUNS]),
                "spi_errors": t.spi_errors,
                "lift_events": t.lift_total,
                "quality": t.quality,  # the newest poll's (SQUAL; -1: the chip has none)
                "low_quality_events": t.low_quality_total,
                # counts lost to lifts, estimated (pln2033.lift_fill), and its 1 sigma
                "lift_est_x_counts": f"{t.x_est_counts:.1f}",
                "lift_est_y_counts": f"{t.y_est_counts:.1f}",
                "lift_est_sigma_x_counts": f"{t.x_est_var_counts**0.5:.1f}",
                "lift_est_sigma_y_counts": f"{t.y_est_var_counts**0.5:.1f}",
                "overflows": t.overflows,
                "cpi": t.cpi_y,
                "x_total_counts": t.x_total,
                "y_total_counts": t.y_total,
                "reinits": t.reinits,
                "poller_cpu_percent": f"{cpu:.1f}",
                "poller_restarts": getattr(self.poller, "restarts", 0),
                "last_error": self._last_errors[i],
            }
            values.update(link)
            level_name, health_text, health_values = self._health(
                i, t, last, rate, overruns_grew, now_ns
            )
            values.update(health_values)
            if self.settings.poller.backend == "sim" or t.gen_x or t.gen_y:
                values["sim_generated_x_counts"] = t.gen_x
                values["sim_generated_y_counts"] = t.gen_y
                values["sim_lift_lost_x_counts"] = t.lift_lost_x
                values["sim_lift_lost_y_counts"] = t.lift_lost_y
            if self.stuck:
                level, text = DiagnosticStatus.ERROR, self.stuck
            elif unavailable:
                level, text = DiagnosticStatus.ERROR, unavailable
            elif t.state != ss.STATE_UP:
                level, text = DiagnosticStatus.ERROR, self._down_message(i)
            elif level_name == "ERROR":
                level, text = DiagnosticStatus.ERROR, health_text
            elif (t.spi_errors, t.overflows) != self._diag_errors[i]:
                level, text = (
                    DiagnosticStatus.WARN,
                    "SPI errors or counter overflows since last report"
                    + (f"; {health_text}" if level_name == "WARN" else ""),
                )
            elif level_name == "WARN":
                level, text = DiagnosticStatus.WARN, health_text
            else:
                level, text = DiagnosticStatus.OK, "up"
            self._diag_errors[i] = (t.spi_errors, t.overflows)
            name = f"{self.get_fully_qualified_name()}: {dev}"  # unique per robot namespace
            arr.status.append(messages.diagnostic(name, dev, level, text, values))
        self.diag_pub.publish(arr)
        self.stuck = ""  # reported (the restart's own round and this one)

    def _health(self, i, t, last, rate, overruns_grew, now_ns):
        """health.assess for sensor ``i`` over the polls since the previous round."""
        prev_seq = last[1][i] if last else t.seq
        try:
            _f, _n, _d, arr = self.poller.state.samples(i, prev_seq, 0)
        except ss.PollerBusyError:
            arr = None
        stamps = arr["stamp_ns"] if arr is not None else []
        if arr is not None and len(stamps):
            self._diag_stamp[i], prev_ns = int(stamps[-1]), self._diag_stamp[i]
            gap = health.longest_gap(stamps, arr["dx"], arr["dy"], prev_ns, now_ns)
        else:
            gap = health.longest_gap([], [], [], self._diag_stamp[i] or t.stamp_ns, now_ns)
        if self.settings.poller.backend == "remote" or t.state != ss.STATE_UP:
            gap = health.Gap(0.0, 0.0, 0.0)  # the link's own values say what is late there
        return health.assess(rate, self.settings.poller.poll_rate, overruns_grew, gap, t.cpi_y)

    def _publish_stuck(self) -> None:
        """ERROR per sensor when no snapshot can be had (the poller stopped mid-write)."""
        arr = DiagnosticArray()
        arr.header.stamp = self.get_clock().now().to_msg()
        restarts = getattr(self.poller, "restarts", 0)
        for dev in self.devices:
            name = f"{self.get_fully_qualified_name()}: {dev}"
            values = {"state": "stuck", "poller_restarts": restarts}
            arr.status.append(
                messages.diagnostic(name, dev, DiagnosticStatus.ERROR, self.stuck, values)
            )
        self.diag_pub.publish(arr)

    def shutdown(self) -> None:
        """Stop the poller process (or close the link to the agent)."""
        self.poller.stop()


def main(argv: list[str] | None = None) -> int:
    """Exit 0 on a clean stop, 2 for bad configuration (found while starting), else 1."""
    stop = ros_spin.init(argv, "mm-beagle")
    node = None
    code = 0
    try:
        try:
            node = BeagleNode()
        except (ValueError, OSError, ParameterException, StartupError) as exc:  # say what, exit 2
            print(f"mm-beagle: {exc}", file=sys.stderr)
            return 2
        ros_spin.spin_until(node, stop)
        code = 1 if node.fatal else 0
    except (KeyboardInterrupt, ExternalShutdownException):
        code = 1 if node is not None and node.fatal else 0
    except Exception as exc:  # at run time nothing is bad configuration: exit 1, never 2
        print(f"mm-beagle: stopped by an error at run time: {exc!r}", file=sys.stderr)
        code = 1
    finally:
        ros_spin.stopping()
        if node is not None:
            print("mm-beagle: shutting down, stopping the poller", file=sys.stderr)
            node.shutdown()
            node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()
    return code


if __name__ == "__main__":
    sys.exit(main())
