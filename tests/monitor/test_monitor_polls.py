"""The monitor's per-poll pose against a real mm-beagle: a pause does not change the path."""

from __future__ import annotations

import os

import numpy as np
import pytest

pytest.importorskip("rclpy")
pytest.importorskip("PySide6")

from mm_beagle.tools.harness import beagle_process
from mm_pc.monitor.context import MonitorConfig, MonitorContext
from mm_pc.monitor.main_window import MainWindow
from mm_pc.monitor.model.session import MonitorSession
from mm_pc.monitor.ros_bridge import RosBridge
from mm_pc.sim import robot

pytestmark = pytest.mark.ros

START_S, RUN_S = 5.0, 12.0
CIRCLE = {  # the figure eight's first circle (0.8 m across, 12.6 s a lap), then still
    "backend": "sim",
    "sim_trajectory": "figure_eight",
    "sim_start_delay": START_S,
    "sim_duration": RUN_S,
    "sim_loop": False,
    "cpi": 6400,
}


def _window(qtbot, tmp_path, name: str):
    config = MonitorConfig(rate_hz=15.0, calibration_file=tmp_path / f"{name}.yaml")
    bridge = RosBridge("/mm_beagle", 15.0, node_name=name)
    window = MainWindow(MonitorContext(MonitorSession(), bridge, config))
    qtbot.addWidget(window)
    window.show()
    bridge.start()
    return window, bridge


def test_a_five_second_pause_mid_turn_ends_on_the_same_path(qtbot, tmp_path):
    """Two windows watch one node; one pauses 5 s while the robot turns. Both end at the
    same pose, on the simulator's path (a per-request pose would cut the circle short)."""
    log = str(tmp_path / "beagle.log")
    # the windows first: they wait for the node, so their baselines come before the run
    steady, b1 = _window(qtbot, tmp_path, "mm_monitor_steady")
    paused, b2 = _window(qtbot, tmp_path, "mm_monitor_paused")
    with beagle_process(CIRCLE, env=dict(os.environ), log_path=log):
        try:
            for b in (b1, b2):
                qtbot.waitUntil(lambda b=b: b.state == "connected", timeout=30_000)
            s1, s2 = steady.ctx.session, paused.ctx.session
            # both baselines before the robot starts (the node started START_S ago at most)
            qtbot.waitUntil(lambda: s1.stats.used > 0 and s2.stats.used > 0, timeout=10_000)
            assert abs(s1.pose.x) < 1e-9 and abs(s2.pose.x) < 1e-9, "the robot moved too early"
            qtbot.waitUntil(lambda: s2.pose.yaw > 0.5, timeout=20_000)  # well into the turn
            b2.set_polling(False)
            rows = len(s2.history)
            qtbot.wait(5000)
            assert len(s2.history) == rows  # no requests while paused
            b2.set_polling(True)
            # the run ends; the robot stands
            target = robot.integrate_pose(*robot.trajectory("figure_eight"), robot.DT)
            end = target[round(RUN_S / robot.DT) - 1]
            qtbot.waitUntil(
                lambda: all(abs(s.pose.yaw - end[2]) < 0.01 for s in (s1, s2)), timeout=30_000
            )
            qtbot.wait(1000)
            p1, p2 = s1.pose.as_array(), s2.pose.as_array()
            assert np.hypot(*(p1[:2] - p2[:2])) < 5e-4, (p1, p2)
            assert abs(p1[2] - p2[2]) < 1e-3
            for p in (p1, p2):
                assert np.hypot(*(p[:2] - end[:2])) < 2e-3, (p, end)
            assert s2.stats.gaps == 0 and s2.stats.per_reply == 0, list(s2.gaps)
            assert s2.stats.polls > RUN_S * 1000
            assert np.max(s2.history.column("dt")) > 4.5  # one request covered (most of) the pause
        finally:
            for b in (b1, b2):
                b.stop()
            steady.close()
            paused.close()


def test_a_link_lost_for_three_seconds_mid_turn_stays_on_the_path(qtbot, tmp_path):
    """The node stops answering for 3 s (SIGSTOP; its poller keeps polling into the ring):
    requests time out, then the first reply's polls cover the outage, and the pose ends
    on the simulator's path (per request it would cut the circle by a chord of 0.6 m)."""
    import signal

    window, bridge = _window(qtbot, tmp_path, "mm_monitor_link")
    s = window.ctx.session
    with beagle_process(CIRCLE, env=dict(os.environ), log_path=str(tmp_path / "b.log")) as node:
        try:
            qtbot.waitUntil(lambda: bridge.state == "connected", timeout=30_000)
            qtbot.waitUntil(lambda: s.stats.used > 0, timeout=10_000)
            assert abs(s.pose.x) < 1e-9, "the robot moved before the baseline"
            qtbot.waitUntil(lambda: s.pose.yaw > 0.5, timeout=20_000)
            node.send_signal(signal.SIGSTOP)
            qtbot.wait(3000)
            node.send_signal(signal.SIGCONT)
            target = robot.integrate_pose(*robot.trajectory("figure_eight"), robot.DT)
            end = target[round(RUN_S / robot.DT) - 1]
            qtbot.waitUntil(lambda: abs(s.pose.yaw - end[2]) < 0.01, timeout=30_000)
            qtbot.wait(1000)
            p = s.pose.as_array()
            assert np.hypot(*(p[:2] - end[:2])) < 2e-3, (p, end)
            assert s.stats.gaps == 0, list(s.gaps)
            assert bridge.stats().dropped_requests >= 1  # the link was down
            assert np.max(s.history.column("dt")) > 2.0  # one reply covered the outage
        finally:
            node.send_signal(signal.SIGCONT)
            bridge.stop()
            window.close()
