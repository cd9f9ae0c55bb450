"""mm-beagle-agent: the 1 kHz poller on the board, served over zenoh, without ROS.

A BeagleBone Black cannot run ROS 2 Jazzy, so the board runs only this: the
same :class:`~mm_beagle.poller.poller.Poller` the node spawns locally (same driver,
same conservation rules), writing into a private shared-state buffer. Every 10 ms,
between polls on the poll thread, it publishes the new polls with the totals after
them and advances the peers' requests by one bounded step. ``mm-beagle --ros-args -p
backend:=remote`` on any ROS machine turns that back into the ROS services
(:mod:`mm_beagle.link.remote`). Keys and frames: :mod:`mm_beagle.link.link`. Needs only
Debian's python3-spidev and python3-yaml and the eclipse-zenoh wheel; ``--backend sim``
also needs python3-numpy. The command line and configuration: :mod:`mm_beagle.link.agent_cli`.

No peer can hold up the poll: the poll thread never calls zenoh. It hands its batches,
events and status requests to a sender thread (an
:class:`~mm_beagle.link.agent_queues.Outbox`), and two worker threads
(:mod:`~mm_beagle.link.agent_workers`) take the command queries and the history requests,
refuse what is too large, too frequent or malformed (:mod:`mm_beagle.link.agent_requests`),
and hand the rest to the poll thread as a :class:`~mm_beagle.link.agent_queues.Job` in a
bounded lane; the poll thread runs at most one step of each lane per service (a patch load
goes in steps of a few register transfers), and the workers send the replies, so a peer
that stops reading blocks at most its worker, never the poll. History replies are at most
:data:`HISTORY_REPLY_POLLS` polls and published with congestion control DROP: a reader
that stops reading misses them (the node asks again).
"""

from __future__ import annotations

import base64
import json
import os
import random
import sys
import threading
import time
import zlib
from collections.abc import Generator

from mm_beagle.link import link, link_auth
from mm_beagle.link.agent_queues import Inbox, Lane, Outbox
from mm_beagle.link.agent_requests import Refusals, TokenBucket
from mm_beagle.link.agent_workers import COMMAND_RATE, HISTORY_RATE, RequestWorkers
from mm_beagle.poller import commands
from mm_beagle.poller import shared_state as ss
from mm_beagle.poller.poller import Poller, PollerConfig

HEARTBEAT_S = 0.1  # an empty batch at least this often: the node's link watchdog
STATUS_S = 1.0
HISTORY_REPLY_POLLS = 4096  # polls per history reply (~94 kB); the node asks on for the rest
JOB_BUDGET_S = 0.003  # the longest the poll thread spends on one lane's job per service


