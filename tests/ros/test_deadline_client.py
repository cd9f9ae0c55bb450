"""DeadlineClient: a call past its deadline is given up (callback None, rclpy forgets it),
a late reply is dropped, the counts and the silence are kept (no ROS process)."""

from __future__ import annotations

import pytest
from fakes import FakeClock

pytest.importorskip("rclpy")
from rclpy.task import Future

from mm_pc.ros.deadline_client import DeadlineClient


class FakeRclpyClient:
    """call_async hands out rclpy Futures; remove_pending_request is recorded."""

    def __init__(self) -> None:
        self.ready = True
        self.futures: list[Future] = []
        self.removed: list[Future] = []

    def service_is_ready(self) -> bool:
        return self.ready

    def call_async(self, request) -> Future:
        future = Future()
        self.futures.append(future)
        return future

    def remove_pending_request(self, future) -> None:
        self.removed.append(future)


def test_a_lost_reply_is_given_up_at_the_deadline_and_the_next_call_goes_out():
    clock, raw = FakeClock(9.0), FakeRclpyClient()
    c = DeadlineClient(raw, 0.5, clock=clock)
    got: list = []
    clock.t = 10.0  # 1 s to discover the service: no silence of the server's
    assert c.silent_s() == pytest.approx(1.0)  # ... until the first call
    assert c.call("req 1", got.append) and c.busy
    assert c.silent_s() == 0.0
    clock.t = 10.5
    assert c.expire() == 0 and c.busy  # at the deadline: not yet
    clock.t = 10.6
    assert c.expire() == 1 and not c.busy
    assert got == [None] and raw.removed == [raw.futures[0]]
    assert c.call("req 2", got.append)
    raw.futures[1].set_result("reply 2")
    raw.futures[0].set_result("late reply 1")  # rclpy would drop it; if not: ignored
    assert got == [None, "reply 2"]
    assert (c.sent, c.answered, c.abandoned) == (2, 1, 1)
    assert c.ever_answered and c.silent_s() == pytest.approx(0.0)
    # the silence that ended at the answer: 0.6 s since the first call
    assert c.take_silence() == pytest.approx(0.6)
    clock.t = 10.8
    assert c.take_silence() == pytest.approx(0.2)  # the next round: only the new one


def test_a_service_that_disappears_gives_its_calls_up_at_once_and_none_go_out():
    clock, raw = FakeClock(), FakeRclpyClient()
    c = DeadlineClient(raw, 5.0, clock=clock)
    got: list = []
    c.call("a", got.append)
    c.call("b", got.append)
    raw.ready = False
    assert c.expire() == 2 and got == [None, None]
    assert not c.call("c", got.append) and c.sent == 2
    assert c.silent_s() == 0.0 and not c.ever_answered
