"""mm_beagle's console scripts (pyproject ``[project.scripts]``).

Each installs the missing-prerequisite hook (:mod:`mm_pc.prerequisites`) and only then
imports its program: a node imports rclpy at its top, so a missing ROS, extra or system
library, or a Ctrl-C or SIGTERM while it still imports, must be caught before that
import runs.
Importing a package of ours installs nothing.
"""

from __future__ import annotations

from mm_pc import stop_signals


def _launch(program: str, module: str) -> int:
    """Stop cleanly on a signal from now on (:mod:`mm_pc.stop_signals`), then hand over to
    :func:`mm_pc.prerequisites.launch` (imported after, as everything else)."""
    stop_signals.during_import(program)
    from mm_pc import prerequisites

    return prerequisites.launch(program, module)


def mm_beagle() -> int:
    """``mm-beagle``: the sensor node."""
    return _launch("mm-beagle", "mm_beagle.node.node")


def mm_beagle_agent() -> int:
    """``mm-beagle-agent``: the poller on the board, served over zenoh (no ROS)."""
    return _launch("mm-beagle-agent", "mm_beagle.link.agent_cli")


def mm_watch() -> int:
    """``mm-watch``: the node's totals in a terminal."""
    return _launch("mm-watch", "mm_beagle.tools.watch")


def mm_security() -> int:
    """``mm-security``: can this ROS installation run DDS security (SROS 2)"""
    return _launch("mm-security", "mm_beagle.link.security")
