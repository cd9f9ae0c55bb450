"""The whole monitor against a real mm-beagle process: connection, restarts, rate, CLI."""

from __future__ import annotations

import os
import re
import subprocess
import sys
import time
from pathlib import Path

import pytest
from fakes import wait_until

pytest.importorskip("rclpy")
pytest.importorskip("PySide6")

from PySide6.QtWidgets import QApplication

from mm_beagle.tools.harness import (
    BeagleClient,
    agent_process,
    beagle_process,
    free_port,
    stop_process,
)
from mm_pc.monitor.context import MonitorConfig, MonitorContext
from mm_pc.monitor.main_window import MainWindow
from mm_pc.monitor.model.session import MonitorSession
from mm_pc.monitor.ros_bridge import RosBridge

pytestmark = pytest.mark.ros
#: wait_until's pump: the window's signals and timers are served while a test waits
PUMP = QApplication.processEvents
ROOT = Path(__file__).resolve().parents[2]
STRAIGHT = {
    "backend": "sim",
    "sim_trajectory": "straight",
    "sim_start_delay": 4.0,
    "sim_duration": 3.0,
    "sim_loop": False,
}


def make_window(qtbot, tmp_path, rate=50.0):
    config = MonitorConfig(rate_hz=rate, calibration_file=tmp_path / "cal.yaml")
    bridge = RosBridge("/mm_beagle", rate, node_name="mm_monitor_test")
    ctx = MonitorContext(MonitorSession(), bridge, config)
    window = MainWindow(ctx)
    qtbot.addWidget(window)
    window.show()
    bridge.start()
    return window, bridge


def assert_run_counted(qtbot, session, timeout: float) -> None:
    """The STRAIGHT run ended at 0.6 m, and every count the node measured after the
    monitor's baseline reached the pose (the node's total from /diagnostics)."""
    wait_until(lambda: session.pose.x > 0.59, timeout, pump=PUMP)
    qtbot.wait(600)
    client = BeagleClient("mm_monitor_check")
    try:
        node_y = client.diagnostics()["/dev/spidev1.0"]["y_total_counts"]
    finally:
        client.close()
    served = sum(session.history.column("s0_raw_dy"))
    assert session.pose.x == pytest.approx(0.6, abs=0.002)
    assert served == pytest.approx(int(node_y) * 0.0254 / 1600, abs=2e-4)


def test_monitor_connects_counts_everything_and_survives_a_restart(qtbot, tmp_path):
    window, bridge = make_window(qtbot, tmp_path)
    try:
        assert "waiting" in window.state_label.text()
        log = str(tmp_path / "beagle1.log")
        with beagle_process(STRAIGHT, env=dict(os.environ), log_path=log) as proc:
            connected = "connected to /mm_beagle"
            wait_until(lambda: connected in window.state_label.text(), 20, pump=PUMP)
            wait_until(lambda: "ms" in window.rtt_label.text(), 5, pump=PUMP)
            # the run: 4 s still, 3 s at 0.2 m/s, then still; wait for it to end
            session = window.ctx.session
            assert_run_counted(qtbot, session, timeout=20)
            stop_process(proc)
        wait_until(lambda: "lost /mm_beagle" in window.state_label.text(), 15, pump=PUMP)
        pose_before = session.pose
        with beagle_process(STRAIGHT, env=dict(os.environ), log_path=str(tmp_path / "b2.log")):
            wait_until(lambda: bridge.state == "connected", 30, pump=PUMP)
            wait_until(lambda: session.stats.restarts >= 1, 10, pump=PUMP)
            # no jump at the restart; the second run adds its own 0.6 m
            assert session.pose.x == pytest.approx(pose_before.x, abs=1e-9)
            wait_until(lambda: session.pose.x > pose_before.x + 0.59, 20, pump=PUMP)
        assert bridge.stats().dropped_requests >= 0
    finally:
        bridge.stop()
        window.close()


