"""The board side without ROS: the 1 kHz poller, its shared memory, chips, the sim backend."""
