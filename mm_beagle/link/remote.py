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

This module holds the facade, its session and its threads (connect, feed, the link
watchdog); the parts: applying what arrives (:mod:`~mm_beagle.link.remote_feed`), the gap
fetch (:mod:`~mm_beagle.link.remote_history`), commands
(:mod:`~mm_beagle.link.remote_commands`), the clock (:mod:`~mm_beagle.link.remote_clock`).
"""

from __future__ import annotations

import collections
import contextlib
import queue
import secrets
import socket
import threading
import time

import numpy as np

from mm_beagle.link import link, link_auth, link_decode, zenoh_config
from mm_beagle.link.remote_clock import StampClock
from mm_beagle.link.remote_commands import CommandClient
from mm_beagle.link.remote_feed import Feed, Refused
from mm_beagle.link.remote_history import LINK_TIMEOUT_S, HistoryFetch
from mm_beagle.poller import shared_state as ss
from mm_beagle.poller.poller import PollerConfig

CREDENTIALS_PROBE_S = 3.0  # TCP reaches the agent but zenoh does not open for this long
# The newest batches' latencies kept (about 100 batches/s: ~80 s; mm-bench agent reads
# up to that many). 100 000 grew the node by ~0.19 MB/min for its first 17 min (soak).
LATENCIES_KEPT = 8192


class RemoteAgent(Feed, HistoryFetch, CommandClient, StampClock):
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
        self.apply_latency_ms: collections.deque = collections.deque(maxlen=LATENCIES_KEPT)
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
