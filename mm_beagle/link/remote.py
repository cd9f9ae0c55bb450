"""backend:=remote: the node's side of the board link to mm-beagle-agent.

:class:`RemoteAgent` offers what :class:`~mm_beagle.poller.poller_client.PollerClient`
offers (``state``, ``command``, ``drain_events``, ...), so the node's services,
topic, diagnostics and onboard odometry read the same shared state whichever
backend fills it. A feeder thread applies the agent's batches in order: a gap
in a sensor's sequence numbers (a lost frame, a link drop) is fetched from the
agent's ring before newer polls are applied; polls older than that ring are
counted as lost and the ring starts after them, while the totals, which come
with every batch, stay exact. A restarted agent (new boot id) continues the
node's totals and sequence numbers instead of resetting them. Stamps are moved
to this machine's clock (offset = the smallest seen delay, allowed to drift
100 ppm), unless ``clock_sync`` is off because both clocks run NTP. A smaller
delay lowers that estimate at once; the offset applied to the stamps follows it
slewed (at most ``CLOCK_SLEW`` of the time between two polls), so a sensor's
stamps never step back: they stay strictly increasing, as the agent took them.
"""

from __future__ import annotations

import collections
import contextlib
import json
import queue
import secrets
import socket
import threading
import time

import numpy as np

from mm_beagle.link import link, link_auth, link_decode, zenoh_config
from mm_beagle.poller import chip_config, commands, ring_layout
from mm_beagle.poller import shared_state as ss
from mm_beagle.poller.options import OPTIONS
from mm_beagle.poller.poller import PollerConfig
from mm_beagle.poller.poller_client import PollerError

LINK_TIMEOUT_S = 1.0  # no batch for this long: the link is down (the agent sends >= 10/s)
COMMAND_TIMEOUT_S = 2.0
HISTORY_TIMEOUT_S = 2.0
GAP_RETRY_S = 5.0  # how long a gap is asked for before its polls count as lost
CLOCK_LEAK = 1e-4  # the clock offset estimate may rise this much per second (100 ppm)
# A lower estimate reaches the stamps at most this fast (ns per ns of poll time): a step of
# d ms is taken in over d / CLOCK_SLEW ms of polls, whose intervals look 5 % shorter meanwhile,
# instead of at once, which put a poll's stamp before its predecessor's (steps of several ms
# under load, against 1 ms between polls).
CLOCK_SLEW = 0.05
RING_DTYPES = ring_layout.WIRE_DTYPES  # a batch block's arrays, in RING_FIELDS order
XY = (ss.I_X_TOTAL, ss.I_Y_TOTAL)
# Plausibility of what the link says (docs/hardware-setup.md, "What a local process can do"):
# a sensor's seq may advance at most SEQ_RATE_MARGIN x the highest poll rate an agent
# accepts, per second since its last block that brought new polls, plus SEQ_SLACK polls.
# Anything beyond is refused, not applied.
MAX_POLL_RATE = float(OPTIONS["poll_rate"].hi or 2000.0)
SEQ_RATE_MARGIN = 1.5
# A burst of frames late from an outage (zenoh's and TCP's buffers) brings seconds of
# polls at once: 65 536 (the default ring, 65 s at 1 kHz) covers it. A forged jump within
# it is caught by the gap fetch: the agent's ring has no polls that far (refused).
SEQ_SLACK = 65_536
GLOB_HOLD_S = 1.0
# A new boot id is followed only when its status arrives after the current boot's frames
# stopped for this long (a restarted agent is silent for seconds: import, bring-up).
BOOT_SILENCE_S = 0.5
RESYNC_S = 2.0  # live blocks refused or stale this long, none taken: follow the agent again
CREDENTIALS_PROBE_S = 3.0  # TCP reaches the agent but zenoh does not open for this long


