"""Mouse Monitor PC: pure math (no Qt, no ROS) and, later, the Qt monitor."""

from . import prerequisites

prerequisites.install()  # started without ROS or an extra: a message and exit 2
