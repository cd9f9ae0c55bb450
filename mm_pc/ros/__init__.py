"""rclpy adapters (never Qt): spinning, parameters, messages, the thin nodes."""
