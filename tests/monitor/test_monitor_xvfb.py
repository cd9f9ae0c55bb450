"""One smoke test under a real X server: Xvfb, the xcb platform plugin, a real key press.

Offscreen tests cannot show what only a real display does (window geometry handed
out by the X server, the shortcut map, focus). This starts ``Xvfb`` on a free display
(``-displayfd``), runs the monitor's window in a child process there (no node: the
window is offline) and checks that it is 1024x700 on screen and that Ctrl+E pressed
while the sample-rate field has the focus reaches the export. Skipped with the
reason when Xvfb is not installed. Every wait is bounded.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import textwrap

import pytest

pytest.importorskip("PySide6")

XVFB = shutil.which("Xvfb")

CHILD = textwrap.dedent(
    """
    import sys
    from pathlib import Path
    from PySide6.QtCore import Qt, QTimer
    from PySide6.QtTest import QTest
    from PySide6.QtWidgets import QApplication
    from mm_pc.monitor.context import MonitorConfig, MonitorContext
    from mm_pc.monitor.main_window import MainWindow
    from mm_pc.monitor.model.session import MonitorSession

    app = QApplication([])
    assert app.platformName() == "xcb", app.platformName()
    out = Path(sys.argv[1])
    ctx = MonitorContext(MonitorSession(), None, MonitorConfig(calibration_file=out / "c.yaml"))
    w = MainWindow(ctx)
    exported = []
    w.export_action.triggered.disconnect()
    w.export_action.triggered.connect(lambda: exported.append(1))
    w.resize(1024, 700)
    w.show()
    QTest.qWaitForWindowExposed(w, 5000)
    w.activateWindow()
    QTest.qWaitForWindowActive(w, 5000)
    field = w.rate_editor.edit
    field.setFocus()
    QTest.qWait(100)
    QTest.keyClick(field, Qt.Key_E, Qt.ControlModifier)
    QTest.qWait(100)
    w.grab().save(str(out / "xvfb.png"))
    print(f"size {w.width()}x{w.height()} exported {len(exported)} focus {field.hasFocus()}")
    w.close()
    """
)


@pytest.mark.skipif(XVFB is None, reason="Xvfb is not installed (apt-get install xvfb)")
def test_window_under_a_real_x_server(tmp_path):
    read, write = os.pipe()
    xvfb = subprocess.Popen(
        [XVFB, "-displayfd", str(write), "-screen", "0", "1280x800x24", "-nolisten", "tcp"],
        pass_fds=(write,), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
    )  # fmt: skip
    os.close(write)
    try:
        with os.fdopen(read) as f:
            display = f.readline().strip()  # Xvfb writes its display number when ready
        assert display, "Xvfb did not start"
        env = dict(os.environ, DISPLAY=f":{display}", QT_QPA_PLATFORM="xcb")
        env.pop("WAYLAND_DISPLAY", None)
        out = subprocess.run(
            [sys.executable, "-c", CHILD, str(tmp_path)],
            env=env, capture_output=True, text=True, timeout=60,
        )  # fmt: skip
        if "could not load the Qt platform plugin" in out.stderr.lower():
            pytest.skip(f"Qt's xcb plugin cannot load here: {out.stderr.strip()[:200]}")
        assert out.returncode == 0, out.stderr
        assert "size 1024x700" in out.stdout, out.stdout
        assert "exported 1" in out.stdout, out.stdout  # Ctrl+E with the focus in a field
        assert (tmp_path / "xvfb.png").stat().st_size > 1000
    finally:
        xvfb.terminate()
        try:
            xvfb.wait(10)
        except subprocess.TimeoutExpired:
            xvfb.kill()
            xvfb.wait(5)
