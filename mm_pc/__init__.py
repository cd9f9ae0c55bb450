"""Mouse Monitor PC: pure math (no Qt, no ROS) and, later, the Qt monitor."""

from . import ros_required

ros_required.install()  # started without ROS: a message and exit 2, not a traceback
