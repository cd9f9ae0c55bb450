"""Ground truth: the robot motion simulator and the simulated mowing-field run."""
