"""Mouse Monitor Beagle: the sensor side. poller/ (the 1 kHz poller, no ROS), link/ (the zenoh
board link), node/ (the mm-beagle ROS 2 node), tools/ (harness, benches, mm-watch, demo)."""
