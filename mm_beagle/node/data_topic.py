"""``~/sensor_data``: one SensorData per sensor that is up, at ``publish_rate`` Hz.

Each message is the displacement since the previous one (the topic's own
read-and-clear cursor, apart from the services'). The timer runs only while
someone subscribes; a skipped round (nobody listens, the poller busy) leaves the
cursor where it was, so the next interval is exact. Each message's header: the
newest poll on the node clock, the sensor's counting-axes frame
(:func:`~mm_beagle.node.messages.counts_frames`).
"""

from __future__ import annotations

from rclpy.event_handler import PublisherEventCallbacks
from rclpy.qos import qos_profile_sensor_data

from mm_beagle.node import messages
from mm_beagle.poller import shared_state as ss
from mm_interfaces.msg import SensorData
from mm_pc.ros.clock import node_stamp


class SensorDataTopic:
    """The topic of ``node`` (a BeagleNode), from the totals snapshot ``start`` on."""

    def __init__(self, node, start: ss.Totals) -> None:
        self.node = node
        self.published = [start] * len(node.devices)
        self.frames = messages.counts_frames(node.devices, node.settings.odometry)
        self.timer = None
        self.pub = node.create_publisher(
            SensorData,
            "~/sensor_data",
            qos_profile_sensor_data,
            event_callbacks=PublisherEventCallbacks(matched=self._on_matched),
        )

    def _on_matched(self, info) -> None:
        """Run the timer only while someone subscribes."""
        if info.current_count > 0 and self.timer is None:
            self._start()
        elif info.current_count == 0 and self.timer is not None:
            self.node.destroy_timer(self.timer)
            self.timer = None

    def _start(self) -> None:
        rate = self.node.settings.publish_rate
        if rate > 0:
            self.timer = self.node.create_timer(1.0 / rate, self.publish)

    def set_rate(self, rate: float) -> None:
        """A new ``publish_rate`` (live parameter): a running timer restarts at it (0: stops)."""
        self.node.settings.publish_rate = rate
        if self.timer is not None:
            self.node.destroy_timer(self.timer)
            self.timer = None
            self._start()

    def publish(self) -> None:
        """One SensorData per sensor that is up, since the previous publication."""
        node = self.node
        if self.pub.get_subscription_count() == 0 or node.poller.unavailable():
            return  # nobody listens or nothing to say: the cursor keeps the interval exact
        with node.lock:
            for i, dev in enumerate(node.devices):
                if not node.is_up(i):
                    continue
                try:
                    now = node.poller.state.snapshot(i)
                except ss.PollerBusyError:
                    continue  # this round skipped: the cursor keeps the next interval exact
                msg = messages.sensor_data(
                    dev, self.published[i], now, node.instance_id, node.chips[i],
                    self.frames[i], node_stamp(node, now.stamp_ns),
                )  # fmt: skip
                self.published[i] = now
                self.pub.publish(msg)
