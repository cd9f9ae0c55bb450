"""A program started without ROS 2 (or without an extra) says how to get it: exit 2, no traceback.

``pip install .`` gives the mm-* commands but not rclpy: ROS 2 is not on PyPI under its
own names (the ros-jazzy-* wheels ./compile uses exist for x86_64 only), and the message
packages mm_interfaces/tf2_msgs are built by ./compile. Likewise mm-monitor needs the
``monitor`` extra (PySide6, pyqtgraph, mcap). A node module imports rclpy at its top, so
the error comes before any ``main`` could catch it; this hook, installed when ``mm_pc`` or
``mm_beagle`` is imported, turns exactly that uncaught error (a missing module of ROS or
of an extra) into a message and exit status 2. Anything else goes to the previous hook,
and code that imports such a module inside ``try`` still gets its ImportError.
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
# Top-level names -> the pyproject extra that installs them.
EXTRA_MODULES = {
    "PySide6": "monitor",
    "shiboken6": "monitor",
    "pyqtgraph": "monitor",
    "mcap": "monitor",
    "spidev": "beagle",
}

EXIT_MISSING = 2
EXIT_INTERRUPTED = 0


def is_ros_module(name: str | None) -> bool:
    """Whether a missing module ``name`` is part of ROS 2 (a message package counts)."""
    top = (name or "").partition(".")[0]
    return top in ROS_MODULES or top.endswith(("_msgs", "_srvs"))


def message(program: str, missing: str) -> str | None:
    """What to tell a user who started ``program`` without the module ``missing`` (its
    top-level name), or None when it is neither ROS nor an extra's."""
    if missing in EXTRA_MODULES:
        extra = EXTRA_MODULES[missing]
        return (
            f"{program}: needs {missing}, from the '{extra}' extra: "
            f"pip install 'mouse-monitor[{extra}]' (in a clone: pip install '.[{extra}]'),\n"
            f"  or set up with './compile {'mm_p' if extra == 'monitor' else 'mm_b'}' "
            "(or './compile setup' for everything)."
        )
    if not is_ros_module(missing):
        return None
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


def _interrupted(exc: BaseException | None) -> bool:
    """``exc`` is a Ctrl-C, or was caused by one: a KeyboardInterrupt that lands while a
    class body is built (a dataclass during an import) reaches the hook wrapped in a
    RuntimeError."""
    seen = 0
    while exc is not None and seen < 20:
        if isinstance(exc, KeyboardInterrupt):
            return True
        exc = exc.__cause__ or exc.__context__
        seen += 1
    return False


def _hook(previous):
    def hook(exc_type, exc, tb):
        if issubclass(exc_type, KeyboardInterrupt) or _interrupted(exc):
            # Ctrl-C before a program installed its own handler (a node still importing
            # rclpy): a stop like any other, no traceback; 0 as the nodes' Ctrl-C gives.
            sys.stderr.write(f"{_program()}: stopped by Ctrl-C\n")
            sys.stderr.flush()
            sys.stdout.flush()
            os._exit(EXIT_INTERRUPTED)
        if issubclass(exc_type, ModuleNotFoundError) and exc.name:
            text = message(_program(), exc.name.partition(".")[0])
            if text is not None:
                sys.stderr.write(text + "\n")
                sys.stderr.flush()
                sys.stdout.flush()
                # The interpreter would exit 1 after any hook; nothing has started yet.
                os._exit(EXIT_MISSING)
        previous(exc_type, exc, tb)

    hook.mm_prerequisites = True
    return hook


def install() -> None:
    """Install the hook once (both packages call this on import)."""
    if not getattr(sys.excepthook, "mm_prerequisites", False):
        sys.excepthook = _hook(sys.excepthook)
