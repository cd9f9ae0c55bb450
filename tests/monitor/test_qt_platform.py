"""The desktop check that names missing Qt/xcb libraries and their Debian packages."""

from __future__ import annotations

import subprocess
import sys

from mm_pc.monitor import qt_platform

LDD = """\
\tlinux-vdso.so.1 (0x00007ffd)
\tlibQt6XcbQpa.so.6 => /venv/PySide6/Qt/lib/libQt6XcbQpa.so.6 (0x00007f)
\tlibxcb-icccm.so.4 => not found
\tlibxcb-keysyms.so.1 => not found
\tlibxcb-cursor.so.0 => not found
\tlibxcb.so.1 => /lib/x86_64-linux-gnu/libxcb.so.1 (0x00007f)
\tlibweird.so.7 => not found
"""


def test_missing_libraries_are_read_from_ldd_and_named_with_their_packages(tmp_path):
    missing = qt_platform.missing_libraries(tmp_path / "libqxcb.so", LDD)
    assert missing == [
        "libweird.so.7", "libxcb-cursor.so.0", "libxcb-icccm.so.4", "libxcb-keysyms.so.1"
    ]
    text = qt_platform.problem(missing)
    assert "sudo apt-get install libxcb-cursor0 libxcb-icccm4 libxcb-keysyms1 (" in text
    assert "apt-file search" in text and "libweird.so.7" in text
    assert "--headless" in text


def test_only_an_x11_session_uses_the_xcb_plugin():
    assert qt_platform.uses_xcb({"DISPLAY": ":0"})
    assert not qt_platform.uses_xcb({"DISPLAY": ":0", "WAYLAND_DISPLAY": "wayland-0"})
    assert not qt_platform.uses_xcb({})
    assert not qt_platform.uses_xcb({"DISPLAY": ":0", "QT_QPA_PLATFORM": "offscreen"})
    assert qt_platform.uses_xcb({"QT_QPA_PLATFORM": "xcb"})


def test_this_install_has_the_plugin_and_the_report_runs():
    plugin = qt_platform.xcb_plugin()
    assert plugin is not None and plugin.name == "libqxcb.so"
    out = subprocess.run(
        [sys.executable, "-m", "mm_pc.monitor.qt_platform"], capture_output=True, text=True,
        timeout=60,
    )
    # 0: every library present; 1: the message with the apt-get line
    assert out.returncode in (0, 1), out.stderr
    assert ("every library" in out.stdout) == (out.returncode == 0)
    assert ("apt-get install" in out.stdout) == (out.returncode == 1)
