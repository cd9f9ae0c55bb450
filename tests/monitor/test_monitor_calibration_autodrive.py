"""The calibration wizard drives a real mm-beagle's guided run (issue 29 item 2).

mm-beagle on emulated sensors mounted with calibration_run's known error (what
``mm-monitor --sim calibration_run`` starts); the wizard's "Drive the calibration run
for me" presses Start/Stop itself; the fit must land within YAW_TOL_DEG / POS_TOL_M of
the sim's true mounts, and the whole test within 60 s of the node's start.
"""

from __future__ import annotations

import math
import os
import time

import pytest
from fakes import wait_until

pytest.importorskip("rclpy")
pytest.importorskip("PySide6")

from PySide6.QtCore import Qt
from PySide6.QtWidgets import QApplication

from mm_beagle.tools.harness import beagle_process
from mm_pc.monitor.context import MonitorConfig, MonitorContext
from mm_pc.monitor.main_window import MainWindow
from mm_pc.monitor.model.calibration_autodrive import DONE
from mm_pc.monitor.model.session import MonitorSession
from mm_pc.monitor.model.sim_mounts import CALIBRATION_SIM_MOUNTS, to_parameter
from mm_pc.monitor.ros_bridge import RosBridge
from mm_pc.monitor.widgets.calibration_wizard import PAGE_RESULTS, CalibrationWizard

pytestmark = pytest.mark.ros
PUMP = QApplication.processEvents
#: the fit against the sim's true mounts, from a real node at 50 Hz (deg, m)
YAW_TOL_DEG, POS_TOL_M = 0.1, 1e-3
PARAMS = {
    "backend": "sim",
    "sim_trajectory": "calibration_run",
    "sim_start_delay": 2.0,  # the node's first replies while it stands: the lap's start
    "sim_mounts": to_parameter(CALIBRATION_SIM_MOUNTS),
}


def test_the_wizard_drives_a_real_sim_node_and_fits_its_true_mounts(qtbot, tmp_path):
    config = MonitorConfig(rate_hz=50.0, calibration_file=tmp_path / "cal.yaml",
                           sim="calibration_run", sim_mounts=CALIBRATION_SIM_MOUNTS)
    bridge = RosBridge("/mm_beagle", 50.0, node_name="mm_monitor_autodrive_test")
    ctx = MonitorContext(MonitorSession(), bridge, config)
    window = MainWindow(ctx)
    qtbot.addWidget(window)
    window.show()
    bridge.start()
    t0 = time.monotonic()
    try:
        with beagle_process(PARAMS, env=dict(os.environ), log_path=str(tmp_path / "b.log")):
            wait_until(lambda: bool(ctx.session.devices), 20, pump=PUMP)
            wiz = CalibrationWizard(ctx, window)
            qtbot.addWidget(wiz)
            wiz.show()
            wiz.next()
            page = wiz.drive_page
            assert page.auto_button.isEnabled()
            qtbot.mouseClick(page.auto_button, Qt.LeftButton)
            wait_until(lambda: not page.auto.active, 60 - (time.monotonic() - t0), pump=PUMP)
            assert page.auto.state == DONE, page.auto.message
        took = time.monotonic() - t0
        steps = ctx.session.calibration_steps()
        assert sorted(s.kind for s, _ in steps) == ["spin"] * 4 + ["straight"] * 2
        assert all(c.ok for _, c in steps), [c.message for _, c in steps]
        wiz.next()
        wiz.next()
        assert wiz.currentId() == PAGE_RESULTS, wiz.compute_error
        cal = wiz.calibration
        for dev, true in zip(ctx.session.devices, CALIBRATION_SIM_MOUNTS, strict=True):
            assert cal[dev].angle_offset_deg == pytest.approx(math.degrees(true.yaw),
                                                              abs=YAW_TOL_DEG)
            assert cal[dev].x == pytest.approx(true.x, abs=POS_TOL_M)
            assert cal[dev].y == pytest.approx(true.y, abs=POS_TOL_M)
        assert wiz.results_page.truth_table.rowCount() == 2
        assert took < 60, took
        print(f"driven run: {took:.1f} s from the node's start; "
              + "; ".join(f"{d}: yaw {cal[d].angle_offset_deg:.3f} deg, "
                          f"({cal[d].x * 1000:.2f}, {cal[d].y * 1000:.2f}) mm"
                          for d in ctx.session.devices))
    finally:
        bridge.stop()
        window.close()
