"""A log throttle: one message per key and period (s, monotonic), the rest counted.

Pure (no rclpy): the nodes, the agent and the link's drop log hand it their keys, the
tests a fake clock. Bounded: at most ``max_keys`` keys are remembered, whatever keys a
caller (or a peer's input) makes up.
"""

from __future__ import annotations

import time
from collections.abc import Callable

__all__ = ["WarnThrottle"]

MAX_KEYS = 1024


class WarnThrottle:
    """Lets one message per key through every ``period_s`` seconds; counts the rest."""

    def __init__(
        self,
        period_s: float = 5.0,
        clock: Callable[[], float] = time.monotonic,
        max_keys: int = MAX_KEYS,
    ):
        self.period_s = period_s
        self.max_keys = max_keys
        self._clock = clock
        self._last: dict[str, float] = {}  # in the order last let through (oldest first)
        self._held: dict[str, int] = {}

    def __call__(self, key: str) -> int | None:
        """None: stay quiet. Else the number of messages held back since the last one."""
        now = self._clock()
        last = self._last.get(key)
        if last is not None and now - last < self.period_s:
            self._held[key] = self._held.get(key, 0) + 1
            return None
        self._last.pop(key, None)
        self._last[key] = now
        if len(self._last) > self.max_keys:
            self._forget(now)
        return self._held.pop(key, 0)

    def _forget(self, now: float) -> None:
        """Forget the keys whose period is over (their next message passes anyway; what
        they held back is dropped), then the oldest until ``max_keys`` are left."""
        for key in [k for k, t in self._last.items() if now - t >= self.period_s]:
            del self._last[key]
            self._held.pop(key, None)
        while len(self._last) > self.max_keys:
            key = next(iter(self._last))
            del self._last[key]
            self._held.pop(key, None)