class AgentLink(RequestWorkers):
    """The agent's zenoh side: publishers on the poll thread, a worker thread each for the
    command queryable and the history-request subscriber, and their job lanes."""

    def __init__(self, session, name: str, poller: AgentPoller, credentials: str = "") -> None:
        import zenoh

        self.keys = link.keys(name)
        self.auth = link_auth.FrameAuth.from_credentials(credentials, name)  # a MAC per message
        self.session = session
        self.poller = poller
        self.boot_id = random.getrandbits(63) | 1
        self.number = 0
        self.pub = session.declare_publisher(self.keys["polls"])
        self.status_pub = session.declare_publisher(self.keys["status"])
        self.events_pub = session.declare_publisher(self.keys["events"])
        self.refusals = Refusals()
        self.cmd_in = Inbox("command", self.refusals)
        self.history_in = Inbox("history", self.refusals)
        self.cmd_q = session.declare_queryable(self.keys["cmd"], self.cmd_in.put)
        self.history_sub = session.declare_subscriber(self.keys["history_req"], self.history_in.put)
        self.history_pub = session.declare_publisher(
            self.keys["history"], congestion_control=zenoh.CongestionControl.DROP
        )
        n = len(poller.channels)
        self.sent = [0] * n  # next seq to publish, per sensor
        self.ring_bytes = [poller.state.ring_bytes(i) for i in range(n)]
        self.last_pub = 0.0
        self.next_status = 0.0
        self.t0 = time.monotonic()
        self.cpu_last = (os.times(), time.monotonic())
        self.cpu_percent = float("nan")
        self.bytes_sent = 0
        self.command_lane, self.history_lane = Lane(), Lane()
        self.command_rate, self.history_rate = (
            TokenBucket(*COMMAND_RATE),
            TokenBucket(*HISTORY_RATE),
        )
        self.workers = [
            threading.Thread(target=self._worker, args=args, name=name, daemon=True)
            for args, name in (
                ((self.cmd_in, self._command_query), "mm_agent_commands"),
                ((self.history_in, self._history_request), "mm_agent_history"),
            )
        ]
        self.outbox = Outbox()
        self.sender = threading.Thread(target=self._send, name="mm_agent_sender", daemon=True)
        for t in (*self.workers, self.sender):
            t.start()

    # --- between polls (the poll thread) ---

    def service(self) -> None:
        now = time.monotonic()
        blocks = [self._block(ch, self.sent[ch.i], ch.seq) for ch in self.poller.channels]
        if any(b.count for b in blocks) or now - self.last_pub >= HEARTBEAT_S:
            self.publish_batch(blocks)
            for ch in self.poller.channels:
                self.sent[ch.i] = ch.seq
            self.last_pub = now
        if self.command_lane.current or self.command_lane.jobs:
            self.command_lane.step(JOB_BUDGET_S)
        if self.history_lane.current or self.history_lane.jobs:
            self.history_lane.step(JOB_BUDGET_S)
        if now >= self.next_status:
            self.next_status = now + STATUS_S
            self.outbox.put(("status", b""))  # built by the sender thread

    def _block(self, ch, first: int, end: int) -> link.Block:
        ring = self.ring_bytes[ch.i]
        return link.ring_block(ch.i, ring, first, end, ch.ints.tobytes(), ch.floats.tobytes())

    def publish_batch(self, blocks: list[link.Block]) -> None:
        self.number += 1
        frame = link.encode_batch(
            self.boot_id, self.number, self.poller.state.glob_view.tobytes(), blocks
        )
        self.bytes_sent += len(frame)
        self.outbox.put(("polls", frame))

    def run_command(self, name: str, i: int | None, args: tuple) -> tuple[str, object, list]:
        """One checked command on the poll thread: (status, payload, seq after it)."""
        status, body = self.poller.serve_command((name, i, *args))
        return status, body, [ch.seq for ch in self.poller.channels]

    def load_patch(self, i: int, words: list[int]) -> Generator[None, None, tuple]:
        """load_patch in steps on the poll thread: (status, payload, seq after it)."""
        status, body = yield from self.poller.load_patch_steps(i, words)
        return status, body, [ch.seq for ch in self.poller.channels]

    def history_frame(self, rid: int, i: int, since: int, most: int) -> bytes:
        """Polls ``since`` onwards of sensor ``i`` (at most ``most`` and
        :data:`HISTORY_REPLY_POLLS`), as a batch frame numbered ``rid``, on the poll thread.
        Polls the ring no longer holds are left out: the block starts at its oldest."""
        ch = self.poller.channels[i]
        if since > ch.seq:
            raise commands.CommandRefusedError(commands.history_ahead(since, ch.seq))
        first = max(since, ch.seq - ch.n)
        end = min(ch.seq, first + min(most, HISTORY_REPLY_POLLS))
        block = self._block(ch, first, end)
        return link.encode_batch(self.boot_id, rid, self.poller.state.glob_view.tobytes(), [block])

    # --- the worker threads ---
    # --- status and events ---

    def _send(self) -> None:
        """The sender thread: every message the poll thread hands over, put on its key. A
        put that waits (a peer that stops reading, zenoh's queue full) waits here."""
        pubs = {"polls": self.pub, "status": self.status_pub, "events": self.events_pub}
        box = self.outbox
        while True:
            box.ready.wait(0.2)
            box.ready.clear()
            while box.items:
                kind, body = box.items.popleft()
                try:
                    if kind == "status":
                        body = self.status_body(time.monotonic())
                    pubs[kind].put(body, attachment=self.auth.tag(kind, body))
                except Exception as exc:  # a session closing under us
                    self.refusals.refuse("send", "put failed", f"{kind}: {exc!r}")
            if box.closed:  # after what was left: the final batch of a stopping agent
                return

    def status_body(self, now: float) -> bytes:
        """The status message (JSON), built on the sender thread: reads of the poller's
        counters only (its own copies: each ``tobytes`` is one step under the GIL)."""
        times, wall = os.times(), time.monotonic()
        last, last_wall = self.cpu_last
        if wall > last_wall:
            busy = (times.user + times.system) - (last.user + last.system)
            self.cpu_percent = 100.0 * busy / (wall - last_wall)
        self.cpu_last = (times, wall)
        hist_z = zlib.compress(self.poller.state.hist_view.tobytes(), 1)
        chans = self.poller.channels
        status = {
            "boot_id": self.boot_id,
            "uptime_s": round(now - self.t0, 3),
            "devices": self.poller.cfg.devices,
            "chips": self.poller.chips,
            "states": [ss.STATE_NAMES.get(ch.ints[ss.I_STATE], "?") for ch in chans],
            "last_errors": [ch.last_error for ch in chans],
            "cpu_percent": round(self.cpu_percent, 2),
            "rss_mb": round(rss_mb(), 2),
            "bytes_sent": self.bytes_sent,
            **self.refusals.status(),
            "hist_z": base64.b64encode(hist_z).decode(),
        }
        status["outbox_dropped"] = self.outbox.dropped
        return json.dumps(status).encode()

    def event(self, kind: str, args: tuple) -> None:
        device = str(args[0]) if kind in ("up", "down") else ""
        text = str(args[-1]) if args else ""
        body = json.dumps({"kind": kind, "device": device, "text": text}).encode()
        self.outbox.put(("events", body))

    def close(self) -> None:
        for entity in (self.cmd_q, self.history_sub):
            entity.undeclare()
        self.cmd_in.close()
        self.history_in.close()
        self.outbox.close()
        for t in (*self.workers, self.sender):
            t.join(1.0)
        for entity in (self.history_pub, self.pub, self.status_pub, self.events_pub):
            entity.undeclare()


