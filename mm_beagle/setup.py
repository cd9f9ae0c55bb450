"""colcon (ament_python) build of the ROS package mm_beagle: the recipe of ../mm_pc/setup.py.

Only colcon runs this file; pip's wheel carries it as the inert module mm_beagle.setup.
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

if __name__ == "__main__":
    _path = Path(__file__).resolve().parent.parent / "mm_pc" / "setup.py"
    _spec = importlib.util.spec_from_file_location("mm_pc_ros_setup", _path)
    _recipe = importlib.util.module_from_spec(_spec)
    _spec.loader.exec_module(_recipe)
    _recipe.ros_package_setup("mm_beagle")
