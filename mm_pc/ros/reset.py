"""``~/reset`` (std_srvs/srv/Trigger) for the odometry and fusion nodes."""

from __future__ import annotations

from collections.abc import Callable

from rclpy.node import Node
from std_srvs.srv import Trigger

__all__ = ["create_reset_service"]


def create_reset_service(node: Node, reset: Callable[[], str]):
    """Serve ``~/reset``: call ``reset`` (it returns what it did, one line), log and answer it."""

    def on_reset(_req, res):
        try:
            text = reset()
        except ValueError as exc:  # e.g. a start pose that cannot be applied
            res.success, res.message = False, f"not reset: {exc}"
            node.get_logger().warning(res.message)
            return res
        res.success, res.message = True, text
        node.get_logger().info(f"reset: {text}")
        return res

    return node.create_service(Trigger, "~/reset", on_reset)
