"""``python -m mm_beagle.node``: mm-beagle exactly as its console script starts it (the
missing-prerequisite hook first, so a Ctrl-C while rclpy still imports is a clean stop)."""

import sys

from mm_beagle.commands import mm_beagle

sys.exit(mm_beagle())
