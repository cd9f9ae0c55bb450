"""Mouse Monitor PC: pure math (no Qt, no ROS) and, later, the Qt monitor."""
