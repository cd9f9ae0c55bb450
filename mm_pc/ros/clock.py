"""Stamps on the node clock (``use_sim_time``), and a word when /clock is missing.

The poller stamps every poll with the wall clock (``time.time_ns()``, or the
agent's clock moved onto the PC's, :mod:`mm_beagle.link.remote`). Message header
stamps follow the node clock instead: with the system clock that is the poll
stamp itself; with ``use_sim_time`` (ROS time from /clock) it is the node's
ROS time minus the poll's age on the wall clock, so a pose stamped 5 ms ago
keeps that latency on the simulated time line. ROS time moves in /clock's steps
while the age grows continuously, so a newer poll whose reply waited longer would
map to an earlier time: a node's stamps for newer polls never go back (up to
``MAX_HOLD_NS``; a larger step back is the clock jumping, a bag looping, and passes).
The poll stamps stay in the messages that carry them (SensorData ``stamp``,
GetSamples ``stamp_ns``).
"""

from __future__ import annotations

import threading
import time
import weakref

from builtin_interfaces.msg import Time
from rclpy.clock import Clock, ClockType
from rclpy.node import Node

__all__ = ["MAX_HOLD_NS", "ClockWatch", "node_stamp"]

#: the most a sim-time stamp is moved forward to keep a node's stamps in order (ns)
MAX_HOLD_NS = 100_000_000

_last_sim: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()  # node -> (poll, stamp)
_last_lock = threading.Lock()


def node_stamp(node: Node, poll_ns: int) -> Time:
    """The node-clock stamp of a poll stamped ``poll_ns`` (wall clock, ns since the epoch)."""
    clock = node.get_clock()
    if getattr(clock, "ros_time_is_active", False):
        t = _sim_stamp(node, clock.now().nanoseconds, int(poll_ns))
    else:
        t = max(0, int(poll_ns))
    return Time(sec=t // 1_000_000_000, nanosec=t % 1_000_000_000)


def _sim_stamp(node: Node, ros_now_ns: int, poll_ns: int) -> int:
    """ROS time minus the poll's age, after the node's last stamp if the poll is newer."""
    t = max(0, ros_now_ns - max(0, time.time_ns() - poll_ns))
    with _last_lock:
        last_poll, last_t = _last_sim.get(node, (-1, 0))
        if poll_ns == last_poll:
            return last_t
        if poll_ns > last_poll:
            if last_t - MAX_HOLD_NS < t <= last_t:
                t = last_t + 1
            _last_sim[node] = (poll_ns, t)
    return t


class ClockWatch:
    """Under ``use_sim_time``: log once while no /clock has come (timers on it wait).

    rclpy's timers run on the node clock; without /clock its ROS time stays 0 and
    they never fire, so nothing timed is published (services still answer). This
    says so after ``after_s`` wall seconds, and once more when the clock starts.
    """

    def __init__(self, node: Node, after_s: float = 1.0) -> None:
        self._node = node
        self._warned = False
        self._timer = node.create_timer(
            after_s, self._check, clock=Clock(clock_type=ClockType.STEADY_TIME)
        )

    def _check(self) -> None:
        clock = self._node.get_clock()
        if not getattr(clock, "ros_time_is_active", False):
            self._stop()
            return
        now = clock.now().nanoseconds
        log = self._node.get_logger()
        if now == 0 and not self._warned:
            self._warned = True
            log.warning(
                "use_sim_time is true and no /clock has come yet: waiting for /clock "
                "(nothing timed is published until it ticks; services answer)"
            )
        elif now:
            if self._warned:
                log.info(f"/clock started at {now / 1e9:.3f} s: publishing")
            self._stop()

    def _stop(self) -> None:
        self._node.destroy_timer(self._timer)
