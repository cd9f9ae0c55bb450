"""Service calls with a deadline: no client of ours waits forever for one reply.

A reply can be lost (mm-beagle's "failed to send response (timeout)" on a busy
machine, a restarted server). :class:`DeadlineClient` wraps an rclpy client: every
call carries a deadline, and :meth:`DeadlineClient.expire` (called from the client's
own timer, on the executor thread) gives up on calls past theirs or whose service is
gone: rclpy forgets them (``remove_pending_request``, so a late reply is dropped) and
their callback gets None. A periodic client then asks again at its next tick: that
is its retry, and the next reply's totals bridge the interval (as a gap is today).
The monitor's bridge does the same in its watchdog (mm_pc/monitor/ros_bridge.py).
The counts and the time of the last answer feed the client's diagnostics.
"""

from __future__ import annotations

import time
from collections.abc import Callable

__all__ = ["DeadlineClient"]


class DeadlineClient:
    """An rclpy ``client`` whose calls are given up after ``timeout_s`` seconds.

    ``clock``: monotonic seconds (a test passes a fake). Not thread-safe: call,
    expire and the replies all run on the one executor thread of the node.
    """

    def __init__(self, client, timeout_s: float, clock: Callable[[], float] = time.monotonic):
        self.client = client
        self.timeout_s = float(timeout_s)
        self._clock = clock
        #: calls sent, answered (any reply), given up (deadline passed or service gone)
        self.sent = self.answered = self.abandoned = 0
        #: ``clock()`` of the last answer; before any, of the first call (of the
        #: construction while none went out: a service never offered is silent too)
        self.last_answer = clock()
        self.ever_answered = False
        self._longest = 0.0  # the longest silence ended by an answer since take_silence()
        self._pending: dict[object, tuple[float, Callable]] = {}  # future -> deadline, on_done

    @property
    def busy(self) -> bool:
        """A call is out (neither answered nor given up yet)."""
        return bool(self._pending)

    def ready(self) -> bool:
        return bool(self.client.service_is_ready())

    def call(self, request, on_done: Callable[[object | None], None]) -> bool:
        """Send ``request``; ``on_done(response)`` once, with None when it is given up.

        False (nothing sent) while the service is not offered.
        """
        if not self.client.service_is_ready():
            return False
        future = self.client.call_async(request)
        now = self._clock()
        self._pending[future] = (now + self.timeout_s, on_done)
        if not self.sent:
            self.last_answer = now  # the discovery's time is no silence of the server
        self.sent += 1
        future.add_done_callback(self._on_done)
        return True

    def _on_done(self, future) -> None:
        entry = self._pending.pop(future, None)
        if entry is None:
            return  # given up already: its callback had None
        self.answered += 1
        now = self._clock()
        self._longest = max(self._longest, now - self.last_answer)
        self.last_answer = now
        self.ever_answered = True
        entry[1](future.result())

    def expire(self, now: float | None = None) -> int:
        """Give up on the calls past their deadline (all of them if the service is gone);
        their callbacks get None. Returns how many."""
        if not self._pending:
            return 0
        now = self._clock() if now is None else now
        gone = not self.client.service_is_ready()
        late = [f for f, (deadline, _) in self._pending.items() if gone or now > deadline]
        for future in late:
            _, on_done = self._pending.pop(future)
            self.client.remove_pending_request(future)
            self.abandoned += 1
            on_done(None)
        return len(late)

    def silent_s(self, now: float | None = None) -> float:
        """Seconds since the last answer (before the first: since the first call, or the
        construction while none went out)."""
        return (self._clock() if now is None else now) - self.last_answer

    def take_silence(self, now: float | None = None) -> float:
        """The longest time without an answer since the previous call (s): the one still
        going on or one an answer ended meanwhile (a diagnostics round sees a short one)."""
        longest, self._longest = max(self._longest, self.silent_s(now)), 0.0
        return longest