def test_monitor_through_the_agent_counts_everything_and_an_agent_restart_is_seamless(
    qtbot, tmp_path
):
    """The BBB chain: agent on emulated sensors, mm-beagle backend:=remote, the monitor.

    The agent restarting mid-run is not a node restart: the node continues its totals,
    so the monitor sees no jump and adds the second run's 0.6 m."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    agent_opts = {k: v for k, v in STRAIGHT.items() if k != "backend"}
    agent_opts.update(backend="sim", listen=[endpoint])
    window, bridge = make_window(qtbot, tmp_path)
    session = window.ctx.session
    try:
        with beagle_process(
            {"backend": "remote", "agent": endpoint}, env=dict(os.environ),
            log_path=str(tmp_path / "node.log"),
        ):  # fmt: skip
            with agent_process(agent_opts, str(tmp_path / "agent1.log")):
                wait_until(lambda: bridge.state == "connected", 30, pump=PUMP)
                assert_run_counted(qtbot, session, timeout=25)
            pose_before = session.pose
            with agent_process(agent_opts, str(tmp_path / "agent2.log")):
                wait_until(lambda: session.pose.x > pose_before.x + 0.59, 30, pump=PUMP)
                qtbot.wait(1000)  # the run's last centimetre
            assert session.stats.restarts == 0  # the node never went back
            assert session.pose.x == pytest.approx(pose_before.x + 0.6, abs=0.004)
    finally:
        bridge.stop()
        window.close()


def test_rate_field_refuses_zero_and_junk_and_applies_good_values(qtbot, tmp_path):
    window, bridge = make_window(qtbot, tmp_path, rate=15.0)
    try:
        editor = window.rate_editor
        for bad, msg in (("0", "1..500 Hz"), ("abc", "number of Hz"), ("501", "1..500"),
                         ("nan", "1..500"), ("", "number of Hz")):  # fmt: skip
            editor.edit.setText(bad)
            assert not editor.apply()
            assert msg in editor.error.text()
            assert not editor.error.isHidden()
            assert bridge.rate_hz == 15.0 and window.ctx.config.rate_hz == 15.0
        editor.edit.setText("100")
        assert editor.apply()
        assert editor.error.isHidden()
        assert bridge.rate_hz == 100.0 and window.ctx.config.rate_hz == 100.0
    finally:
        bridge.stop()
        window.close()


def test_pause_stops_requests(qtbot, tmp_path):
    with beagle_process({"backend": "sim"}, env=dict(os.environ), log_path=str(tmp_path / "b.log")):
        window, bridge = make_window(qtbot, tmp_path, rate=50.0)
        try:
            wait_until(lambda: bridge.replies > 5, 20, pump=PUMP)
            window.pause_button.setChecked(True)
            qtbot.wait(300)
            n = bridge.requests
            qtbot.wait(700)
            assert bridge.requests == n
            assert window.pause_button.text() == "Resume polling"
            window.pause_button.setChecked(False)
            wait_until(lambda: bridge.requests > n + 5, 5, pump=PUMP)
        finally:
            bridge.stop()
            window.close()


def test_method_selector_switches_the_pose_method(qtbot, tmp_path):
    config = MonitorConfig(calibration_file=tmp_path / "cal.yaml")
    ctx = MonitorContext(MonitorSession(), None, config)
    window = MainWindow(ctx)
    qtbot.addWidget(window)
    window.method_box.setCurrentIndex(window.method_box.findData("two-sensor"))
    assert ctx.session.method == "two-sensor"
    assert window.method_error.isHidden()
    assert "offline" in window.state_label.text()


def test_headless_cli_runs_against_the_sim_and_writes_a_screenshot(tmp_path):
    shot = tmp_path / "shot.png"
    env = dict(os.environ, QT_QPA_PLATFORM="offscreen")
    out = subprocess.run(
        # 15 s: the emulated node is not waited for, and took over 6 s to come up under load
        [sys.executable, "-m", "mm_pc.monitor.app", "--sim", "--headless", "--duration", "15",
         "--rate", "30", "--screenshot", str(shot)],
        capture_output=True, text=True, timeout=120, env=env,
    )  # fmt: skip
    assert out.returncode == 0, out.stdout + out.stderr
    assert shot.stat().st_size > 10_000
    assert "was connected to /mm_beagle" in out.stdout
    assert "the robot (exact) travelled" in out.stdout
    log = Path(out.stdout.split("node log: ", 1)[1].split()[0])  # a private folder, printed
    assert not log.parent.exists()  # and removed, since the run ended well


def test_headless_cli_with_optical_flow_and_pixart_chips_uses_every_single_poll():
    """A PMW3901 (fixed, rounded CPI) beside a PMW3360: the polls agree with the totals, so
    the pose integrates them and steps over no gap (it once dropped every one)."""
    env = dict(os.environ, QT_QPA_PLATFORM="offscreen")
    out = subprocess.run(
        [sys.executable, "-m", "mm_pc.monitor.app", "--sim", "--sim-chips", "pmw3901,pmw3360",
         "--headless", "--duration", "5", "--rate", "30"],
        capture_output=True, text=True, timeout=120, env=env,
    )  # fmt: skip
    assert out.returncode == 0, out.stdout + out.stderr
    m = re.search(r"integrated (\d+) single polls; (\d+) gap", out.stdout)
    assert m, out.stdout
    # the bug dropped every poll as polls disagreeing with the totals; a gap from a reply
    # lost on a loaded slow VM (at most one seen) is not it: the summary names each cause
    assert int(m.group(1)) > 1000 and int(m.group(2)) <= 1, out.stdout
    causes = re.search(r"Gaps: (.*)\.$", out.stdout, re.M)
    assert bool(causes) == (m.group(2) != "0"), out.stdout
    if causes:
        assert not re.search(r"sum to|come to|CPI", causes.group(1)), out.stdout


def test_headless_cli_with_agent_runs_the_bbb_chain(tmp_path):
    env = dict(os.environ, QT_QPA_PLATFORM="offscreen")
    out = subprocess.run(
        [sys.executable, "-m", "mm_pc.monitor.app", "--sim", "--agent", "--headless",
         "--duration", "6", "--rate", "30"],
        capture_output=True, text=True, timeout=120, env=env,
    )  # fmt: skip
    assert out.returncode == 0, out.stdout + out.stderr
    assert "mm-beagle-agent + mm-beagle backend:=remote" in out.stdout
    assert "was connected to /mm_beagle" in out.stdout
    assert " 0 samples used" not in out.stdout


def test_no_display_falls_back_to_headless_with_a_message(tmp_path):
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    env.pop("QT_QPA_PLATFORM", None)
    shot = tmp_path / "fallback.png"
    t0 = time.monotonic()
    out = subprocess.run(
        [sys.executable, "-m", "mm_pc.monitor.app", "--duration", "2", "--screenshot", str(shot),
         "--beagle", "/nobody_here"],
        capture_output=True, text=True, timeout=60, env=env,
    )  # fmt: skip
    assert out.returncode == 0, out.stderr
    assert "no display" in out.stdout and "running headless for 2 s" in out.stdout
    assert "waited for /nobody_here" in out.stdout or "No sensor data arrived" in out.stdout
    assert shot.exists()
    assert time.monotonic() - t0 < 50


@pytest.mark.parametrize(
    ("args", "message"),
    [(["--rate", "0"], "1..500"), (["--rate", "junk"], "invalid float value"),
     (["--duration", "-1"], "--duration must be 0..2000000 s"),
     (["--agent"], "--agent goes with --sim"),
     (["--executor", "multi"], "invalid choice: 'multi'")],
)  # fmt: skip
def test_bad_command_line_exits_2_with_a_message(args, message):
    out = subprocess.run(
        [sys.executable, "-m", "mm_pc.monitor.app", "--headless", *args],
        capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    assert out.returncode == 2
    assert message in out.stderr



def test_a_call_without_answer_fails_once_and_its_late_reply_is_ignored(qtbot):
    """A node that answers a settings read only after 1.5 s: the monitor reports the timeout
    next to the request and ignores the late reply (no second, contradicting signal)."""
    import threading

    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor

    from mm_interfaces.srv import GetSensorSettings

    ctx = Context()
    rclpy.init(context=ctx)
    server = rclpy.create_node("slow_beagle", namespace="/slow", context=ctx)

    def slow(req, res):
        time.sleep(1.5)
        res.success = True
        res.settings.spi_device = req.id
        return res

    server.create_service(GetSensorSettings, "/slow/mm_beagle/get_sensor_settings", slow)
    executor = SingleThreadedExecutor(context=ctx)
    executor.add_node(server)
    spin = threading.Thread(target=executor.spin, daemon=True)
    spin.start()
    bridge = RosBridge("/slow/mm_beagle", 15.0, node_name="mm_monitor_slow", timeout_s=0.2)
    failed, received = [], []
    bridge.settings_failed.connect(lambda dev, msg: failed.append((dev, msg)))
    bridge.settings_received.connect(lambda dev, msg: received.append(dev))
    bridge.start()
    try:
        client = bridge._clients["get_sensor_settings"]
        qtbot.waitUntil(client.service_is_ready, timeout=20_000)
        bridge.request_settings("/dev/spidev1.0")
        qtbot.waitUntil(lambda: bool(failed), timeout=5_000)
        assert failed == [("/dev/spidev1.0", "no answer within 0.5 s")]
        qtbot.wait(2_000)  # the late reply arrives meanwhile
        assert received == [] and len(failed) == 1
    finally:
        bridge.stop()
        executor.shutdown(timeout_sec=1.0)
        spin.join(3.0)
        server.destroy_node()
        ctx.try_shutdown()


def test_the_bridge_takes_diagnostics_only_of_the_node_it_watches(qtbot):
    """Two robots publish the same device ids on /diagnostics; --beagle picks one."""
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

    from mm_pc.monitor.ros_bridge import RosBridge

    bridge = RosBridge("/robot2/mm_beagle")  # constructed, never started: no ROS traffic
    got: list[dict] = []
    bridge.diagnostics_received.connect(got.append)

    def status(node: str, y: str) -> DiagnosticStatus:
        return DiagnosticStatus(
            name=f"{node}: /dev/spidev1.0", hardware_id="/dev/spidev1.0", message="up",
            values=[KeyValue(key="y_total_counts", value=y)],
        )

    bridge._on_diagnostics(DiagnosticArray(status=[status("/robot1/mm_beagle", "111")]))
    bridge._on_diagnostics(DiagnosticArray(status=[status("/robot2/mm_beagle", "222")]))
    bridge._on_diagnostics(DiagnosticArray(status=[status("/robot2/mm_beagle_x", "333")]))
    assert [d["/dev/spidev1.0"]["y_total_counts"] for d in got] == ["222"]


def test_wizard_calibrates_from_a_real_node_on_the_guided_run(qtbot, tmp_path):
    """mm-beagle's emulated sensors (mounted +5 / -3 deg) drive the guided run
    (--sim calibration_run); the wizard records its steps with Start/Stop pressed
    in the pauses (decided per reply, so a busy machine cannot shift them) and
    recovers both mounting angles to within 0.1 deg."""
    import math

    from PySide6.QtCore import Qt

    from mm_pc.monitor.widgets.calibration_wizard import PAGE_RESULTS, CalibrationWizard

    yaw = (math.radians(5.0), math.radians(-3.0))
    params = {
        "backend": "sim",
        "sim_trajectory": "calibration_run",
        "sim_start_delay": 3.0,
        "sim_loop": False,
        "sim_mounts": [0.049, -0.0395, yaw[0], 0.049, 0.0395, yaw[1]],
    }
    window, bridge = make_window(qtbot, tmp_path)
    ctx = window.ctx
    kinds = ["straight"] * 2 + ["spin"] * 4
    state = {"moved": False, "done": False}

    def on_reply(_reply) -> None:
        s = ctx.session
        if s.recording_step is None or s.history is None or not len(s.history):
            return
        still = all(s.history.last(f"s{k}_raw_d{a}") == 0 for k in (0, 1) for a in "xy")
        if not still:
            state["moved"] = True
        elif state["moved"]:
            qtbot.mouseClick(wiz.drive_page.stop_button, Qt.LeftButton)
            state["moved"] = False
            if kinds:
                wiz.drive_page.start(kinds.pop(0))
            else:
                state["done"] = True

    try:
        with beagle_process(params, env=dict(os.environ), log_path=str(tmp_path / "b.log")):
            wait_until(lambda: bool(ctx.session.devices), 30, pump=PUMP)
            wiz = CalibrationWizard(ctx, window)
            qtbot.addWidget(wiz)
            wiz.show()
            wiz.next()
            assert wiz.drive_page.start(kinds.pop(0))  # in the start delay: standing
            ctx.reply_processed.connect(on_reply)
            wait_until(lambda: state["done"], 90, pump=PUMP)
            ctx.reply_processed.disconnect(on_reply)
        steps = ctx.session.calibration_steps()
        assert [s.kind for s, _ in steps] == ["straight"] * 2 + ["spin"] * 4
        assert all(c.ok for _, c in steps), [c.message for _, c in steps]
        wiz.next()
        wiz.next()  # distance not measured, spins of 360 deg
        assert wiz.currentId() == PAGE_RESULTS, wiz.compute_error
        cal = wiz.calibration
        for dev, psi in zip(ctx.session.devices, yaw, strict=True):
            assert cal[dev].angle_offset == pytest.approx(psi, abs=math.radians(0.1))
            assert cal[dev].x == pytest.approx(0.049, abs=1e-3)
        wiz.accept()
        assert ctx.session.calibration == cal and not ctx.session.calibrating
    finally:
        bridge.stop()
        window.close()
