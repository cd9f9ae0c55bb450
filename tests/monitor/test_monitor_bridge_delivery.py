"""RosBridge hands replies to the GUI thread in batches (one ``data_received`` with a list):
in order, none lost, and the GUI thread woken about once per delivery interval, not once
per reply."""

from __future__ import annotations

import threading
import time

import pytest
from fakes import scaled

from mm_pc.core.sensor_data import Reply
from mm_pc.monitor.ros_bridge import DELIVERY_INTERVAL_S, RosBridge


def test_replies_reach_the_gui_thread_in_order_and_in_batches(qtbot):
    bridge = RosBridge(rate_hz=500.0)
    got, wakes, batches = [], [], []
    bridge.data_received.connect(got.extend)
    bridge.data_received.connect(lambda b: batches.append(len(b)))
    bridge._inbox_filled.connect(lambda: wakes.append(time.monotonic()))
    n = 100

    def executor_thread() -> None:  # replies every 2 ms, as at 500 Hz
        for i in range(n):
            bridge._hand_on(Reply((), received_s=float(i)))
            time.sleep(0.002)

    t = threading.Thread(target=executor_thread)
    t0 = time.monotonic()
    t.start()
    qtbot.waitUntil(lambda: len(got) == n, timeout=int(scaled(30) * 1000))
    t.join(scaled(30))
    took = time.monotonic() - t0
    assert [r.received_s for r in got] == [float(i) for i in range(n)]
    # one wake-up per delivery interval (+1 for the first), never one per reply
    assert len(wakes) <= took / DELIVERY_INTERVAL_S + 2 and len(wakes) < n / 3
    assert len(batches) == len(wakes) and max(batches) > 1


def test_a_lone_reply_is_handed_on_without_waiting(qtbot):
    """At low rates (the default 15 Hz) each reply is delivered as it comes."""
    bridge = RosBridge(rate_hz=15.0)
    got = []
    bridge.data_received.connect(got.extend)
    bridge._delivered_at = time.monotonic() - 1.0  # the last delivery was long ago
    bridge._hand_on(Reply(()))
    assert bridge._delivery.isActive() and bridge._delivery.interval() == 0
    qtbot.waitUntil(lambda: len(got) == 1, timeout=int(scaled(30) * 1000))


@pytest.mark.ros
def test_stop_drops_what_is_still_waiting(qtbot):
    """Replies the GUI thread has not taken when the bridge stops go nowhere."""
    pytest.importorskip("rclpy")
    bridge = RosBridge(rate_hz=500.0, node_name="mm_monitor_delivery")
    got = []
    bridge.data_received.connect(got.extend)
    bridge.set_polling(False)  # no node here anyway: nothing but this reply
    bridge.start()
    bridge._delivered_at = time.monotonic()  # just delivered: the next take waits
    bridge._hand_on(Reply(()))
    assert bridge._delivery.isActive()
    bridge.stop()
    qtbot.wait(int(3 * DELIVERY_INTERVAL_S * 1000))  # on purpose: nothing may arrive meanwhile
    assert got == [] and not bridge._delivery.isActive()
