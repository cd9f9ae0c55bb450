"""mm_beagle's console scripts (pyproject ``[project.scripts]``).

Each installs the missing-prerequisite hook (:mod:`mm_pc.prerequisites`) and only then
imports its program: a node imports rclpy at its top, so a missing ROS, extra or system
library, or a Ctrl-C while it still imports, must be caught before that import runs.
Importing a package of ours installs nothing.
"""

from __future__ import annotations

from mm_pc import prerequisites


def mm_beagle() -> int:
    """``mm-beagle``: the sensor node."""
    return prerequisites.launch("mm-beagle", "mm_beagle.node.node")


def mm_beagle_agent() -> int:
    """``mm-beagle-agent``: the poller on the board, served over zenoh (no ROS)."""
    return prerequisites.launch("mm-beagle-agent", "mm_beagle.link.agent_cli")


def mm_watch() -> int:
    """``mm-watch``: the node's totals in a terminal."""
    return prerequisites.launch("mm-watch", "mm_beagle.tools.watch")


def mm_security() -> int:
    """``mm-security``: can this ROS installation run DDS security (SROS 2)"""
    return prerequisites.launch("mm-security", "mm_beagle.link.security")
