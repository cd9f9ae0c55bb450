"""Hostile peers of mm-beagle-agent and what they do to its poll: the attacks of issue 27
for tests/beagle/test_hostile_agent.py and ``mm-bench agent``'s ``hostile`` figures.

A :class:`PollWatch` is an honest peer: it follows the agent's status and batches (the
newest totals per sensor, with the sim backend's ground truth) and reads the polls of a
window back through history requests, so the longest gap between two consecutive poll
stamps and the counts lost (emulator truth minus totals) come from the agent's own ring.
A stuck reader (a peer that asks for history and commands and never reads the answers)
must run in a process of its own: ``python -m mm_beagle.tools.hostile_peer stuck
ENDPOINT NAME SECONDS``.
"""

from __future__ import annotations

import contextlib
import json
import subprocess
import sys
import threading
import time

import numpy as np

from mm_beagle.link import link, zenoh_config
from mm_beagle.poller import shared_state as ss


class PollWatch:
    """An honest peer of the agent at ``endpoint``: newest totals and status, history."""

    def __init__(self, endpoint: str, name: str = link.DEFAULT_NAME, n: int = 2) -> None:
        import zenoh

        self.zenoh = zenoh
        self.keys = link.keys(name)
        self.n = n
        self.session = zenoh.open(zenoh_config.zenoh_config(connect=[endpoint]))
        self.ints = [np.zeros(ss.N_INT, np.int64) for _ in range(n)]
        self.status: dict = {}
        self._answers: list[bytes] = []
        self._lock = threading.Lock()
        self._rid = 1 << 40  # far from other peers' ids: their answers come here too
        s = self.session
        self._subs = [
            s.declare_subscriber(self.keys["polls"], self._on_polls),
            s.declare_subscriber(self.keys["status"], self._on_status),
            s.declare_subscriber(self.keys["history"], self._on_history),
        ]

    def _on_polls(self, sample) -> None:
        try:
            batch = link.decode_batch(sample.payload.to_bytes(), self.n)
        except link.LinkError:
            return
        for b in batch.blocks:
            ints = np.frombuffer(b.ints, np.int64)
            with self._lock:
                if ints[ss.I_SEQ] >= self.ints[b.index][ss.I_SEQ]:
                    self.ints[b.index] = ints.copy()

    def _on_status(self, sample) -> None:
        with contextlib.suppress(ValueError):
            self.status = json.loads(sample.payload.to_bytes())

    def _on_history(self, sample) -> None:
        with self._lock:
            self._answers.append(sample.payload.to_bytes())

    def seq(self, i: int) -> int:
        with self._lock:
            return int(self.ints[i][ss.I_SEQ])

    def counts_lost(self) -> int:
        """|emulator truth - totals| over both axes and every sensor (sim backend)."""
        with self._lock:
            pairs = [(t[ss.I_GEN_X], t[ss.I_X_TOTAL]) for t in self.ints]
            pairs += [(t[ss.I_GEN_Y], t[ss.I_Y_TOTAL]) for t in self.ints]
        return sum(abs(int(gen - total)) for gen, total in pairs)

    def command(self, timeout: float = 10.0, **msg) -> dict | None:
        """One command and its JSON reply (None: no good reply)."""
        for reply in self.session.get(
            self.keys["cmd"], payload=json.dumps(msg).encode(), timeout=timeout
        ):
            if reply.ok is not None:
                return json.loads(reply.ok.payload.to_bytes())
        return None

    def wait_status(self, pred, timeout: float) -> dict:
        """The newest status once ``pred(status)`` holds (AssertionError after ``timeout``)."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if self.status and pred(self.status):
                return self.status
            time.sleep(0.05)
        raise AssertionError(f"no agent status satisfying the test in {timeout:g} s")

    def stamps(self, i: int, since: int, until: int, timeout: float = 20.0) -> np.ndarray:
        """The poll stamps (ns) of sensor ``i``, seq since..until, from the agent's ring."""
        out: list[np.ndarray] = []
        deadline = time.monotonic() + timeout
        while since < until:
            if time.monotonic() > deadline:
                raise AssertionError(f"history of sensor {i} from {since} not answered")
            self._rid += 1
            rid = self._rid
            req = {"id": rid, "sensor": i, "since": since, "max": until - since}
            self.session.put(self.keys["history_req"], json.dumps(req).encode())
            block = self._answer(rid, min(2.0, deadline - time.monotonic()))
            if block is None or block.index != i or block.first_seq < since:
                continue  # dropped, rate limited (or another peer's answer): ask again
            if block.first_seq > since:
                raise AssertionError(f"polls {since}..{block.first_seq} no longer in the ring")
            take = min(block.count, until - since)
            out.append(np.frombuffer(block.arrays[0], np.int64)[:take])
            since += take
        return np.concatenate(out) if out else np.zeros(0, np.int64)

    def _answer(self, rid: int, timeout: float):
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            with self._lock:
                answers, self._answers = self._answers, []
            for data in answers:
                if data[:4] == link.MAGIC:
                    batch = link.decode_batch(data, self.n)
                    if batch.number == rid and batch.blocks:
                        return batch.blocks[0]
            time.sleep(0.01)
        return None

    def longest_gap_ms(self, since: list[int], until: list[int]) -> float:
        """The longest time between two consecutive polls of any sensor in the window."""
        gaps = [0.0]
        for i in range(self.n):
            st = self.stamps(i, since[i], until[i])
            if len(st) > 1:
                gaps.append(float(np.diff(st).max()) / 1e6)
        return max(gaps)

    def close(self) -> None:
        for s in self._subs:
            s.undeclare()
        self.session.close()