class AgentPoller(Poller):
    """The poller with its link served every 10 ms instead of a pipe to a node."""

    service_period = 0.01

    def __init__(self, cfg: PollerConfig, state: ss.SharedState) -> None:
        # no pipes: their only users, emit and service, are overridden below
        super().__init__(cfg, state, None, None)  # type: ignore[arg-type]
        self.link: AgentLink | None = None
        self.run_thread_cpu_s = 0.0  # the poll thread's CPU time in run() (s)
        # nobody reads this private shared state between two services (the link sends it
        # then): the fast poll writes the ring only, seq and totals at each service
        for ch in self.channels:
            ch.deferred = True

    def emit(self, kind: str, *args: object) -> None:
        text = " ".join(str(a) for a in args)
        print(f"mm-beagle-agent: {kind}: {text}", file=sys.stderr, flush=True)
        if self.link is not None:
            self.link.event(kind, args)

    def run(self, max_polls: int = 0, paced: bool = True) -> None:
        """:meth:`Poller.run`, keeping the poll thread's own CPU time of it in
        ``run_thread_cpu_s`` (the self-test's figure beside the whole process's)."""
        t0 = time.thread_time()
        try:
            super().run(max_polls, paced)
        finally:
            self.run_thread_cpu_s = time.thread_time() - t0

    def service(self) -> None:
        for ch in self.channels:
            ch.publish()
        if self.link is not None:
            self.link.service()


class StubMotionBus:
    """Benchmarks: an emulated sensor whose motion bursts get a constant reply.

    Bring-up and commands reach the emulator; the 1 kHz motion burst costs
    nothing but the Python around it (3 and 5 counts of motion, every poll).
    """

    def __init__(self, emulator, regmap) -> None:
        a = regmap.addresses
        self.emulator = emulator
        self.status_addr, self.dx_addr = a["status"], a["delta_x_disp"]
        m = regmap.status_motion
        self.reply = [0, m >> 8, m & 0xFF, 0, 0, 3, 0, 0, 5]
        self.burst: list[int] | None = None

    def xfer2(self, data: list[int]) -> list[int]:
        if data is self.burst:  # the driver's own motion-burst list, once it is known
            return self.reply[:]  # a new list each time, as spidev returns
        if len(data) == 9 and data[0] == self.status_addr and data[3] == self.dx_addr:
            self.burst = data
            return self.reply[:]
        return self.emulator.xfer2(data)

    def close(self) -> None:
        self.emulator.close()


def rss_mb() -> float:
    """Resident memory of this process (MB): /proc, or the peak where /proc is absent."""
    try:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 1e6
    except (OSError, ValueError, IndexError):
        import resource  # a chroot without /proc (the armhf check): the peak instead

        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e3


def make_state(cfg: PollerConfig) -> ss.SharedState:
    """A private shared-state buffer for the agent's poller (nobody else maps it)."""
    n = len(cfg.devices)
    return ss.SharedState(bytearray(ss.SharedState.size(n, cfg.ring_size)), n, cfg.ring_size)