class RemoteAgent:
    """Feeds a local shared state from an mm-beagle-agent over zenoh."""

    def __init__(
        self,
        cfg: PollerConfig,
        endpoint: str = link.DEFAULT_ENDPOINT,
        name: str = link.DEFAULT_NAME,
        credentials: str = "",
        clock_sync: bool = True,
    ) -> None:
        self.cfg = cfg
        self.endpoint = endpoint
        self.keys = link.keys(name)
        self.credentials = credentials
        self.clock_sync = clock_sync
        zenoh_config.endpoint_host(endpoint)  # LinkError now, not in the thread
        self.auth = link_auth.FrameAuth.from_credentials(credentials, name)
        n = len(cfg.devices)
        self.n = n
        self.state = ss.SharedState(
            bytearray(ss.SharedState.size(n, cfg.ring_size)), n, cfg.ring_size
        )
        self.state.ints[:, ss.I_STATE] = ss.STATE_STARTING
        self._rings = [
            [getattr(self.state, f)[i] for f in ss.SharedState.RING_FIELDS] for i in range(n)
        ]
        self.session = None
        self._queue: queue.Queue = queue.Queue(maxsize=20000)
        self._events: list[tuple] = []
        self._events_lock = threading.Lock()
        self._running = False
        self._threads: list[threading.Thread] = []
        # link state
        self.link_up = False
        self.ever_up = False
        self.since_wall = time.time()  # when the link last changed
        self.last_heard = 0.0  # monotonic time of the newest batch applied
        self.last_rx = 0.0  # ... of the newest frame received on the polls key
        self.link_drops = 0
        self.polls_lost = 0
        self.bad_frames = 0  # every input dropped (undecodable, forged or implausible)
        self.drops = link_decode.DropLog()  # ... per kind, and the rate-limited log line
        self.refused = 0  # of those: well-formed but refused (auth, boot id, seq, totals)
        self.unannounced = 0  # batches of a boot whose status has not come yet (not counted)
        self.restarts = 0
        self.refused_credentials = ""  # the agent is reached by TCP but the session never opens
        self._tcp_probe_t = 0.0
        self._tcp_since: float | None = None  # since when TCP reaches the agent
        self._started = time.monotonic()
        self.agent_status: dict = {}
        self.mismatch = ""  # the agent serves other devices than this node expects
        self.query_error = ""
        self._history_q: queue.Queue = queue.Queue(maxsize=64)
        self._history_pub = None
        self._history_id = secrets.randbits(40)  # request ids a peer cannot guess ahead
        self.latency_ms: collections.deque = collections.deque(maxlen=4096)
        # poll stamp -> applied here (ms; meaningful on one clock: benchmarks)
        self.apply_latency_ms: collections.deque = collections.deque(maxlen=100_000)
        self._offset_ns: int | None = None  # the estimate (smallest delay, leaking up)
        self._offset_t = 0.0
        # per sensor: the offset applied to its newest poll's stamp, and that poll's agent stamp
        self._stamp_off: list[int | None] = [None] * n
        self._stamp_raw: list[int] = [0] * n
        # sequence bookkeeping, per sensor
        self.boot: int | None = None
        self.boots_seen: set[int] = set()  # a boot once left is never followed again
        self.boot_devices: tuple | None = None  # devices/chips of this boot (never change)
        self.boot_heard = 0.0  # monotonic time of the newest accepted frame of this boot
        self.batch_number = 0  # the newest batch frame of this boot applied
        self._batch_t = 0.0  # when batch_number was set
        # per sensor (node time, agent seq end) of the newest block that brought new polls
        self._seq_ref: list[tuple[float, int] | None] = [None] * n
        # per sensor: (x, y) counts of history polls applied since the last live totals
        self._accepted_t = [time.monotonic()] * n  # when its last live block was taken
        self.resyncs = 0  # times a sensor followed the agent again after a forgery
        self._pending = [[0, 0] for _ in range(n)]
        # the node's counts start at its first contact: the stamp of that poll (node clock,
        # ns), the origin of its first read-and-clear interval (0: not reached yet)
        self.origin_ns = 0
        self.next_agent = [None] * n  # next agent seq expected
        self.base_i = np.zeros((n, ss.N_INT), np.int64)
        self.base_f = np.zeros((n, ss.N_FLOAT), np.float64)
        self.agent_i = np.zeros((n, ss.N_INT), np.int64)  # the agent's newest totals
        self.agent_f = np.zeros((n, ss.N_FLOAT), np.float64)
        self._mono = list(ss.MONOTONE_INTS)

    # --- what the node uses (the PollerClient interface) ---

    def start(self) -> None:
        self._running = True
        for target, name in ((self._connect, "mm_link_connect"), (self._feed, "mm_link_feed")):
            t = threading.Thread(target=target, name=name, daemon=True)
            t.start()
            self._threads.append(t)

    @property
    def alive(self) -> bool:
        return self._running and self._threads[1].is_alive()

    def index(self, device: str) -> int | None:
        try:
            return self.cfg.devices.index(device)
        except ValueError:
            return None

    def unavailable(self) -> str:
        """'' while the link is up, else what the services answer."""
        if self.mismatch:
            return self.mismatch
        if self.link_up:
            return ""
        if self.refused_credentials and not self.ever_up:
            return self.refused_credentials
        since = time.strftime("%H:%M:%S", time.localtime(self.since_wall))
        ago = time.time() - self.since_wall
        what = "unreachable since" if self.ever_up else "not reached yet, trying since"
        return f"agent at {self.endpoint} {what} {since} ({ago:.0f} s)"

    def command(self, kind: str, i: int, *args: object, timeout: float = COMMAND_TIMEOUT_S):
        """One agent command: ("ok"|"invalid"|"error", payload), once its effect is here."""
        problem = self.unavailable()
        if problem or self.session is None:
            raise PollerError(problem or f"agent at {self.endpoint} not connected")
        msg = commands.to_link(kind, self.cfg.devices[i], *args)  # load_patch: a file name
        reply = self._query(self.keys["cmd"], json.dumps(msg).encode(), timeout)
        if reply is None:
            raise PollerError(
                f"agent at {self.endpoint} did not answer {kind!r} within {timeout:g} s"
                f" ({self.query_error})"
            )
        status, payload, seqs, _boot = reply
        self._wait_applied(seqs, deadline=time.monotonic() + 1.0)
        return status, payload

    def drain_events(self) -> list[tuple]:
        with self._events_lock:
            out, self._events = self._events, []
        return out

    def cpu_percent(self) -> float:
        """The agent's CPU use (% of one of its cores), as it last reported."""
        return float(self.agent_status.get("cpu_percent", float("nan")))

    def link_values(self) -> dict[str, object]:
        """Link figures for /diagnostics."""
        lat = np.array(self.latency_ms) if self.latency_ms else np.array([np.nan])
        return {
            "backend": "remote",
            "agent": self.endpoint,
            "link": "up" if self.link_up else self.unavailable(),
            "link_drops": self.link_drops,
            "link_polls_lost": self.polls_lost,
            "link_bad_frames": self.bad_frames,
            "link_refused_frames": self.refused,
            "link_resyncs": self.resyncs,
            "link_dropped_by_kind": self._drop_counts(),
            "agent_restarts": self.restarts,
            "link_latency_p50_ms": f"{np.nanpercentile(lat, 50):.2f}",
            "link_latency_p99_ms": f"{np.nanpercentile(lat, 99):.2f}",
            "agent_rss_mb": self.agent_status.get("rss_mb", ""),
            "agent_requests_refused": self.agent_status.get("requests_refused", ""),
        }

    def _drop_counts(self) -> str:
        return ", ".join(f"{k} {v}" for k, v in sorted(self.drops.counts.items())) or "none"

    def stop(self, timeout: float = 3.0) -> None:
        self._running = False
        for t in self._threads[1:]:
            t.join(timeout)
        if self.session is not None:
            with contextlib.suppress(Exception):  # a session whose peer is gone may complain
                self.session.close()

    # --- the threads ---

    def _emit(self, *event: object) -> None:
        with self._events_lock:
            self._events.append(tuple(event))

    def _connect(self) -> None:
        """Open the session (blocks until the agent is first reached), then subscribe."""
        import zenoh

        try:
            session = zenoh.open(
                zenoh_config.zenoh_config(connect=[self.endpoint], credentials=self.credentials)
            )
        except Exception as exc:
            self._emit("log", f"cannot open the link to {self.endpoint}: {exc}")
            return
        if not self._running:
            session.close()
            return
        self._block_cc = zenoh.CongestionControl.BLOCK
        self._target_all = zenoh.QueryTarget.ALL
        self._no_consolidation = zenoh.ConsolidationMode.NONE
        self.session = session
        q = self._queue

        limits = {
            "polls": min(link.max_batch_bytes(self.n), link.NODE_RX_MAX_BYTES),
            "status": link_decode.MAX_STATUS_BYTES,
            "events": link_decode.MAX_EVENT_BYTES,
        }

        def put(kind: str):
            limit = limits[kind]

            def cb(sample) -> None:
                # size first: a payload over the limit is never copied out of zenoh
                size = len(sample.payload)
                item = (kind, b"", time.time_ns(), None, size)
                if size <= limit:
                    if kind == "polls":  # the link carries frames (a gap fetch waits for it)
                        self.last_rx = time.monotonic()
                    data = sample.payload.to_bytes()
                    item = (kind, data, item[2], link_auth.attachment_bytes(sample), size)
                # a full queue: the feeder is behind; the seq gap is fetched from the agent's ring
                with contextlib.suppress(queue.Full):
                    q.put_nowait(item)

            return cb

        self._subs = [
            session.declare_subscriber(self.keys[k], put(k)) for k in ("polls", "status", "events")
        ]

        def history(sample) -> None:
            if len(sample.payload) > limits["polls"]:
                return  # counted when nothing answers the request
            item = (sample.payload.to_bytes(), link_auth.attachment_bytes(sample))
            with contextlib.suppress(queue.Full):
                self._history_q.put_nowait(item)

        self._subs.append(session.declare_subscriber(self.keys["history"], history))
        self._history_pub = session.declare_publisher(
            self.keys["history_req"], congestion_control=zenoh.CongestionControl.BLOCK
        )

    def _feed(self) -> None:
        """Apply what arrives, in order; no input ends this thread (the node would stop)."""
        while self._running:
            try:
                kind, data, recv_ns, tag, size = self._queue.get(timeout=0.1)
            except queue.Empty:
                self._watch_link()
                self._probe_credentials()
                continue
            self._handle(kind, data, recv_ns, tag, size)
            self._watch_link()

    def _handle(self, kind: str, data: bytes, recv_ns: int, tag, size: int) -> None:
        """Apply one input, or drop, count and log it: nothing raises out of here."""
        try:
            self._on_input(kind, data, recv_ns, tag, size)
        except Refused as exc:
            self.refused += 1
            self._dropped(kind, str(exc))
        except link.LinkError as exc:
            self._dropped(kind, str(exc))
        except Exception as exc:  # a bug or an input no check foresaw: drop it, go on
            self._dropped(kind, f"{type(exc).__name__}: {str(exc)[:200]}")

    def _dropped(self, kind: str, why: str) -> None:
        self.bad_frames += 1
        line = self.drops.drop(kind, why)
        if line:
            self._emit("log", line)

    def _on_input(self, kind: str, data: bytes, recv_ns: int, tag, size: int) -> None:
        if len(data) != size:
            raise link.LinkError(f"{kind} message of {size} bytes is too large")
        try:
            self.auth.check(kind, data, tag)
        except link.LinkError as exc:
            raise Refused(str(exc)) from None
        if kind == "polls":
            self._on_batch(link.decode_batch(data, self.n), recv_ns)
        elif kind == "status":
            self._on_status(data)
        else:
            self._on_event(data)

    def _probe_credentials(self) -> None:
        """Never reached yet: is something listening there that does not let us in?"""
        now = time.monotonic()
        if self.ever_up or now - self._tcp_probe_t < 1.0 or not self.endpoint.startswith("tcp/"):
            return
        self._tcp_probe_t = now
        host = zenoh_config.endpoint_host(self.endpoint)
        port = int(self.endpoint.rpartition(":")[2].split("#", 1)[0])
        try:
            with socket.create_connection((host, port), timeout=0.5):
                pass
        except OSError:
            self._tcp_since = None
            self.refused_credentials = ""
            return
        if self._tcp_since is None:
            self._tcp_since = now
        waited = now - self._tcp_since
        if self.session is None and waited >= CREDENTIALS_PROBE_S and not self.refused_credentials:
            what = "our credentials" if self.credentials else "us without credentials"
            self.refused_credentials = (
                f"agent at {self.endpoint} refused {what}: it listens but the zenoh "
                f"session does not open (agent_credentials must be the agent's "
                f"--credentials file; {link_auth.CREDENTIALS_HELP})"
            )
            self._emit("log", self.refused_credentials)

    def _watch_link(self, heard: float | None = None) -> None:
        """Mark the link down once nothing was heard for LINK_TIMEOUT_S (``heard``:
        the newest frame's time if newer than the last applied batch)."""
        heard = self.last_heard if heard is None else max(heard, self.last_heard)
        if self.link_up and time.monotonic() - heard > LINK_TIMEOUT_S:
            self.link_up = False
            self.link_drops += 1
            self.since_wall = time.time()
            self._emit("log", f"link to the agent at {self.endpoint} lost; reconnecting")

    # --- applying what the agent sent ---

    def _on_batch(self, batch: link.Batch, recv_ns: int) -> None:
        if self.mismatch:
            return
        if self.boot is None or (
            batch.boot_id != self.boot and time.monotonic() - self.boot_heard >= BOOT_SILENCE_S
        ):
            self.unannounced += 1  # a (re)started agent before its status: not yet followed
            return
        if batch.boot_id != self.boot:
            raise Refused(
                f"a batch of boot {batch.boot_id:#x}, not of the agent's boot {self.boot:#x} "
                "(a new boot is followed only after its status, once the old one fell silent)"
            )
        now = time.monotonic()
        self._check_blocks(batch, now)
        self.boot_heard = now
        self.last_heard = now
        if not self.link_up:
            self.link_up = self.ever_up = True
            self.since_wall = time.time()
            self._emit("log", f"link to the agent at {self.endpoint} up")
        # a frame overtaken by a newer one (the subscriber's callbacks may run on several
        # threads): its polls are skipped as already applied, its older counters too. A
        # number far ahead (forged) holds the counters back for GLOB_HOLD_S at most.
        if batch.number > self.batch_number or now - self._batch_t > GLOB_HOLD_S:
            self.batch_number, self._batch_t = batch.number, now
            self.state.glob[:] = np.frombuffer(batch.glob, np.int64)
        newest = max(
            (int(np.frombuffer(b.ints, np.int64)[ss.I_STAMP_NS]) for b in batch.blocks if b.count),
            default=0,
        )
        clock = (self._offset_ns, self._offset_t)
        if newest:  # before applying: the very first polls get an offset too
            self._clock(recv_ns, newest)
        for k, block in enumerate(batch.blocks):
            before = self.next_agent[block.index]
            try:
                self._apply(block, fetch_gaps=True)
            except Refused:
                if k == 0:  # nothing of it applied: its stamp must not move the clock either
                    self._offset_ns, self._offset_t = clock
                raise
            self._seq_reference(block, before, now)
            if not self.origin_ns and np.frombuffer(block.ints, np.int64)[ss.I_STAMP_NS] > 0:
                self.origin_ns = int(self.state.ints[block.index][ss.I_STAMP_NS])
        # a gap fetch can take seconds: frames that kept arriving meanwhile mean the link is
        # up (else the feeder would call it lost the moment the fetch returns)
        self.last_heard = max(self.last_heard, self.last_rx)
        if newest:
            self.apply_latency_ms.append((time.time_ns() - newest) / 1e6)

    def _check_blocks(self, batch: link.Batch, now: float) -> None:
        """Refuse a live batch whose sequence numbers cannot be the agent's: a seq beyond
        what the time since the sensor's last block allows, totals whose seq is not the
        block's end (counts that do not add up: :meth:`_apply`)."""
        seen = set()
        for b in batch.blocks:
            i = b.index
            if i in seen:
                raise Refused(f"batch names sensor {i} twice")
            seen.add(i)
            ints = np.frombuffer(b.ints, np.int64)
            end = b.first_seq + b.count
            if int(ints[ss.I_SEQ]) != end:
                raise Refused(
                    f"block of sensor {i}: totals at seq {int(ints[ss.I_SEQ])}, not {end}"
                )
            expected = self.next_agent[i]
            if expected is None:
                continue
            ref = self._seq_ref[i]
            if ref is not None:
                elapsed = now - ref[0]
                most = elapsed * MAX_POLL_RATE * SEQ_RATE_MARGIN + SEQ_SLACK
                if end - ref[1] > most:
                    raise Refused(
                        f"sensor {i}'s seq {end} is {end - ref[1]} polls past seq {ref[1]} "
                        f"of {elapsed:.2f} s ago (at most {most:.0f})"
                    )

    def _seq_reference(self, block: link.Block, before: int | None, now: float) -> None:
        """(now, end) becomes sensor i's seq reference when ``block`` brought new polls."""
        end = block.first_seq + block.count
        if before is None or self.next_agent[block.index] != before:
            self._seq_ref[block.index] = (now, end)

    def _new_boot(self, boot_id: int, uptime_s: float = 0.0) -> None:
        if self.boot is not None:  # a restarted agent: continue from what we had
            self.restarts += 1
            self.base_i[:, self._mono] += self.agent_i[:, self._mono]
            self.base_f += self.agent_f
            self.agent_i[:] = 0
            self.agent_f[:] = 0
            self.next_agent = [0] * self.n  # its polls since it started: fetch what we missed
            self._emit("log", "the agent restarted: totals and sequence numbers continue")
            self.boots_seen.add(self.boot)
        self.boot = boot_id
        self.boot_devices = None
        now = time.monotonic()
        self.boot_heard = now
        self.batch_number = 0
        self._batch_t = now
        # its polls since it started are to come: the seq check counts from its start
        up = min(max(uptime_s, 0.0), 1e6) if uptime_s == uptime_s else 0.0
        self._seq_ref = [(now - up, 0)] * self.n

    def _apply(self, block: link.Block, fetch_gaps: bool, totals: bool = True) -> None:
        """Write a block's new polls into the ring and, with ``totals``, publish its totals.

        A history reply (``totals=False``) carries the agent's newest totals, not those
        after its polls: published, they would serve a seq beyond the polls written (old
        ring slots) that steps back with the next batch. Its polls stay unseen until the
        live batch after the gap publishes its own totals.
        """
        i = block.index
        first, count = block.first_seq, block.count
        end = first + count
        expected = self.next_agent[i]
        check = totals  # a live block right after known polls: its counts must add up
        if expected is None:  # first contact: the node's totals and ring start after it
            if not totals:
                return
            self._zero_at(i, block)
            expected = self.next_agent[i] = end
            self.state.ints[i][ss.I_RING_FROM] = self.base_i[i][ss.I_SEQ] + end
            check = False
        elif end < expected or (end == expected and count):
            if not (totals and self._resync_due(i, block)):
                return  # already applied (a history reply overlapping the live stream)
            expected, check = self._resync(i, block, "are behind the node's"), False
        if first > expected:
            if fetch_gaps:
                self._fill_gap(i, expected, first)
                expected = self.next_agent[i]
            if first > expected:  # what the agent's ring no longer holds
                check = False
                self._pending[i] = [0, 0]
                self.polls_lost += first - expected
                self._emit(
                    "log",
                    f"{first - expected} single polls of {self.cfg.devices[i]} "
                    f"({expected}..{first}) are lost: the agent did not send them "
                    f"({self.query_error}); the totals are exact",
                )
                self.state.ints[i][ss.I_RING_FROM] = self.base_i[i][ss.I_SEQ] + first
                expected = first
        skip = expected - first
        ints = np.frombuffer(block.ints, np.int64)
        floats = np.frombuffer(block.floats, np.float64)
        sums = [0, 0]
        if count > skip:
            sums = [
                int(np.frombuffer(block.arrays[k], RING_DTYPES[k])[skip:].sum()) for k in (1, 2)
            ]
        if check:
            have = [int(self.agent_i[i][k]) + p for k, p in zip(XY, self._pending[i], strict=True)]
            got = [int(ints[k]) for k in XY]
            if [h + d for h, d in zip(have, sums, strict=True)] != got:
                if not self._resync_due(i, block):
                    raise Refused(f"sensor {i}'s totals {got} are not {have} + its polls {sums}")
                expected = self._resync(i, block, "do not add up to the node's")
                skip = 0
                sums = [int(np.frombuffer(block.arrays[k], RING_DTYPES[k]).sum()) for k in (1, 2)]
            self._pending[i] = [0, 0]
        elif not totals:  # a history reply: its counts are in the next live block's totals
            self._pending[i] = [p + d for p, d in zip(self._pending[i], sums, strict=True)]
        sync = self.clock_sync and self._offset_ns is not None
        st = self.state.ints[i]
        st[ss.I_VERSION] += 1  # odd: writing
        if count > skip:
            node_first = int(self.base_i[i][ss.I_SEQ]) + expected
            slots = np.arange(node_first, node_first + count - skip) % self.state.ring_size
            for ring, data, dtype in zip(self._rings[i], block.arrays, RING_DTYPES, strict=True):
                ring[slots] = np.frombuffer(data, dtype)[skip:]
            if sync:
                stamps = self._rings[i][0]
                stamps[slots] += self._stamp_offsets(i, stamps[slots])
        if end >= expected and totals:
            self.agent_i[i] = ints
            self.agent_f[i] = floats
            # every field but the lock word (never the agent's version, even for a moment:
            # a reader would take a half-written snapshot) and the node's own ring start
            fields = ints.copy()
            fields[self._mono] += self.base_i[i][self._mono]
            if sync:  # the newest poll's stamp, as its ring slot has it
                off = self._stamp_off[i]
                fields[ss.I_STAMP_NS] += self._offset_ns if off is None else off
            st[1 : ss.I_RING_FROM] = fields[1 : ss.I_RING_FROM]
            st[ss.I_RING_FROM + 1 :] = fields[ss.I_RING_FROM + 1 :]
            self.state.floats[i] = floats
            self.state.floats[i][: ss.N_TOTAL_FLOAT] += self.base_f[i][: ss.N_TOTAL_FLOAT]
        if end >= expected:
            self.next_agent[i] = end
            if totals:
                self._accepted_t[i] = time.monotonic()
        st[ss.I_VERSION] += 1  # even: consistent

    def _zero_at(self, i: int, block: link.Block) -> None:
        """The node's counts start after ``block``, its first contact with sensor i: the
        agent's totals before it (its whole uptime) are not this node's, or the first
        read-and-clear interval (from the node's start) would carry them."""
        ints = np.frombuffer(block.ints, np.int64)
        floats = np.frombuffer(block.floats, np.float64)
        zero = [k for k in self._mono if k != ss.I_REINITS]
        self.base_i[i][zero] = -ints[zero]
        self.base_f[i][: ss.N_TOTAL_FLOAT] = -floats[: ss.N_TOTAL_FLOAT]

    def _resync_due(self, i: int, block: link.Block) -> bool:
        """Live blocks of sensor i have been refused or skipped as already applied for
        RESYNC_S while none was accepted: the node took a forged one before (consistent
        enough to pass) and now refuses the agent's own. Time to follow the agent again."""
        return bool(block.count) and time.monotonic() - self._accepted_t[i] >= RESYNC_S

    def _resync(self, i: int, block: link.Block, why: str) -> int:
        """Follow the agent's ``block`` again: its polls overwrite the node's from its first
        seq on and its totals replace what a forged block had put there."""
        self.resyncs += 1
        self._pending[i] = [0, 0]
        self._emit(
            "log",
            f"{self.cfg.devices[i]}: the agent's polls {why} for {RESYNC_S:g} s (a forged "
            f"frame was taken before): following the agent's own again from its seq "
            f"{block.first_seq}; the totals are the agent's",
        )
        self.next_agent[i] = block.first_seq
        return block.first_seq

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

    def _query(self, key: str, payload: bytes, timeout: float) -> tuple | None:
        """The first good command reply of the agent's boot: (status, payload, seqs,
        boot_id), or None (``self.query_error`` says why). A reply that fails its tag,
        does not decode or names another boot id is refused and counted."""
        session = self.session
        if session is None:
            self.query_error = "not connected"
            return None
        t0 = time.monotonic()
        deadline = t0 + timeout
        while True:
            replies, refused, errors = 0, [], []
            try:
                # BLOCK: the reply inherits it (zenoh's default drops under load). Every
                # queryable is asked and no reply merged away: the first good one is taken
                # as it arrives, a foreign responder's are refused (it cannot answer first).
                for reply in session.get(
                    key,
                    payload=payload,
                    timeout=max(0.1, deadline - time.monotonic()),
                    congestion_control=self._block_cc,
                    target=self._target_all,
                    consolidation=self._no_consolidation,
                ):
                    replies += 1
                    if reply.ok is not None:
                        good = self._reply(reply.ok)
                        if isinstance(good, tuple):
                            return good
                        refused.append(good)
                    elif reply.err is not None:
                        errors.append(str(reply.err.payload.to_string())[:200])
            except Exception as exc:  # a session closing under us
                self.query_error = f"query failed: {exc}"
                return None
            if refused:
                self.query_error = "; ".join(refused[:3])
                return None
            elapsed = time.monotonic() - t0
            self.query_error = f"{replies} replies in {elapsed:.2f} s, errors: {errors}"
            # A query that ends at once with no reply never reached the agent (zenoh
            # 1.10 right after a reconnection, eclipse-zenoh/zenoh#2767): ask again.
            if replies or time.monotonic() > deadline - 0.1:
                return None
            time.sleep(0.05)

    def _reply(self, sample) -> tuple | str:
        """One command reply checked (tuple), or why it was refused (str, counted)."""
        try:
            if len(sample.payload) > link_decode.MAX_REPLY_BYTES:
                raise link.LinkError(f"a command reply of {len(sample.payload)} bytes")
            data = sample.payload.to_bytes()
            try:
                self.auth.check("reply", data, link_auth.attachment_bytes(sample))
            except link.LinkError as exc:
                raise Refused(str(exc)) from None
            reply = link_decode.decode_command_reply(data, self.n)
            if reply[3] != self.boot:
                raise Refused(
                    f"a command reply from boot {reply[3]}, not the agent's boot {self.boot}"
                )
            return reply
        except Refused as exc:
            self.refused += 1
            self._dropped("reply", str(exc))
            return f"refused a reply: {exc}"
        except Exception as exc:
            self._dropped("reply", f"{type(exc).__name__}: {str(exc)[:200]}")
            return f"a malformed reply: {exc}"

    def _wait_applied(self, seqs: list, deadline: float) -> None:
        """Until the feeder has applied the agent's polls up to ``seqs`` (its reply's)."""
        if not isinstance(seqs, list) or len(seqs) != self.n:
            return
        while time.monotonic() < deadline:
            if all(
                nxt is not None and isinstance(s, int) and nxt >= s
                for nxt, s in zip(self.next_agent, seqs, strict=True)
            ):
                return
            time.sleep(0.002)

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

    def _on_status(self, data: bytes) -> None:
        """A status, checked. Its boot id is how a new agent boot is followed: only when
        the current boot fell silent for BOOT_SILENCE_S and the id was never seen before.
        Devices and chips never change within a boot: a status that says otherwise is
        refused, so a forged one cannot make the services fail."""
        status = link_decode.decode_status(data, self.n, ss.HIST_BINS)
        boot = status["boot_id"]
        if boot != self.boot:
            if boot in self.boots_seen:
                raise Refused(f"a status of the agent's earlier boot {boot:#x}")
            if self.boot is not None:
                silent = time.monotonic() - self.boot_heard
                if silent < BOOT_SILENCE_S:
                    raise Refused(
                        f"a status of boot {boot:#x} while the agent's boot {self.boot:#x} "
                        f"was heard {silent:.2f} s ago"
                    )
            self._new_boot(boot, status["uptime_s"])
        devices = (tuple(status["devices"]), tuple(status["chips"] or ()))
        if self.boot_devices is None:
            self.boot_devices = devices
            self._check_devices(status)
        elif devices != self.boot_devices:
            raise Refused("a status whose devices or chips differ from its boot's first status")
        if self.mismatch:
            return
        first = not self.agent_status
        self.agent_status = status
        if status["hist"] is not None:
            self.state.hist[:] = np.frombuffer(status["hist"], np.int64)
        if first:
            for dev, state, err in zip(
                self.cfg.devices, status["states"], status["last_errors"], strict=True
            ):
                if state == "down":
                    self._emit("down", dev, err)

    def _check_devices(self, status: dict) -> None:
        """Set ``mismatch`` when the agent serves other devices or chips than expected."""
        self.mismatch = ""
        if status["devices"] != self.cfg.devices:
            self.mismatch = (
                f"the agent at {self.endpoint} serves {status['devices']}, this node "
                f"expects {self.cfg.devices}: set the node's 'devices' parameter to match"
            )
        else:
            chips = status["chips"]  # an agent from before issue 15 polls PLN2033s only
            expected = chip_config.resolve_chips(self.cfg.chips, self.cfg.devices)
            if (chips or ["pln2033"] * len(expected)) != expected:
                self.mismatch = (
                    f"the agent at {self.endpoint} polls chips {chips}, this node expects "
                    f"{expected}: set the node's 'chips' parameter to match the agent's --chips"
                )
        if self.mismatch:
            self._emit("log", self.mismatch)

    def _on_event(self, data: bytes) -> None:
        kind, device, text = link_decode.decode_event(data)
        if kind in ("up", "down"):
            if device not in self.cfg.devices:
                raise link.LinkError(f"an event for unknown device {device[:80]!r}")
            self._emit(kind, device, text)
        else:
            self._emit("log", f"agent: {text}")


class Refused(link.LinkError):
    """A well-formed input refused: failed authentication, another boot, an implausible
    sequence number or totals that do not add up. Counted apart from undecodable ones."""
