"""A program started without ROS 2 says how to get it (exit 2), instead of a traceback.

``pip install .`` gives the mm-* commands but not rclpy: ROS 2 is not on PyPI under its
own names (the ros-jazzy-* wheels ./compile uses exist for x86_64 only), and the message
packages mm_interfaces/tf2_msgs are built by ./compile. A node module imports rclpy at
its top, so the error comes before any ``main`` could catch it; this hook, installed when
``mm_pc`` or ``mm_beagle`` is imported, turns exactly that uncaught error (a missing ROS
module) into a message and exit status 2. Anything else goes to the previous hook, and
code that imports a node module inside ``try`` still gets its ImportError.
"""

from __future__ import annotations

import os
import sys

# Top-level names that come with ROS 2 (or with ./compile's interface builds).
ROS_MODULES = frozenset(
    {
        "rclpy",
        "rcl_interfaces",
        "rosidl_runtime_py",
        "rosidl_parser",
        "builtin_interfaces",
        "ament_index_python",
        "launch",
        "launch_ros",
        "tf2_ros",
        "rosbag2_py",
        "mm_interfaces",
        "tf2_msgs",
    }
)

EXIT_NO_ROS = 2


def is_ros_module(name: str | None) -> bool:
    """Whether a missing module ``name`` is part of ROS 2 (a message package counts)."""
    top = (name or "").partition(".")[0]
    return top in ROS_MODULES or top.endswith(("_msgs", "_srvs"))


def message(program: str, missing: str) -> str:
    """What to tell a user who started ``program`` without the ROS module ``missing``."""
    built_here = missing in ("mm_interfaces", "tf2_msgs")
    what = (
        f"the message package {missing}, which ./compile builds"
        if built_here
        else f"ROS 2 Jazzy ({missing} is missing)"
    )
    return (
        f"{program}: needs {what}.\n"
        "  ROS 2 is not a plain PyPI package (rclpy comes as ros-jazzy-* wheels, x86_64 only).\n"
        "  Either run './compile setup' in the repository and 'source install/setup.bash',\n"
        "  or install ROS 2 Jazzy (/opt/ros/jazzy), 'source /opt/ros/jazzy/setup.bash' and run\n"
        "  './compile mm_b' or './compile mm_p' (docs/system-ros.md)."
    )


def _program() -> str:
    """The command the user typed: the console script, or for ``python -m M`` the script
    whose entry point is M (else M itself)."""
    spec = getattr(sys.modules.get("__main__"), "__spec__", None)
    if spec is None:  # a console script, or python -c
        name = os.path.basename(sys.argv[0]) if sys.argv and sys.argv[0] else ""
        return name if name and name != "-c" else "mouse monitor"
    from importlib.metadata import entry_points

    for ep in entry_points(group="console_scripts"):
        if ep.value.partition(":")[0] == spec.name:
            return ep.name
    return spec.name


def _hook(previous):
    def hook(exc_type, exc, tb):
        if issubclass(exc_type, ModuleNotFoundError) and is_ros_module(exc.name):
            sys.stderr.write(message(_program(), exc.name.partition(".")[0]) + "\n")
            sys.stderr.flush()
            sys.stdout.flush()
            # The interpreter would exit 1 after any hook; nothing has started yet.
            os._exit(EXIT_NO_ROS)
        previous(exc_type, exc, tb)

    hook.mm_ros_required = True
    return hook


def install() -> None:
    """Install the hook once (both packages call this on import)."""
    if not getattr(sys.excepthook, "mm_ros_required", False):
        sys.excepthook = _hook(sys.excepthook)
