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
    prerequisites.install()
    from mm_beagle.node.node import main

    return main()


def mm_beagle_agent() -> int:
    """``mm-beagle-agent``: the poller on the board, served over zenoh (no ROS)."""
    prerequisites.install()
    from mm_beagle.link.agent_cli import main

    return main()


def mm_watch() -> int:
    """``mm-watch``: the node's totals in a terminal."""
    prerequisites.install()
    from mm_beagle.tools.watch import main

    return main()


def mm_security() -> int:
    """``mm-security``: can this ROS installation run DDS security (SROS 2)?."""
    prerequisites.install()
    from mm_beagle.link.security import main

    return main()
