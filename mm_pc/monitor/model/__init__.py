"""The monitor's model: no Qt, no rclpy (readings, history, session)."""
