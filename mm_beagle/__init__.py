"""Mouse Monitor Beagle: the sensor node (1 kHz poller + ROS 2 services)."""

from mm_pc import prerequisites

prerequisites.install()  # started without ROS or an extra: a message and exit 2
