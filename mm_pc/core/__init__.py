"""Pure math: numpy, yaml and pln2033's units only; no ROS, no Qt."""
