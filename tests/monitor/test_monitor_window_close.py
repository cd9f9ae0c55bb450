"""Closing the main window closes the modeless windows it opened (the log), so none stays
on screen after it: a leftover log dialog kept later tests' views from getting mouse moves."""

from __future__ import annotations

import pytest

pytest.importorskip("PySide6")

from mm_pc.monitor.context import MonitorConfig, MonitorContext
from mm_pc.monitor.main_window import MainWindow
from mm_pc.monitor.model.session import MonitorSession
from mm_pc.monitor.widgets.log_dialog import LogDialog


def test_closing_the_window_closes_its_log_dialog(qtbot, tmp_path):
    config = MonitorConfig(rate_hz=15.0, calibration_file=tmp_path / "cal.yaml")
    window = MainWindow(MonitorContext(MonitorSession(), None, config), None)
    qtbot.addWidget(window)
    window.show()
    window.open_log_dialog()
    log = window.findChild(LogDialog)
    qtbot.waitExposed(log)
    assert log.isVisible() and not log.isModal()
    window.close()
    assert not window.isVisible()
    qtbot.waitUntil(lambda: window.findChild(LogDialog) is None or not log.isVisible(),
                    timeout=2000)
