"""Test-wide set-up: every run talks ROS 2 only to itself.

A random ROS_DOMAIN_ID per pytest session and localhost-only discovery, set
before anything imports rclpy, so parallel runs (or a node left running by
hand) never see each other and nothing leaves this machine.
"""

from __future__ import annotations

import os
import random

os.environ["ROS_DOMAIN_ID"] = str(random.randint(120, 220))
os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
os.environ.pop("ROS_STATIC_PEERS", None)
os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
