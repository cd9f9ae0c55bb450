"""A log throttle for the nodes: one message per key and period, the rest counted.

No rclpy import: the nodes hand it their keys, the tests a fake clock.
"""

from __future__ import annotations

import time
from collections.abc import Callable

__all__ = ["WarnThrottle"]


class WarnThrottle:
    """Lets one message per key through every ``period_s`` seconds; counts the rest."""

    def __init__(self, period_s: float = 5.0, clock: Callable[[], float] = time.monotonic):
        self.period_s = period_s
        self._clock = clock
        self._last: dict[str, float] = {}
        self._held: dict[str, int] = {}

    def __call__(self, key: str) -> int | None:
        """None: stay quiet. Else the number of messages held back since the last one."""
        now = self._clock()
        last = self._last.get(key)
        if last is not None and now - last < self.period_s:
            self._held[key] = self._held.get(key, 0) + 1
            return None
        self._last[key] = now
        return self._held.pop(key, 0)
