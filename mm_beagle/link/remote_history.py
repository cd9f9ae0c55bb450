"""Gaps in a sensor's polls fetched from the agent's ring (backend:=remote).

A history request ``{"id", "sensor", "since", "max"}`` is put on ``history_req`` and its
answer (a batch frame numbered by the id, or JSON saying why not) taken from ``history``;
ids start at a random 40-bit number so a peer cannot answer ahead of the agent. A link
that drops while asking is waited for as long as the agent's ring holds the polls; only
time with the link up spends :data:`GAP_RETRY_S`. Part of
:class:`~mm_beagle.link.remote.RemoteAgent`.
"""

from __future__ import annotations

import json
import queue
import time

from mm_beagle.link import link, link_decode
from mm_beagle.link.remote_feed import Refused

LINK_TIMEOUT_S = 1.0  # no batch for this long: the link is down (the agent sends >= 10/s)
HISTORY_TIMEOUT_S = 2.0
GAP_RETRY_S = 5.0  # how long a gap is asked for before its polls count as lost


class HistoryFetch:
    """RemoteAgent's gap fetch (``_history_pub``, ``_history_q``, ``_history_id`` and the
    rest of its state set up by RemoteAgent)."""

    def _fill_gap(self, i: int, since: int, until: int) -> None:
        """Fetch the missing polls since..until of sensor i from the agent's ring.

        A link that drops again while asking (a flapping Wi-Fi) is waited for
        as long as the ring can still hold the polls, instead of counting them
        lost; while it is down the services say so. Only time with the link up
        spends the ``GAP_RETRY_S`` budget (right after a reconnection the
        agent's queryable may not be routed to us yet: a query then ends at
        once with no reply).
        """
        budget = GAP_RETRY_S
        ring_s = self.cfg.ring_size / self.cfg.poll_rate
        while self._running:
            t0 = time.monotonic()
            if self._fetch(i, self.next_agent[i], until) or self.next_agent[i] >= until:
                return
            if self._rx_silent():
                self._watch_link(self.last_rx)
                if not self._wait_rx(ring_s):
                    return
                continue
            budget -= time.monotonic() - t0
            if budget <= 0:
                return
            time.sleep(0.1)

    def _rx_silent(self) -> bool:
        """No frame on the polls key for LINK_TIMEOUT_S (the agent sends >= 10/s)."""
        return time.monotonic() - self.last_rx > LINK_TIMEOUT_S

    def _wait_rx(self, timeout: float) -> bool:
        """Until frames arrive on the polls key again (True) or ``timeout`` s pass."""
        deadline = time.monotonic() + timeout
        while self._running and time.monotonic() < deadline:
            if not self._rx_silent():
                return True
            time.sleep(0.05)
        return False

    def _fetch(self, i: int, since: int, until: int) -> bool:
        """Ask the agent for polls since..until of sensor i and apply them in order.

        True when asking again is pointless (the agent restarted meanwhile).
        """
        while since < until and self._running:
            data = self._history(i, since, min(link.MAX_HISTORY, until - since))
            if data is None:
                if "ahead of the newest poll" in self.query_error:  # commands.history_ahead
                    raise Refused(f"a block of sensor {i} from seq {until}: {self.query_error}")
                return False
            batch = link.decode_batch(data, self.n)
            if batch.boot_id != self.boot or not batch.blocks:
                self.query_error = "the agent restarted meanwhile"
                return True
            if not batch.blocks[0].count:  # its ring ends before the block that named them
                raise Refused(
                    f"a block of sensor {i} from seq {until}: the agent's own ring ends at "
                    f"{since} (a forged seq)"
                )
            block = batch.blocks[0]
            if block.index != i or block.first_seq > since or block.first_seq + block.count > until:
                self.refused += 1
                self._dropped(
                    "history", f"a history reply for other polls than asked ({i}, {since}..{until})"
                )
                self.query_error = "the history reply was not for the polls asked"
                return False
            self._apply(block, fetch_gaps=False, totals=False)
            since = block.first_seq + block.count
        return False

    def _history(self, i: int, since: int, most: int) -> bytes | None:
        """One history request and its answer (a batch frame), or None (query_error says why)."""
        if self._history_pub is None:
            self.query_error = "not connected"
            return None
        self._history_id += 1
        rid = self._history_id
        req = {"id": rid, "sensor": i, "since": since, "max": most}
        self._history_pub.put(json.dumps(req).encode())
        deadline = time.monotonic() + HISTORY_TIMEOUT_S
        while (left := deadline - time.monotonic()) > 0:
            if self._rx_silent():  # the link died while we wait: say so now, not in 2 s
                self._watch_link(self.last_rx)
                self.query_error = "the link went down while asking"
                return None
            try:
                data, tag = self._history_q.get(timeout=min(left, 0.1))
            except queue.Empty:
                continue
            try:
                self.auth.check("history", data, tag)
            except link.LinkError as exc:
                self.refused += 1
                self._dropped("history", str(exc))
                continue
            if data[:4] == link.MAGIC:
                if len(data) >= link.HEADER.size and link.HEADER.unpack_from(data, 0)[5] == rid:
                    return data
            else:
                try:
                    answer_id, why = link_decode.decode_history_answer(data)
                except link.LinkError as exc:
                    self._dropped("history", str(exc))
                    continue
                if answer_id == rid:
                    self.query_error = why
                    return None
        self.query_error = f"no answer to a history request within {HISTORY_TIMEOUT_S:g} s"
        return None
