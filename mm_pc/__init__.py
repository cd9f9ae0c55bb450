"""Mouse Monitor PC: core/ (pure math), sim/ (ground truth), ros/ (the nodes' rclpy adapters),
monitor/ (the Qt monitor), bench/ (mm-bench)."""
