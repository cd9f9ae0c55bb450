"""Start and spin a node so that Ctrl-C and SIGTERM stop it cleanly (ROS, no Qt)."""

from __future__ import annotations

import signal
import sys
import threading
from collections.abc import Callable

import rclpy
from rclpy.exceptions import NameValidationException, ParameterException
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions

#: errors of a node's set-up that mean "bad configuration": exit 2 with the message
SETUP_ERRORS = (ValueError, ParameterException, NameValidationException, OSError)


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


def spin_until(node: Node, stop: threading.Event, executor=None) -> None:
    """Spin ``node`` until ``stop`` is set or the context shuts down (checked every 0.1 s).

    ``executor``: the executor to use (default: a new SingleThreadedExecutor);
    it is shut down on return.
    """
    executor = executor if executor is not None else SingleThreadedExecutor()
    executor.add_node(node)
    try:
        while not stop.is_set() and rclpy.ok():
            executor.spin_once(timeout_sec=0.1)
    finally:
        executor.shutdown()


def run(
    prog: str,
    make_node: Callable[[], Node],
    body: Callable[[Node, threading.Event], int | None],
    argv: list[str] | None = None,
    errors: tuple[type[BaseException], ...] = SETUP_ERRORS,
) -> int:
    """The ``main`` of a node: init, build, run ``body``, clean stop; the exit code.

    A configuration error (``errors``) prints ``prog: message`` to stderr and
    gives 2; ``body``'s return value (None = 0) otherwise. Ctrl-C and SIGTERM
    end ``body`` through the stop event; the node is destroyed and rclpy shut
    down whatever happened.
    """
    stop = init(argv)
    node = None
    code = 0
    try:
        node = make_node()
        code = body(node, stop) or 0
    except errors as exc:
        print(f"{prog}: {exc}", file=sys.stderr)
        code = 2
    finally:
        stopping()
        if node is not None:
            node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()
    return code
