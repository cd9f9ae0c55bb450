"""A program started without ROS 2, an extra or a system library says how to get it: exit 2,
no traceback.

``pip install .`` gives the mm-* commands but not rclpy: ROS 2 is not on PyPI under its
own names (the ros-jazzy-* wheels ./compile uses exist for x86_64 only), and the message
packages mm_interfaces/tf2_msgs are built by ./compile. Likewise mm-monitor needs the
``monitor`` extra (PySide6, pyqtgraph, mcap). A node module imports rclpy at its top, so
the error comes before any ``main`` could catch it; this hook, installed by each console
script's launcher (``mm_pc.commands``, ``mm_beagle.commands``) before it imports its program,
turns exactly that uncaught error (a missing module of ROS or
of an extra) into a message and exit status 2. Anything else goes to the previous hook,
and code that imports such a module inside ``try`` still gets its ImportError.

The same for a system library: PySide6's Qt loads libEGL, libglib, libxkbcommon... from the
system, and on a bare Debian importing PySide6 fails with ``ImportError: libEGL.so.1: cannot
open shared object file``. The hook names the Debian package from the project's one package
list, ``tools/system-packages.txt`` (which ./compile installs), together with every other
package whose library ``ldd`` finds missing among the Qt files the monitor loads, so one
``sudo apt-get install`` line fixes it at once.
"""

from __future__ import annotations

import importlib
import importlib.util
import os
import re
import sys
from functools import cache
from pathlib import Path

from mm_pc import stop_signals

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

#: the project's list of Debian/Ubuntu packages (in a clone; a wheel install has none)
SYSTEM_PACKAGES = Path(__file__).resolve().parents[1] / "tools" / "system-packages.txt"
NEEDS = ("setup", "headless", "window", "test")

#: PySide6's files the monitor loads (globs under the PySide6 package), by need: ldd on
#: them lists every system library Qt needs (tools/system-packages.txt says how they were
#: found). Absent ones are skipped (PySide6 versions differ).
QT_FILES = {
    "headless": (
        "Qt/lib/libQt6Core.so.6", "Qt/lib/libQt6Gui.so.6", "Qt/lib/libQt6Widgets.so.6",
        "Qt/lib/libQt6OpenGL.so.6", "Qt/lib/libQt6OpenGLWidgets.so.6", "Qt/lib/libQt6Svg.so.6",
        "Qt/lib/libQt6Test.so.6", "Qt/lib/libQt6DBus.so.6",
        "Qt/plugins/platforms/libqoffscreen.so", "Qt/plugins/platforms/libqminimal.so",
        "Qt/plugins/imageformats/libqsvg.so", "Qt/plugins/iconengines/libqsvgicon.so",
    ),
    "window": (
        "Qt/lib/libQt6XcbQpa.so.6", "Qt/lib/libQt6WaylandClient.so.6",
        "Qt/plugins/platforms/libqxcb.so", "Qt/plugins/platforms/libqwayland*.so",
        "Qt/plugins/xcbglintegrations/*.so",
        "Qt/plugins/wayland-graphics-integration-client/libqt-plugin-wayland-egl.so",
        "Qt/plugins/wayland-shell-integration/*.so", "Qt/plugins/wayland-decoration-client/*.so",
        "Qt/plugins/platforminputcontexts/libcompose*.so",
        "Qt/plugins/platforminputcontexts/libibus*.so",
    ),
}  # fmt: skip

_ROS_LIBRARY = re.compile(
    r"lib(rcl|rmw|rcutils|rcpputils|rosidl|fastrtps|fastcdr|tracetools)|.*__rosidl_"
)
_NO_LIBRARY = re.compile(r"([\w.+-]+\.so(?:\.[\w]+)*): cannot open shared object file")


def system_packages(path: Path | None = None) -> list[tuple[str, str, tuple[str, ...]]]:
    """``(package, need, sonames)`` per line of the package list; ``package`` may be
    ``name|alternative``. A malformed line raises ValueError naming it."""
    path = SYSTEM_PACKAGES if path is None else path
    out = []
    for n, line in enumerate(path.read_text().splitlines(), 1):
        words = line.partition("#")[0].split()
        if not words:
            continue
        if len(words) < 2 or words[1] not in NEEDS:
            raise ValueError(f"{path.name} line {n}: expected 'PACKAGE NEED [SONAMES]' with "
                             f"NEED one of {', '.join(NEEDS)}: {line.strip()!r}")  # fmt: skip
        out.append((words[0], words[1], tuple(words[2:])))
    return out


@cache
def library_packages() -> dict[str, str]:
    """soname -> the Debian package that ships it (the first name of an alternative), from
    the package list; empty where the list is absent (a wheel install) or unreadable."""
    try:
        entries = system_packages()
    except (OSError, ValueError):
        return {}
    return {so: pkg.partition("|")[0] for pkg, _need, sonames in entries for so in sonames}


def missing_library(exc: BaseException) -> str | None:
    """The soname an ImportError/OSError says the dynamic loader could not find, else None."""
    match = _NO_LIBRARY.search(str(exc))
    return match.group(1) if match else None


def _pyside_dir() -> Path | None:
    try:
        spec = importlib.util.find_spec("PySide6")
    except (ImportError, ValueError):
        return None
    if spec is None or not spec.submodule_search_locations:
        return None
    return Path(next(iter(spec.submodule_search_locations)))


