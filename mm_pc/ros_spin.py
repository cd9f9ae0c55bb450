"""Start and spin a node so that Ctrl-C and SIGTERM stop it cleanly (ROS, no Qt)."""

from __future__ import annotations

import signal
import sys
import threading

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions


def init(argv: list[str] | None) -> threading.Event:
    """rclpy.init without rclpy's signal handlers; SIGINT/SIGTERM set the returned event.

    The handler must not call into rclpy: it can run while the main thread
    holds the context's lock (inside Context.ok()), and try_shutdown() would
    then wait for that same lock forever. rclpy's own handler is not used
    either, since it re-raises KeyboardInterrupt later, possibly in the middle
    of a node's clean-up.
    """
    rclpy.init(
        args=argv if argv is not None else sys.argv, signal_handler_options=SignalHandlerOptions.NO
    )
    stop = threading.Event()

    def handler(_signum, _frame) -> None:
        stop.set()

    signal.signal(signal.SIGINT, handler)
    signal.signal(signal.SIGTERM, handler)
    return stop


def stopping() -> None:
    """Ignore further SIGINT/SIGTERM: the node is already shutting down.

    Python restores the default handlers during interpreter finalisation, so
    an impatient second Ctrl-C arriving then would kill the process with
    SIGINT (exit -2) instead of the clean exit 0; an ignored signal stays
    ignored through finalisation.
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)


def spin_until(node: Node, stop: threading.Event) -> None:
    """Spin ``node`` until ``stop`` is set or the context shuts down (checked every 0.1 s)."""
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    while not stop.is_set() and rclpy.ok():
        executor.spin_once(timeout_sec=0.1)
