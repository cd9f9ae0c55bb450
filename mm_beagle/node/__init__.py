"""The mm-beagle ROS 2 node: services, parameters, messages, diagnostics, on-board odometry."""