def unresolved(files: list[Path], ldd_output: str | None = None) -> list[str]:
    """The sonames ``ldd`` reports as 'not found' for ``files`` (``ldd_output`` for tests)."""
    if ldd_output is None:
        if not files:
            return []
        import subprocess  # here: every command's launcher imports this module

        try:
            ldd_output = subprocess.run(
                ["ldd", *map(str, files)], capture_output=True, text=True, timeout=60
            ).stdout
        except (OSError, subprocess.SubprocessError):
            return []  # no ldd: nothing more to say
    return sorted({ln.split()[0] for ln in ldd_output.splitlines() if "not found" in ln})


def qt_files(needs: tuple[str, ...] = ("headless", "window")) -> list[Path]:
    """PySide6's files of :data:`QT_FILES` for ``needs`` that this install has."""
    root = _pyside_dir()
    if root is None:
        return []
    return sorted({f for need in needs for pattern in QT_FILES[need] for f in root.glob(pattern)})


def qt_missing_libraries(needs: tuple[str, ...] = ("headless", "window")) -> list[str]:
    """Every system library that PySide6's files for ``needs`` cannot load (ldd)."""
    return unresolved(qt_files(needs))


def install_line(sonames: list[str]) -> tuple[str, list[str]]:
    """``sudo apt-get install ...`` for the packages of ``sonames`` ('' if none is known), and
    the sonames whose package the list does not know."""
    packages = library_packages()
    known = sorted({packages[so] for so in sonames if so in packages})
    unknown = [so for so in sonames if so not in packages]
    return ("sudo apt-get install " + " ".join(known) if known else ""), unknown


def library_message(program: str, soname: str, others: list[str] | None = None) -> str:
    """What to tell a user whose ``program`` could not load the system library ``soname``;
    ``others``: more libraries found missing (ldd on the Qt files), named in the same line."""
    if soname not in library_packages() and _ROS_LIBRARY.match(soname):
        return (
            f"{program}: cannot start: the ROS 2 library {soname} is not on the library path.\n"
            "  Start it from a shell that ran 'source install/setup.bash' (./compile setup\n"
            "  writes it), or with a system ROS 'source /opt/ros/jazzy/setup.bash' first."
        )
    if others is None:  # a Qt library: name every other one Qt misses in the same line
        others = qt_missing_libraries() if soname in library_packages() else []
    missing = [soname, *sorted(set(others) - {soname})]
    line, unknown = install_line(missing)
    text = f"{program}: cannot start: the system library {soname} is missing"
    if len(missing) > 1:
        text += f" (and {len(missing) - 1} more the monitor's Qt needs: {', '.join(missing[1:])})"
    text += ".\n"
    if line:
        text += f"  Install {'it' if len(missing) == 1 else 'them'} with:  {line}\n"
    if unknown:
        text += f"  Find the package of {', '.join(unknown)} with:  apt-file search {unknown[0]}\n"
    return text + (
        "  (./compile installs every package of tools/system-packages.txt before it builds,\n"
        "  unless MM_SKIP_SYSTEM_PACKAGES is set.)"
    )


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


_launched: str | None = None  # the program prerequisites.launch started


def _program() -> str:
    """The command the user typed: the program :func:`launch` started, the console script
    (``sys.argv[0]``), else the module run with ``python -m``."""
    if _launched:
        return _launched
    spec = getattr(sys.modules.get("__main__"), "__spec__", None)
    if spec is None:  # a console script, or python -c
        name = os.path.basename(sys.argv[0]) if sys.argv and sys.argv[0] else ""
        return name if name and name != "-c" else "mouse monitor"
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
        if issubclass(exc_type, KeyboardInterrupt) or _interrupted(exc) or stop_signals.raised():
            # Ctrl-C or SIGTERM that got past launch() (raised inside a Qt callback, or a
            # program run with python -m): a stop like any other, no traceback, children
            # ended; 0 as the nodes' Ctrl-C gives.
            sys.stderr.write(stop_signals.stop_line(_program(), stop_signals.stopped_by()) + "\n")
            sys.stderr.flush()
            sys.stdout.flush()
            stop_signals.end_children()
            os._exit(EXIT_INTERRUPTED)
        text = None
        if issubclass(exc_type, ModuleNotFoundError) and exc.name:
            text = message(_program(), exc.name.partition(".")[0])
        elif issubclass(exc_type, ImportError) and (soname := missing_library(exc)):
            text = library_message(_program(), soname)
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
    """Install the hook once (the console scripts' launchers call this; importing a package
    of ours does not)."""
    if not getattr(sys.excepthook, "mm_prerequisites", False):
        sys.excepthook = _hook(sys.excepthook)


def launch(program: str, module: str) -> int:
    """A console script's body: install the hook, then import ``module`` and return what its
    ``main()`` returns (the exit status). The import comes after the hook, so a missing ROS,
    extra or system library at the program's top is a message and exit 2 that names
    ``program`` (also when started as ``python -m``). SIGINT and SIGTERM stop it at any
    moment with one line and exit 0, its children ended too (:mod:`mm_pc.stop_signals`)."""
    global _launched
    _launched = program
    install()
    stop_signals.during_import(program)  # before anything else is imported
    main = importlib.import_module(module).main
    stop_signals.while_running(program)
    try:
        return main()
    except KeyboardInterrupt:  # SIGINT or SIGTERM (stop_signals), cleaned up on the way here
        stop_signals.ignore_more()
        print(stop_signals.stop_line(program, stop_signals.stopped_by()), file=sys.stderr)
        return stop_signals.EXIT_STOPPED
    finally:
        stop_signals.ignore_more()
        stop_signals.end_children()
