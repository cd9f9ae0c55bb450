"""A tick skipped while a request is out is owed: the bridge asks again as soon as the
reply is done, not a whole period later (the real rclpy client is replaced by a recorder;
the live behaviour is measured by ``mm-bench gui``)."""

from __future__ import annotations

from types import SimpleNamespace

import pytest

pytest.importorskip("PySide6")

from mm_pc.monitor.ros_bridge import RosBridge


class _Future:
    def __init__(self, result) -> None:
        self._result, self.callbacks = result, []

    def add_done_callback(self, cb) -> None:
        self.callbacks.append(cb)

    def result(self):
        return self._result

    def finish(self) -> None:
        for cb in self.callbacks:
            cb(self)


class _Client:
    def __init__(self) -> None:
        self.sent: list[_Future] = []

    def service_is_ready(self) -> bool:
        return True

    def call_async(self, request) -> _Future:
        f = _Future(SimpleNamespace(success=True, message="", data=[]))
        self.sent.append(f)
        return f


def deliver_at_once(bridge: RosBridge) -> None:
    """These tests drive the executor side by hand: hand each reply on at once instead of
    through the GUI thread's delivery timer (test_monitor_bridge_delivery tests that)."""
    bridge._inbox_filled.disconnect(bridge._schedule_delivery)
    bridge._inbox_filled.connect(bridge._deliver)


def _bridge(in_flight: int = 1) -> tuple[RosBridge, _Client]:
    """A bridge with ``in_flight`` data requests out at most (1: the owed logic alone)."""
    bridge = RosBridge(rate_hz=500.0, fetch_polls=False)
    bridge.max_in_flight = in_flight
    client = _Client()
    bridge._clients = {"get_sensor_data": client}
    bridge._types = {"get_sensor_data": SimpleNamespace(Request=lambda id: id)}
    deliver_at_once(bridge)
    return bridge, client


def test_a_skipped_tick_is_asked_for_when_the_reply_is_done(qapp):
    bridge, client = _bridge()
    got = []
    bridge.data_received.connect(got.extend)
    bridge._tick()
    bridge._tick()  # the first request is still out: skipped and owed
    assert len(client.sent) == 1 and bridge.skipped_ticks == 1
    client.sent[0].finish()
    assert len(got) == 1
    assert len(client.sent) == 2  # the owed request went out with the reply, not a tick later
    client.sent[1].finish()
    assert len(client.sent) == 2  # nothing owed any more: the next request waits for a tick
    assert bridge.requests == bridge.replies == 2


def test_nothing_is_owed_while_paused(qapp):
    bridge, client = _bridge()
    bridge._tick()
    bridge._tick()
    bridge.set_polling(False)
    client.sent[0].finish()
    assert len(client.sent) == 1

