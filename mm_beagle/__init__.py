"""Mouse Monitor Beagle: the sensor node (1 kHz poller + ROS 2 services)."""

from mm_pc import ros_required

ros_required.install()  # started without ROS: a message and exit 2, not a traceback
