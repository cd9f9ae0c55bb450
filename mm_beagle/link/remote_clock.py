"""The agent's poll stamps moved onto the node's clock (backend:=remote).

The offset estimate is the smallest delay seen between a poll's agent stamp and its
arrival here (ns), allowed to rise by :data:`CLOCK_LEAK` (100 ppm) so that it follows a
drifting clock. A smaller delay lowers the estimate at once; the offset applied to a
sensor's stamps follows it slewed (at most :data:`CLOCK_SLEW` of the time between two
polls), so its stamps never step back. Part of :class:`~mm_beagle.link.remote.RemoteAgent`.
"""

from __future__ import annotations

import time

import numpy as np

CLOCK_LEAK = 1e-4  # the clock offset estimate may rise this much per second (100 ppm)
# A lower estimate reaches the stamps at most this fast (ns per ns of poll time): a step of
# d ms is taken in over d / CLOCK_SLEW ms of polls, whose intervals look 5 % shorter meanwhile,
# instead of at once, which put a poll's stamp before its predecessor's (steps of several ms
# under load, against 1 ms between polls).
CLOCK_SLEW = 0.05


class StampClock:
    """RemoteAgent's clock mapping: ``_offset_ns``/``_offset_t`` (the estimate and when it
    was set), per sensor ``_stamp_off``/``_stamp_raw`` (the offset applied to its newest
    poll and that poll's agent stamp), ``latency_ms``; all set up by RemoteAgent."""

    def _stamp_offsets(self, i: int, raw: np.ndarray) -> np.ndarray:
        """The offsets to add to sensor i's next polls (agent stamps ``raw``, in order).

        Up to the estimate at once (stamps only move forward); down towards it by at
        most ``CLOCK_SLEW`` of the agent time since sensor i's last poll, so each
        mapped stamp stays after the one before it.
        """
        # only called once an offset exists (sync: _apply checks it)
        target = int(self._offset_ns)  # type: ignore[arg-type]
        prev = self._stamp_off[i]
        if prev is None or target >= prev:
            offs = np.full(len(raw), target, np.int64)
        else:
            since = np.maximum(raw - self._stamp_raw[i], 0)
            offs = np.maximum(target, prev - (since * CLOCK_SLEW).astype(np.int64))
        self._stamp_off[i], self._stamp_raw[i] = int(offs[-1]), int(raw[-1])
        return offs

    def _clock(self, recv_ns: int, stamp_ns: int) -> None:
        sample = recv_ns - stamp_ns
        now = time.monotonic()
        off = self._offset_ns
        if off is None:
            off = sample
        else:
            off = min(sample, off + int(CLOCK_LEAK * (now - self._offset_t) * 1e9))
        self._offset_ns, self._offset_t = off, now
        self.latency_ms.append((sample - off) / 1e6 if self.clock_sync else sample / 1e6)
