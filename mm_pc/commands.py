"""mm_pc's console scripts (pyproject ``[project.scripts]``).

Each installs the missing-prerequisite hook (:mod:`mm_pc.prerequisites`) and only then
imports its program: a node imports rclpy and the monitor PySide6 at their tops, so a
missing ROS, extra or system library, or a Ctrl-C while it still imports, must be caught
before that import runs. Importing a package of ours installs nothing.
"""

from __future__ import annotations

from mm_pc import prerequisites


def mm_odometry() -> int:
    """``mm-odometry``: robot pose from the sensor node's samples."""
    return prerequisites.launch("mm-odometry", "mm_pc.ros.odometry_node")


def mm_fusion() -> int:
    """``mm-fusion``: odometry fused with wheels, GPS and the perimeter wire."""
    return prerequisites.launch("mm-fusion", "mm_pc.ros.fusion_node")


def mm_field_sim() -> int:
    """``mm-field-sim``: the simulated mowing run on topics."""
    return prerequisites.launch("mm-field-sim", "mm_pc.ros.field_sim_node")


def mm_monitor() -> int:
    """``mm-monitor``: the Qt monitor."""
    return prerequisites.launch("mm-monitor", "mm_pc.monitor.app")


def mm_bench() -> int:
    """``mm-bench``: the benchmarks (JSON)."""
    return prerequisites.launch("mm-bench", "mm_pc.bench.cli")


def mm_otos_settings() -> int:
    """``mm-otos-settings``: an OTOS's linear scalar and offset from a calibration file."""
    return prerequisites.launch("mm-otos-settings", "mm_pc.core.otos_settings")
