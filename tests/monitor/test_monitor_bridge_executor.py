"""The bridge spins either rclpy executor (the C++ events one by default, the Python
wait-set one as the fallback): both get replies from a real node, run the GUI's
actions, stop cleanly and leave the application's Ctrl-C handler in place."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest
from fakes import scaled

pytest.importorskip("PySide6")
pytest.importorskip("rclpy")

from mm_beagle.tools.harness import beagle_process
from mm_pc.monitor.ros_bridge import EXECUTORS, RosBridge

pytestmark = pytest.mark.ros


def ms(seconds: float) -> int:
    """A qtbot.waitUntil timeout (ms) of ``seconds``, scaled for a slow machine."""
    return int(scaled(seconds) * 1000)


def test_an_unknown_executor_is_refused_before_anything_starts(qapp):
    with pytest.raises(ValueError, match="executor must be one of events, waitset, got 'multi'"):
        RosBridge(executor="multi")


@pytest.mark.parametrize("executor", EXECUTORS)
def test_each_executor_serves_replies_actions_and_stops_cleanly(qtbot, tmp_path, executor):
    bridge = RosBridge("/mm_beagle", 50.0, node_name="mm_monitor_exec", executor=executor)
    settings = []
    bridge.settings_received.connect(lambda dev, msg: settings.append(dev))
    try:
        with beagle_process({"backend": "sim"}, env=dict(os.environ),
                            log_path=str(tmp_path / "beagle.log")):  # fmt: skip
            bridge.start()
            qtbot.waitUntil(lambda: bridge.replies >= 20, timeout=ms(60))
            assert bridge.executor == executor and bridge.state == "connected"
            # actions from the GUI thread reach the executor thread: a settings read ...
            bridge.request_settings("/dev/spidev1.0")
            qtbot.waitUntil(lambda: settings == ["/dev/spidev1.0"], timeout=ms(30))
            # ... and a new rate (its timer is replaced on the executor thread)
            bridge.set_rate(200.0)
            qtbot.waitUntil(lambda: bridge._timer.timer_period_ns == 5_000_000, timeout=ms(30))
            n = bridge.replies
            qtbot.waitUntil(lambda: bridge.replies >= n + 100, timeout=ms(30))
            bridge.stop()
            assert not bridge.running
            n = bridge.replies
            qtbot.wait(200)  # on purpose: no reply may come meanwhile
            assert bridge.replies == n  # nothing spins any more
    finally:
        bridge.stop()


SIGNALS_KEPT = """
import os, signal, sys, time
sys.path.insert(0, sys.argv[2])
from fakes import wait_until
from PySide6.QtCore import QCoreApplication
app = QCoreApplication([])
from mm_pc.monitor.ros_bridge import RosBridge
got = []
signal.signal(signal.SIGINT, lambda *a: got.append("int"))
signal.signal(signal.SIGTERM, lambda *a: got.append("term"))
bridge = RosBridge("/nobody/mm_beagle", 10.0, executor=sys.argv[1])
bridge.start()
ran = []
bridge._post(lambda: ran.append(1))  # run on the executor thread once it spins
wait_until(lambda: ran, 60, "the executor thread spinning")
for phase in ("running", "stopped"):
    os.kill(os.getpid(), signal.SIGINT)
    os.kill(os.getpid(), signal.SIGTERM)
    time.sleep(0.3)  # on purpose: time for an executor that took them to shut down
    print(phase, got, bridge._ctx.ok(), flush=True)
    got.clear()
    bridge.stop()
"""


@pytest.mark.parametrize("executor", EXECUTORS)
def test_ctrl_c_stays_the_applications_with_either_executor(executor):
    """The monitor quits on Ctrl-C/SIGTERM through its own Python handlers: the executor
    must neither take the signals (and shut the bridge's context down) nor leave the
    default action (death) behind when it stops."""
    out = subprocess.run(
        [sys.executable, "-c", SIGNALS_KEPT, executor, os.path.dirname(os.path.dirname(__file__))],
        capture_output=True, text=True, timeout=scaled(120), env=dict(os.environ),
    )  # fmt: skip
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.splitlines() == [
        "running ['int', 'term'] True",
        "stopped ['int', 'term'] False",
    ]
