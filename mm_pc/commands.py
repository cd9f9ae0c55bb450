"""mm_pc's console scripts (pyproject ``[project.scripts]``).

Each installs the missing-prerequisite hook (:mod:`mm_pc.prerequisites`) and only then
imports its program: a node imports rclpy and the monitor PySide6 at their tops, so a
missing ROS, extra or system library, or a Ctrl-C or SIGTERM while it still imports, must be
caught before that import runs. Importing a package of ours installs nothing.
"""

from __future__ import annotations

from mm_pc import stop_signals


def _launch(program: str, module: str) -> int:
    """Stop cleanly on a signal from now on (:mod:`mm_pc.stop_signals`), then hand over to
    :func:`mm_pc.prerequisites.launch` (imported after, as everything else)."""
    stop_signals.during_import(program)
    from mm_pc import prerequisites

    return prerequisites.launch(program, module)


def mm_odometry() -> int:
    """``mm-odometry``: robot pose from the sensor node's samples."""
    return _launch("mm-odometry", "mm_pc.ros.odometry_node")


def mm_fusion() -> int:
    """``mm-fusion``: odometry fused with wheels, GPS and the perimeter wire."""
    return _launch("mm-fusion", "mm_pc.ros.fusion_node")


def mm_field_sim() -> int:
    """``mm-field-sim``: the simulated mowing run on topics."""
    return _launch("mm-field-sim", "mm_pc.ros.field_sim_node")


def mm_monitor() -> int:
    """``mm-monitor``: the Qt monitor."""
    return _launch("mm-monitor", "mm_pc.monitor.app")


def mm_bench() -> int:
    """``mm-bench``: the benchmarks (JSON)."""
    return _launch("mm-bench", "mm_pc.bench.cli")


def mm_otos_settings() -> int:
    """``mm-otos-settings``: an OTOS's linear scalar and offset from a calibration file."""
    return _launch("mm-otos-settings", "mm_pc.core.otos_settings")
