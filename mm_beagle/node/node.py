"""mm-beagle: the sensor node. Thin: the poller process (or the board's agent) does the work.

``backend`` spidev|sim spawns the 1 kHz poller here; ``remote`` reads the same
shared state from an mm-beagle-agent over zenoh (:mod:`mm_beagle.link.remote`), so
everything below is one implementation for both.

Services (private namespace, so /mm_beagle/... by default), in
:mod:`~mm_beagle.node.sensor_services`:
  ~/get_sensor_data      read-and-clear sums (empty id = every sensor that is up),
                         with the single polls when asked (polls_ids)
  ~/get_sensor_settings  all registers of one sensor, without losing counts
  ~/set_resolution       CPI of one sensor (X and Y)
  ~/get_samples          single polls from the ring buffer
Topics: ~/sensor_data (SensorData, sensor-data QoS, `publish_rate` Hz;
:mod:`~mm_beagle.node.data_topic`) and /diagnostics (one status per sensor every
`diagnostics_period` s; :mod:`~mm_beagle.node.diagnostics`); the optional odometry
outputs in :mod:`~mm_beagle.node.odometry_publishers`. Live parameters:
:mod:`~mm_beagle.node.live_parameters`; the poller watched and restarted:
:mod:`~mm_beagle.node.supervision`.
"""

from __future__ import annotations

import sys
import threading
import time

import rclpy
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node

from mm_beagle.link.remote import RemoteAgent
from mm_beagle.node import memory_trace, messages
from mm_beagle.node.data_topic import SensorDataTopic
from mm_beagle.node.diagnostics import Diagnostics
from mm_beagle.node.live_parameters import LiveParameters
from mm_beagle.node.params import NodeSettings, declare
from mm_beagle.node.sensor_services import SensorServices
from mm_beagle.node.supervision import PollerSupervisor, StartupError
from mm_beagle.poller import chip_config
from mm_beagle.poller import shared_state as ss
from mm_beagle.poller.poller_client import PollerClient
from mm_pc.ros import spin as ros_spin
from mm_pc.ros.clock import ClockWatch

NODE_NAME = "mm_beagle"
#: how long a poller stopped during the node's start gets to answer "stop", then to end (s)
STOP_WHILE_STARTING_S = 0.5


class BeagleNode(Node):
    """The composition: settings, the poller, and the parts that serve what it writes."""

    def __init__(self, stop: threading.Event | None = None, **kwargs) -> None:
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
        self.lock = threading.Lock()  # the read-and-clear cursors move under it
        self.last_errors = [""] * len(self.devices)  # why each sensor went down
        self.fatal = ""  # why the poller stopped for good
        self.stuck = ""  # why the poller counts as stuck, '' while it polls
        started_ns = time.time_ns()
        self.supervisor = PollerSupervisor(self)
        # A signal while the node starts (stop set): main stops what was started, nothing
        # more is made (under load the poller's start and the services took seconds more).
        self.start_interrupted = stop is not None and stop.is_set()
        if self.start_interrupted:
            return
        self.poller.start()
        self.supervisor.wait_for_first_bring_up(timeout=10.0, stop=stop)  # stop: Ctrl-C
        self.start_interrupted = stop is not None and stop.is_set()
        if self.start_interrupted:
            return
        # the read-and-clear cursors' origin: now, or the remote link's first contact
        start = ss.Totals.zero(getattr(self.poller, "origin_ns", 0) or started_ns)

        self.sensor_services = SensorServices(self, start)
        # the service callbacks, also called directly (in-process tests)
        self.on_get_sensor_data = self.sensor_services.on_get_sensor_data
        self.on_get_samples = self.sensor_services.on_get_samples
        self.data_topic = SensorDataTopic(self, start)
        self.diagnostics = Diagnostics(self)
        self.onboard = None
        if self.settings.odometry.rate > 0:
            from mm_beagle.node.odometry_publishers import OnboardOdometryPublisher

            self.onboard = OnboardOdometryPublisher(self)
        otos = [i for i, c in enumerate(self.chips) if c == "otos"]
        if otos and self.settings.publish_rate > 0:
            from mm_beagle.node.odometry_publishers import ChipOdometryPublisher

            ChipOdometryPublisher(self, otos)
        self.supervisor.start_timer()
        self.live_parameters = LiveParameters(self)
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

    # --- what the parts share ---------------------------------------------------------------

    def unknown_id(self, sensor_id: str) -> str:
        known = ", ".join(self.devices)
        if not sensor_id:
            return f"this service needs a sensor id; known: {known}"
        return f"unknown sensor id '{sensor_id}'; known: {known}"

    def is_up(self, i: int) -> bool:
        return int(self.poller.state.ints[i][ss.I_STATE]) == ss.STATE_UP

    def down_message(self, i: int) -> str:
        why = self.last_errors[i] or "starting up"
        return f"sensor {self.devices[i]} is down ({why})"

    def publish_data(self) -> None:
        """One SensorData per sensor that is up (the topic's round, also called directly)."""
        self.data_topic.publish()

    def publish_diagnostics(self) -> None:
        """One /diagnostics round now (also called directly)."""
        self.diagnostics.publish()

    def shutdown(self) -> None:
        """Stop the poller process (or close the link to the agent). One stopped while it
        started may still be importing and cannot answer the stop command: it gets
        :data:`STOP_WHILE_STARTING_S` before it is terminated, not the usual 3 s."""
        if self.start_interrupted:
            self.poller.stop(timeout=STOP_WHILE_STARTING_S)
        else:
            self.poller.stop()


def main(argv: list[str] | None = None) -> int:
    """Exit 0 on a clean stop, 2 for bad configuration (found while starting), else 1."""
    memory_trace.start()  # MM_BEAGLE_TRACEMALLOC: a debug aid, off unless set
    stop = ros_spin.init(argv, "mm-beagle")
    node = None
    code = 0
    try:
        try:
            node = BeagleNode(stop)
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
