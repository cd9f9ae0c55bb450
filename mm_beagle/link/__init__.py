"""The zenoh board link: mm-beagle-agent, the node's remote backend, credentials (no ROS)."""
