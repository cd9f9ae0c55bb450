"""Are the system libraries Qt's X11 (xcb) platform plugin needs installed?

PySide6's wheel brings Qt but not the X11/xcb libraries of the desktop. On a
Debian desktop without some of them Qt only says that it "could not load the
Qt platform plugin xcb" (naming at most libxcb-cursor0, which alone does not
help) and aborts with no window. ``ldd`` on the plugin lists exactly what is
missing; :data:`DEBIAN_PACKAGES` names the package that ships each library
(found with ``dpkg -S`` on Debian 12, kept in ``tools/system-packages.txt``). Run
``python -m mm_pc.monitor.qt_platform`` for a report (``--all``: every Qt file the monitor
loads, headless and windowed, whatever the display); ``./compile setup`` and ``mm-monitor``
run the same check, and the message names a command that works without a window.
"""

from __future__ import annotations

import importlib.util
import os
import sys
from pathlib import Path

from mm_pc.prerequisites import library_packages, qt_files, unresolved

__all__ = ["DEBIAN_PACKAGES", "missing_libraries", "problem", "uses_xcb", "xcb_plugin"]

#: soname -> Debian 12 package, from the project's one package list
#: (tools/system-packages.txt: every library ldd resolves for PySide6's Qt and its plugins that
#: a minimal, non-desktop Debian may lack)
DEBIAN_PACKAGES = library_packages()


def xcb_plugin() -> Path | None:
    """PySide6's libqxcb.so, or None (PySide6 missing, or a build without it)."""
    spec = importlib.util.find_spec("PySide6")
    if spec is None or not spec.submodule_search_locations:
        return None
    for root in spec.submodule_search_locations:
        path = Path(root) / "Qt" / "plugins" / "platforms" / "libqxcb.so"
        if path.exists():
            return path
    return None


def uses_xcb(env: dict[str, str] | None = None) -> bool:
    """Whether Qt will pick the X11 plugin: QT_QPA_PLATFORM=xcb, or unset with $DISPLAY
    and no Wayland session."""
    env = os.environ if env is None else env
    platform = env.get("QT_QPA_PLATFORM", "")
    if platform:
        return platform.split(":")[0] == "xcb"
    return bool(env.get("DISPLAY")) and not env.get("WAYLAND_DISPLAY")


def missing_libraries(plugin: Path, ldd_output: str | None = None) -> list[str]:
    """The sonames ``ldd plugin`` reports as 'not found' (``ldd_output`` for tests)."""
    return unresolved([plugin], ldd_output)  # no ldd: nothing (Qt says what it misses)


def headless_commands(cwd: Path | None = None) -> str:
    """Commands this user has that run the monitor without a window: the demo through
    ./compile (in a clone; relative when run from its folder), and this environment's
    mm-monitor by its full path (the venv's bin is not on PATH after a plain ./compile)."""
    root = Path(__file__).resolve().parents[2]
    out = []
    if (root / "compile").is_file():
        here = (cwd or Path.cwd()).resolve() == root
        out.append(f"{'./compile' if here else root / 'compile'} demo --headless")
    script = Path(sys.executable).parent / "mm-monitor"
    out.append(f"{script if script.exists() else 'mm-monitor'} --headless")
    return ", or ".join(out)


def problem(missing: list[str]) -> str:
    """The message for missing libraries: what, and the apt-get line that installs them."""
    packages = sorted({DEBIAN_PACKAGES.get(lib, "") for lib in missing} - {""})
    unknown = [lib for lib in missing if lib not in DEBIAN_PACKAGES]
    text = (
        "Qt's X11 platform plugin cannot load: these system libraries are missing: "
        + ", ".join(missing)
        + "."
    )
    if packages:
        text += " Install them with:  sudo apt-get install " + " ".join(packages)
    if unknown:
        text += " (find the package of " + ", ".join(unknown) + " with apt-file search)"
    return text + f". Meanwhile, without a window: {headless_commands()}."


def check() -> str:
    """'' when the window can open as far as libraries go, else :func:`problem`'s text."""
    if not uses_xcb():
        return ""
    plugin = xcb_plugin()
    if plugin is None:
        return ""
    missing = missing_libraries(plugin)
    return problem(missing) if missing else ""


def main(argv: list[str] | None = None) -> int:
    """Print the check's verdict; exit 1 when libraries are missing. ``--all``: every Qt
    file the monitor loads, headless and windowed (X11 and Wayland), whatever the display."""
    argv = sys.argv[1:] if argv is None else argv
    if argv not in ([], ["--all"]):
        print("usage: python -m mm_pc.monitor.qt_platform [--all]", file=sys.stderr)
        return 2
    if argv == ["--all"]:
        files = qt_files()
        if not files:
            print("PySide6 is not installed here (or has none of the Qt files the monitor loads)")
            return 1
        missing = unresolved(files)
        if missing:
            print(problem(missing).replace("X11 platform plugin", "monitor (headless or windowed)"))
            return 1
        print(f"Qt has every system library the monitor loads, headless and in a window "
              f"(ldd on {len(files)} files of {files[0].parents[2]})")  # fmt: skip
        return 0
    plugin = xcb_plugin()
    if plugin is None:
        print("PySide6 has no xcb plugin here (or PySide6 is not installed)")
        return 0
    missing = missing_libraries(plugin)
    if missing:
        print(problem(missing))
        return 1
    print(f"Qt's X11 platform plugin has every library it needs ({plugin})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
