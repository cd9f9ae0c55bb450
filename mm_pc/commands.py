"""mm_pc's console scripts (pyproject ``[project.scripts]``).

Each installs the missing-prerequisite hook (:mod:`mm_pc.prerequisites`) and only then
imports its program: a node imports rclpy and the monitor PySide6 at their tops, so a
missing ROS, extra or system library, or a Ctrl-C or SIGTERM while it still imports, must be
caught before that import runs. Importing a package of ours installs nothing.
"""

from __future__ import annotations

from mm_pc import stop_signals


def launch_command(program: str, module: str, node: bool = False) -> int:
    """Stop cleanly on a signal from now on (:mod:`mm_pc.stop_signals`), then hand over to
    :func:`mm_pc.prerequisites.launch` (imported after, as everything else). Every
    console script of ours, mm_beagle's too, starts here.

    A ROS ``node``: ``--help`` or an argument that is not a ROS argument is answered before
    anything of ROS is imported (:mod:`mm_pc.node_usage`), and once the node has stopped
    cleanly the process ends without the interpreter's finalisation
    (:func:`mm_pc.stop_signals.exit_now`: seconds under load)."""
    stop_signals.during_import(program)
    if node:
        from mm_pc import node_usage

        if (code := node_usage.check(program)) is not None:
            return code
    from mm_pc import prerequisites

    code = prerequisites.launch(program, module)
    if node:
        stop_signals.exit_now(code)
    return code


def mm_odometry() -> int:
    """``mm-odometry``: robot pose from the sensor node's samples."""
    return launch_command("mm-odometry", "mm_pc.ros.odometry_node", node=True)


def mm_fusion() -> int:
    """``mm-fusion``: odometry fused with wheels, GPS and the perimeter wire."""
    return launch_command("mm-fusion", "mm_pc.ros.fusion_node", node=True)


def mm_field_sim() -> int:
    """``mm-field-sim``: the simulated mowing run on topics."""
    return launch_command("mm-field-sim", "mm_pc.ros.field_sim_node", node=True)


def mm_monitor() -> int:
    """``mm-monitor``: the Qt monitor."""
    return launch_command("mm-monitor", "mm_pc.monitor.app")


def mm_bench() -> int:
    """``mm-bench``: the benchmarks (JSON)."""
    return launch_command("mm-bench", "mm_pc.bench.cli")


def mm_otos_settings() -> int:
    """``mm-otos-settings``: an OTOS's linear scalar and offset from a calibration file."""
    return launch_command("mm-otos-settings", "mm_pc.core.otos_settings")
