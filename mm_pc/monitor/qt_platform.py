"""Are the system libraries Qt's X11 (xcb) platform plugin needs installed?

PySide6's wheel brings Qt but not the X11/xcb libraries of the desktop. On a
Debian desktop without some of them Qt only says that it "could not load the
Qt platform plugin xcb" (naming at most libxcb-cursor0, which alone does not
help) and aborts with no window. ``ldd`` on the plugin lists exactly what is
missing; :data:`DEBIAN_PACKAGES` names the package that ships each library
(found with ``dpkg -S`` on Debian 12). Run ``python -m mm_pc.monitor.qt_platform``
for a report; ``./compile setup`` and ``mm-monitor`` run the same check.
"""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
from pathlib import Path

__all__ = ["DEBIAN_PACKAGES", "missing_libraries", "problem", "uses_xcb", "xcb_plugin"]

#: soname -> Debian 12 package, for every library ldd resolves for PySide6 6.x's libqxcb.so
#: that a minimal (non-desktop) Debian may lack.
DEBIAN_PACKAGES = {
    "libEGL.so.1": "libegl1",
    "libGL.so.1": "libgl1",
    "libGLX.so.0": "libglx0",
    "libGLdispatch.so.0": "libglvnd0",
    "libX11-xcb.so.1": "libx11-xcb1",
    "libX11.so.6": "libx11-6",
    "libXau.so.6": "libxau6",
    "libXdmcp.so.6": "libxdmcp6",
    "libdbus-1.so.3": "libdbus-1-3",
    "libfontconfig.so.1": "libfontconfig1",
    "libfreetype.so.6": "libfreetype6",
    "libglib-2.0.so.0": "libglib2.0-0",
    "libgthread-2.0.so.0": "libglib2.0-0",
    "libpng16.so.16": "libpng16-16",
    "libxcb-cursor.so.0": "libxcb-cursor0",
    "libxcb-icccm.so.4": "libxcb-icccm4",
    "libxcb-image.so.0": "libxcb-image0",
    "libxcb-keysyms.so.1": "libxcb-keysyms1",
    "libxcb-randr.so.0": "libxcb-randr0",
    "libxcb-render-util.so.0": "libxcb-render-util0",
    "libxcb-render.so.0": "libxcb-render0",
    "libxcb-shape.so.0": "libxcb-shape0",
    "libxcb-shm.so.0": "libxcb-shm0",
    "libxcb-sync.so.1": "libxcb-sync1",
    "libxcb-util.so.1": "libxcb-util1",
    "libxcb-xfixes.so.0": "libxcb-xfixes0",
    "libxcb-xkb.so.1": "libxcb-xkb1",
    "libxcb.so.1": "libxcb1",
    "libxkbcommon-x11.so.0": "libxkbcommon-x11-0",
    "libxkbcommon.so.0": "libxkbcommon0",
}


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
    if ldd_output is None:
        try:
            ldd_output = subprocess.run(
                ["ldd", str(plugin)], capture_output=True, text=True, timeout=30
            ).stdout
        except (OSError, subprocess.SubprocessError):
            return []  # no ldd: nothing to say; Qt reports what it misses itself
    return sorted(
        {line.split()[0] for line in ldd_output.splitlines() if "not found" in line}
    )


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
    return text + ". Without a window: mm-monitor --headless."


def check() -> str:
    """'' when the window can open as far as libraries go, else :func:`problem`'s text."""
    if not uses_xcb():
        return ""
    plugin = xcb_plugin()
    if plugin is None:
        return ""
    missing = missing_libraries(plugin)
    return problem(missing) if missing else ""


def main() -> int:
    """Print the check's verdict; exit 1 when libraries are missing."""
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
