"""Mouse Monitor Beagle: the sensor node (1 kHz poller + ROS 2 services)."""