def peak_rss_mb(pid: int) -> tuple[float, float]:
    """(current, peak) resident memory of process ``pid`` (MB), from /proc."""
    fields = {}
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            key, _, value = line.partition(":")
            if key in ("VmRSS", "VmHWM"):
                fields[key] = int(value.split()[0]) / 1024
    return fields["VmRSS"], fields["VmHWM"]


def flood(session, key: str, payloads: list[bytes], query: bool) -> None:
    """Send each payload on ``key``: as a query (replies not awaited) or a put."""
    for p in payloads:
        if query:
            session.get(key, payload=p, timeout=5.0)  # the replies are never read
        else:
            session.put(key, p)


def stuck_reader(endpoint: str, name: str, seconds: float) -> subprocess.Popen:
    """A peer process that asks for history and commands, then never reads a byte: its
    zenoh channels hold one message, so its whole session stops reading from the agent."""
    return subprocess.Popen(
        [sys.executable, "-m", "mm_beagle.tools.hostile_peer", "stuck", endpoint, name,
         str(seconds)],
        stdout=subprocess.PIPE,
        text=True,
    )  # fmt: skip


def _stuck_main(endpoint: str, name: str, seconds: float) -> None:
    import zenoh

    keys = link.keys(name)
    s = zenoh.open(zenoh_config.zenoh_config(connect=[endpoint]))
    fifo = zenoh.handlers.FifoChannel
    subs = [s.declare_subscriber(keys[k], handler=fifo(1)) for k in ("history", "polls")]
    time.sleep(0.5)
    print("stuck", flush=True)
    pub = s.declare_publisher(keys["history_req"])
    end = time.monotonic() + seconds
    k = 0
    gets = []
    while time.monotonic() < end:
        k += 1
        req = {"id": k, "sensor": k % 2, "since": 0, "max": link.MAX_HISTORY}
        pub.put(json.dumps(req).encode())
        if k % 10 == 0:  # replies never read (a channel of one)
            gets.append(s.get(keys["cmd"], payload=b'{"cmd": "info"}', handler=fifo(1)))
        time.sleep(0.005)
    del subs, gets
    import os

    os._exit(0)  # no orderly close: a peer that just stops


if __name__ == "__main__":
    if len(sys.argv) == 5 and sys.argv[1] == "stuck":
        _stuck_main(sys.argv[2], sys.argv[3], float(sys.argv[4]))
    else:
        print("usage: python -m mm_beagle.tools.hostile_peer stuck ENDPOINT NAME SECONDS")
        sys.exit(2)
