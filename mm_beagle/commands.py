"""mm_beagle's console scripts (pyproject ``[project.scripts]``).

Each installs the missing-prerequisite hook (:mod:`mm_pc.prerequisites`) and only then
imports its program: a node imports rclpy at its top, so a missing ROS, extra or system
library, or a Ctrl-C or SIGTERM while it still imports, must be caught before that
import runs.
Importing a package of ours installs nothing.
"""

from __future__ import annotations

from mm_pc.commands import launch_command as _launch


def mm_beagle() -> int:
    """``mm-beagle``: the sensor node."""
    return _launch("mm-beagle", "mm_beagle.node.node", node=True)


def mm_beagle_agent() -> int:
    """``mm-beagle-agent``: the poller on the board, served over zenoh (no ROS)."""
    return _launch("mm-beagle-agent", "mm_beagle.link.agent_cli")


def mm_watch() -> int:
    """``mm-watch``: the node's totals in a terminal."""
    return _launch("mm-watch", "mm_beagle.tools.watch")


def mm_security() -> int:
    """``mm-security``: can this ROS installation run DDS security (SROS 2)"""
    return _launch("mm-security", "mm_beagle.link.security")
