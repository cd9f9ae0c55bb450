"""The monitor's only contact with ROS: rclpy in its own thread, results as Qt signals.

The GUI thread never waits on the network. It calls the bridge's methods
(``set_rate``, ``request_once``, ``set_resolution``, ...), which only queue
the action and wake the executor through a guard condition; the action then
runs on the executor thread (where every rclpy object is used), and the
answer comes back as a Qt signal, which Qt delivers on the GUI thread.

Requests of the sample timer: at most ``max_in_flight`` (:data:`MAX_IN_FLIGHT`, 2)
``get_sensor_data`` are in flight, so a round trip of about one period (2 ms at 500 Hz)
no longer costs a tick; replies are handled strictly in the order they were asked (one
that comes early waits for those before it), so totals and polls never go back.
With ``fetch_polls`` (default) each reply brings exactly the polls its totals added
since the previous reply, and the :class:`Reply` is emitted with them
(``Reply.polls``), so the session integrates the pose per poll. The polls come
inside the ``get_sensor_data`` reply (its ``polls_ids``/``polls_since_seq`` fields:
one round trip a reply, docs/beagle-node.md section 3.1); a request sent while another
is out asks from the same cursor, so its polls start with those of the reply before it:
they are cut off at the cursor that reply left (:func:`polls_after`), no poll twice, none
lost. For a sensor the reply has none for (a node without those fields, a busy ring), or
whose polls do not start where they were asked from, one ``get_samples`` follows.
A fetch that fails, takes longer than ``timeout_s`` or whose service disappears
leaves that sensor's entry None (the session then steps over the interval with
the totals and marks the gap). The next ``get_sensor_data`` waits for the fetch.
A tick that finds ``max_in_flight`` requests outstanding is skipped (``skipped_ticks``):
the next reply's totals cover the gap, so a slow link (WLAN latency) costs
neither double counts nor lost counts. A request without an answer after
``timeout_s`` is abandoned and counted in ``dropped_requests``.

Recording live topics: :meth:`RosBridge.record_topics` subscribes (on the
executor thread, with a QoS matching each publisher's) and hands every
message's CDR bytes to the recorder as it arrives, with the publishers'
offered QoS; the GUI thread is not involved.

Connection states: ``waiting`` (the node was never seen), ``connected``
(replies arrive), ``lost`` (it was seen, and now the service is gone or
requests time out). The bridge keeps asking, so a restarted node is found
again by itself.

Delivery: the executor thread puts each :class:`Reply` in an inbox and wakes the
GUI thread only when the inbox was empty; the GUI thread takes the whole inbox
at most :data:`DELIVERY_INTERVAL_S` after the previous take and emits it as
one ``data_received`` (a list of replies, oldest first). At 500 Hz that is ~60 wake-ups of
the GUI thread a second instead of 500 (each one a cross-thread event and a
hand-over of the interpreter lock); at 60 Hz and below every reply is handed on
as it comes (docs/monitor.md, "Threads").
"""

from __future__ import annotations

import queue
import statistics
import threading
import time
from collections import deque
from collections.abc import Callable
from contextlib import suppress
from dataclasses import dataclass
from typing import ClassVar

from PySide6.QtCore import QObject, QTimer, Signal

from mm_pc.core.sensor_data import Reading, Reply

__all__ = ["EXECUTORS", "MAX_RATE_HZ", "MIN_RATE_HZ", "BridgeStats", "RosBridge", "validate_rate"]

MIN_RATE_HZ = 1.0
MAX_RATE_HZ = 500.0
WAITING, CONNECTED, LOST = "waiting", "connected", "lost"
#: rclpy executors the bridge can spin: the C++ EventsExecutor (rclpy.experimental, half
#: the CPU per reply, docs/benchmarks.md) or the Python SingleThreadedExecutor
EVENTS, WAITSET = "events", "waitset"
EXECUTORS = (EVENTS, WAITSET)
#: data requests in flight at once (a second one hides a round trip of about a period)
MAX_IN_FLIGHT = 2
#: a second request waits until this fraction of a period after the one out (else owed)
SPACING = 0.5
#: the GUI thread takes the replies waiting for it at most this often (s): one frame
#: of a 60 Hz screen, so a batch never holds a reply back longer than a frame
DELIVERY_INTERVAL_S = 1 / 60


def validate_rate(value) -> float:
    """A sample rate in Hz, 1..500; ValueError with the allowed range otherwise."""
    try:
        hz = float(value)
    except (TypeError, ValueError):
        raise ValueError(
            f"sample rate must be a number of Hz in {MIN_RATE_HZ:g}..{MAX_RATE_HZ:g}, got {value!r}"
        ) from None
    if not (MIN_RATE_HZ <= hz <= MAX_RATE_HZ):  # also rejects NaN
        raise ValueError(
            f"sample rate must be in {MIN_RATE_HZ:g}..{MAX_RATE_HZ:g} Hz, got {value!r}"
        )
    return hz


@dataclass(frozen=True)
class BridgeStats:
    """Link figures for the status bar: round-trip time (s) and achieved reply rate (Hz)."""

    state: str
    rtt_p50_s: float
    rtt_max_s: float
    rate_hz: float
    requests: int
    replies: int
    skipped_ticks: int
    dropped_requests: int
    failed_replies: int


class RosBridge(QObject):
    """rclpy node + executor thread serving the monitor.

    ``beagle``: namespace/name of the mm_beagle node (its services are
    ``<beagle>/get_sensor_data`` etc.). ``rate_hz``: sample rate of the data
    requests. ``timeout_s``: a request older than this is abandoned.
    """

    data_received = Signal(object)  # list[Reply] delivered together, oldest first
    data_failed = Signal(str)  # what went wrong (success=false, or no reply)
    settings_received = Signal(str, object)  # id, mm_interfaces/SensorSettings
    settings_failed = Signal(str, str)  # id, message
    resolution_done = Signal(str, bool, str, int)  # id, ok, message, CPI read back (0 = unknown)
    samples_received = Signal(str, object)  # id, GetSamples.Response
    samples_failed = Signal(str, str)  # id, message
    diagnostics_received = Signal(object)  # {device: {"level", "message", key: value...}}
    connection_changed = Signal(str)  # waiting | connected | lost
    polling_changed = Signal(bool)  # periodic requests on (True) or paused
    stats_updated = Signal(object)  # BridgeStats, twice a second
    #: the inbox was empty and now holds a reply (emitted on the executor thread)
    _inbox_filled = Signal()

    def __init__(
        self,
        beagle: str = "/mm_beagle",
        rate_hz: float = 15.0,
        node_name: str = "mm_monitor",
        timeout_s: float = 2.0,
        parent: QObject | None = None,
        fetch_polls: bool = True,
        executor: str = EVENTS,
    ) -> None:
        super().__init__(parent)
        self.beagle = "/" + beagle.strip("/") if beagle.strip("/") else "/mm_beagle"
        self._rate = validate_rate(rate_hz)
        self.node_name = node_name
        self.timeout_s = float(timeout_s)
        #: settings, CPI and samples calls may take longer (the node talks to the chip)
        self.call_timeout_s = 2.5 * self.timeout_s
        self._actions: queue.SimpleQueue[Callable[[], None]] = queue.SimpleQueue()
        if executor not in EXECUTORS:
            raise ValueError(f"executor must be one of {', '.join(EXECUTORS)}, got {executor!r}")
        #: rclpy's C++ events executor (default) or its Python wait-set executor
        self.executor = executor
        self._thread: threading.Thread | None = None
        #: set by stop() to end the events executor's loop (a plain flag: it is read once
        #: per event, and Event.is_set is a Python call each time)
        self._stopping = False
        self._polling = True
        self._state = WAITING
        #: data requests out, oldest first: _Request; executor thread only
        self._in_flight: deque[_Request] = deque()
        #: how many may be out at once (1: the one-at-a-time bridge of before)
        self.max_in_flight = MAX_IN_FLIGHT
        self._draining = False
        #: other calls in flight: future -> (service, device, deadline); executor thread only
        self._pending: dict[object, tuple[str, str, float]] = {}
        self._rtts: deque[float] = deque(maxlen=200)
        self._reply_times: deque[float] = deque(maxlen=2000)
        #: fetch the single polls with each reply (the per-poll pose)
        self.fetch_polls = bool(fetch_polls)
        #: device -> the seq up to which polls were fetched; executor thread only
        self._poll_cursor: dict[str, int] = {}
        #: ask for the polls inside the get_sensor_data reply (its polls_ids fields);
        #: False (or an interface without them) = one get_samples per sensor, as before
        self.polls_in_reply = True
        #: a reply waiting for its polls: [Reply, {device: response or None}, {future: device},
        #: deadline]; executor thread only
        self._poll_fetch: list | None = None
        self.poll_fetches = self.poll_fetch_failures = 0
        self.requests = self.replies = self.skipped_ticks = 0
        #: requests sent while another was still out (two in flight), and their replies
        #: that brought the same polls' seqs as the reply before (not handed on)
        self.overlapped_requests = self.duplicate_replies = 0
        self._last_seqs: tuple = ()
        self._last_at = -1.0
        self.dropped_requests = self.failed_replies = 0
        self._consecutive_failures = 0
        #: a tick found a request out: ask again as soon as it is done, not at the next tick
        #: (a cycle a little longer than the period would otherwise halve the rate)
        self._owed = False
        #: live-topic subscriptions for a recorder; executor thread only
        self._recording_subs: list = []
        #: live topics that could not be subscribed: topic -> why
        self.recording_skipped: dict[str, str] = {}
        #: replies for the GUI thread (filled on the executor thread, taken by _deliver)
        self._inbox: list[Reply] = []
        self._inbox_lock = threading.Lock()
        self._delivered_at = -1.0  # time.monotonic() of the last take
        self._delivery = QTimer(self)
        self._delivery.setSingleShot(True)
        self._delivery.timeout.connect(self._deliver)
        self._inbox_filled.connect(self._schedule_delivery)

    # -- life cycle (GUI thread) ---------------------------------------------------------

    def start(self) -> None:
        """Create the node in a private rclpy context and spin it in a thread."""
        import rclpy
        from diagnostic_msgs.msg import DiagnosticArray
        from rclpy.context import Context

        from mm_pc.ros.services import service_types

        self._ctx = Context()
        rclpy.init(context=self._ctx)
        # no parameter services: the monitor has no parameters, and six services fewer
        # in every wait set is CPU saved per reply (docs/benchmarks.md, gui section)
        self.node = rclpy.create_node(
            self.node_name, context=self._ctx, start_parameter_services=False
        )
        self._types = service_types()
        self._clients = {
            n: self.node.create_client(t, f"{self.beagle}/{n}") for n, t in self._types.items()
        }
        self.node.create_subscription(DiagnosticArray, "/diagnostics", self._on_diagnostics, 10)
        self._timer = self.node.create_timer(1.0 / self._rate, self._tick)
        self.node.create_timer(0.1, self._watchdog)
        self.node.create_timer(0.5, self._publish_stats)
        self._executor = self._make_executor()
        self._executor.add_node(self.node)
        self._stopping = False
        self._thread = threading.Thread(target=self._spin, name="mm_monitor_ros", daemon=True)
        self._thread.start()

    def _make_executor(self):
        """The executor ``self.executor`` names; ``events`` falls back to ``waitset`` where
        rclpy has no EventsExecutor (then ``self.executor`` says ``waitset``)."""
        if self.executor == EVENTS:
            try:
                from rclpy.experimental import EventsExecutor
            except ImportError:
                self.executor = WAITSET
            else:
                return EventsExecutor(context=self._ctx)
        from rclpy.executors import SingleThreadedExecutor

        # the GUI's actions wake this executor through a guard condition (the events
        # executor has none: actions reach it as tasks, see _post)
        self._wake = self.node.create_guard_condition(self._run_actions)
        return SingleThreadedExecutor(context=self._ctx)

    def _spin(self) -> None:
        from rclpy.executors import ExternalShutdownException

        self._run_actions()  # those posted before start()
        with suppress(ExternalShutdownException, RuntimeError):
            if self.executor == WAITSET:
                self._executor.spin()
                return
            # spin_once in a loop: the events executor's spin() does not run timers here
            # (rclpy 7.1.5), and the loop ends once stop() sets the flag (or the context
            # is shut down: spin_once raises)
            while not self._stopping:
                self._executor.spin_once(0.1)

    def stop(self) -> None:
        """Stop the executor thread and shut the private context down (idempotent)."""
        if self._thread is None:
            return
        self._stopping = True  # ends the events executor's loop ...
        self._executor.shutdown(timeout_sec=5.0)  # ... and the wait-set one's spin()
        self._thread.join(5.0)
        alive, self._thread = self._thread.is_alive(), None
        self._delivery.stop()
        with self._inbox_lock:
            self._inbox.clear()  # nobody listens for them any more
        if alive:
            return  # a thread still waiting on the node's handles would raise if they went
        with suppress(Exception):
            self.node.destroy_node()
        with suppress(Exception):
            self._ctx.try_shutdown()

    @property
    def running(self) -> bool:
        return self._thread is not None

    @property
    def thread_native_id(self) -> int | None:
        """The OS id of the executor thread (None when not running): for CPU per thread."""
        return self._thread.native_id if self._thread is not None else None

    # -- requests from the GUI (any thread) ---------------------------------------------

    def _post(self, action: Callable[[], None]) -> None:
        self._actions.put(action)
        if self._thread is None:
            return  # the thread runs them when it starts
        if self.executor == WAITSET:
            self._wake.trigger()
        else:  # thread-safe: the events executor posts the task to its own loop
            self._executor.create_task(self._run_actions)

    def _run_actions(self) -> None:
        while True:
            try:
                action = self._actions.get_nowait()
            except queue.Empty:
                return
            try:
                action()
            except Exception as e:  # a task would keep it to itself: say it
                self.node.get_logger().error(f"monitor action failed: {e!r}")

    @property
    def rate_hz(self) -> float:
        return self._rate

    def set_rate(self, hz) -> float:
        """Change the sample rate (1..500 Hz); ValueError (nothing changed) otherwise."""
        rate = validate_rate(hz)
        self._rate = rate

        def apply() -> None:
            self._timer.cancel()
            self.node.destroy_timer(self._timer)
            self._timer = self.node.create_timer(1.0 / rate, self._tick)

        self._post(apply)
        return rate

    @property
    def polling(self) -> bool:
        return self._polling

    def set_polling(self, on: bool) -> None:
        """Pause (False) or resume (True) the periodic data requests."""
        if bool(on) != self._polling:
            self._polling = bool(on)
            self.polling_changed.emit(self._polling)

    def request_once(self) -> None:
        """One data request now (the debug view's 'request sample')."""
        self._post(lambda: self._request_data(manual=True))

    def request_settings(self, device: str) -> None:
        self._post(lambda: self._call("get_sensor_settings", device, id=device))

    def set_resolution(self, device: str, cpi: int) -> None:
        self._post(lambda: self._call("set_resolution", device, id=device, cpi=int(cpi)))

    def request_samples(self, device: str, since_seq: int = 0, max_samples: int = 0) -> None:
        self._post(
            lambda: self._call(
                "get_samples", device, id=device, since_seq=int(since_seq),
                max_samples=int(max_samples),
            )
        )

    def record_topics(self, topics, sink) -> None:
        """Subscribe to ``topics`` (:class:`~mm_pc.monitor.io.bag_format.LiveTopic`) and call
        ``sink(topic, type_name, cdr_bytes, offered_qos)`` for each message, on the executor
        thread, until :meth:`stop_recording_topics`. ``offered_qos``: the publishers'
        profiles (rosbag2's v9 dicts), looked up at the topic's first message. A type
        that is not installed is skipped (``recording_skipped`` says why)."""
        self._post(lambda: self._subscribe_raw(tuple(topics), sink))

    def stop_recording_topics(self) -> None:
        """End the subscriptions of :meth:`record_topics` (messages already queued may
        still reach the sink: the recorder drops them once closed)."""
        self._post(self._unsubscribe_raw)

    def _subscribe_raw(self, topics, sink) -> None:
        import importlib

        self._unsubscribe_raw()
        for t in topics:
            pkg, _, name = t.type_name.split("/")
            try:
                msg_type = getattr(importlib.import_module(f"{pkg}.msg"), name)
            except (ImportError, AttributeError) as e:
                self.recording_skipped[t.name] = f"{t.type_name} is not installed ({e})"
                continue
            offered: dict[str, list] = {}

            def on_message(data, t=t, offered=offered) -> None:
                if "qos" not in offered:
                    offered["qos"] = self._offered_qos(t.name) or [t.qos]
                sink(t.name, t.type_name, data, offered["qos"])

            self._recording_subs.append(
                self.node.create_subscription(
                    msg_type, t.name, on_message, _qos_from_dict(t.subscription_qos), raw=True
                )
            )

    def _unsubscribe_raw(self) -> None:
        for sub in self._recording_subs:
            with suppress(Exception):
                self.node.destroy_subscription(sub)
        self._recording_subs = []

    def _offered_qos(self, topic: str) -> list[dict]:
        try:
            infos = self.node.get_publishers_info_by_topic(topic)
        except Exception:  # a graph query must not stop the recording
            return []
        return [_qos_to_dict(i.qos_profile) for i in infos]

    # -- executor thread ------------------------------------------------------------------

    def _tick(self) -> None:
        if self._polling:
            self._request_data(manual=False)

    def _full(self) -> bool:
        """No room for another data request: ``max_in_flight`` out, a reply waiting for its
        polls, or (polls in the reply) no cursors yet: a second request would ask for no
        polls and its reply need a get_samples per sensor."""
        limit = self.max_in_flight
        if self.fetch_polls and self.polls_in_reply and not self._poll_cursor:
            limit = 1
        if len(self._in_flight) >= limit or self._poll_fetch is not None:
            return True
        # two requests sent closer than half a period (the timer catching up after the
        # thread was held up) reach the node in the same poll: the second brings nothing
        return bool(self._in_flight) and (
            time.monotonic() - self._in_flight[-1].sent < SPACING / self._rate
        )

    def _pay_owed(self) -> None:
        """The request a skipped tick owes, once there is room for it."""
        if self._owed and self._polling and not self._full():
            self._owed = False
            self._request_data(manual=False)

    def _request_data(self, manual: bool) -> None:
        client = self._clients["get_sensor_data"]
        if self._full():
            if not manual:
                self.skipped_ticks += 1
                self._owed = True
            return
        if not client.service_is_ready():
            return
        self.requests += 1
        self.overlapped_requests += bool(self._in_flight)
        request = self._data_request()
        asked = dict(zip(getattr(request, "polls_ids", ()),
                         (int(s) for s in getattr(request, "polls_since_seq", ())), strict=False))
        entry = _Request(None, time.monotonic(), asked, overlapped=bool(self._in_flight))
        entry.future = client.call_async(request)
        self._in_flight.append(entry)
        entry.future.add_done_callback(lambda f: self._on_data(f, entry))

    def _data_request(self):
        """``get_sensor_data`` for every sensor; with ``fetch_polls`` it asks for the polls of
        every sensor with a cursor in the same reply (``polls_ids``), where the interface
        has those fields (one round trip a reply instead of 1 + one ``get_samples`` each)."""
        request_type = self._types["get_sensor_data"].Request
        if not (
            self.fetch_polls
            and self.polls_in_reply
            and self._poll_cursor
            and hasattr(request_type, "polls_ids")
        ):
            return request_type(id="")
        ids = list(self._poll_cursor)
        return request_type(
            id="", polls_ids=ids, polls_since_seq=[self._poll_cursor[d] for d in ids]
        )

    def _on_data(self, future, entry: _Request) -> None:
        """A data reply came: handle it and every one after it that came already, in the
        order they were asked (one before it still out: it waits)."""
        if entry not in self._in_flight:
            return  # abandoned by the watchdog
        entry.arrived = time.monotonic()
        self._drain()

    def _drain(self) -> None:
        if self._draining:
            return  # a reply handled inside the loop below: the loop goes on
        self._draining = True
        try:
            while self._in_flight and self._in_flight[0].arrived is not None:
                if self._poll_fetch is not None:
                    return  # the reply before waits for its polls: this one after it
                self._handle_data(self._in_flight.popleft())
        finally:
            self._draining = False
        self._pay_owed()

    def _handle_data(self, entry: _Request) -> None:
        sent, now = entry.sent, entry.arrived
        res = entry.future.result()
        if res is not None and not res.success and res.message.startswith("polls_"):
            # the cursors do not fit this node (a restarted one counts from 0 again):
            # ask again at once without polls; the next reply starts new cursors
            self._poll_cursor.clear()
            self.poll_fetch_failures += 1
            self._owed = True
            return
        if res is None or not res.success:
            self.failed_replies += 1
            self.data_failed.emit(res.message if res is not None else "no reply")
            if res is not None:
                self._set_state(CONNECTED)  # the node answers; its sensors are down
            return
        self._consecutive_failures = 0
        self._rtts.append(now - sent)
        self._set_state(CONNECTED)
        seqs = tuple((m.id, m.seq) for m in res.data)
        if entry.overlapped and seqs == self._last_seqs and now - self._last_at < 1 / self._rate:
            # served in the same poll as the reply before it (the node had both requests
            # waiting): nothing new; a reply a period later is handed on even so
            self.duplicate_replies += 1
            return
        self._last_seqs, self._last_at = seqs, now
        self.replies += 1
        self._reply_times.append(now)
        readings = tuple(Reading.from_msg(m) for m in res.data)
        reply = Reply(readings, received_s=now, rtt_s=now - sent)
        if self.fetch_polls:
            self._fetch_polls(reply, {p.id: p for p in getattr(res, "polls", ())}, entry.asked)
        else:
            self._hand_on(reply)

    # -- the single polls of a reply (executor thread) --------------------------------------

    def _fetch_polls(
        self, reply: Reply, in_reply: dict[str, object], asked: dict[str, int] | None = None
    ) -> None:
        """Each sensor's polls since its cursor up to this reply's seq: those the reply
        carried (``in_reply``, device -> SensorPolls, asked from the cursors ``asked`` of
        :meth:`_data_request`; cut at the cursor now when a reply before this one moved
        it), the others (a node without the polls fields, a busy ring) asked with one
        ``get_samples`` per sensor; emit when all are there."""
        from types import SimpleNamespace

        polls: dict[str, object] = {}
        waiting: dict[object, str] = {}
        client = self._clients["get_samples"]
        request_type = self._types["get_samples"].Request
        for r in reply.readings:
            since = self._poll_cursor.get(r.id)
            self._poll_cursor[r.id] = r.seq
            if since is None or r.seq <= since:  # first reply, nothing new, or a restart
                polls[r.id] = SimpleNamespace(
                    first_seq=r.seq, next_seq=r.seq, dropped=0, cpi=r.cpi, stamp_ns=(),
                    dx=(), dy=(), status=(), flags=(),
                )  # fmt: skip
                continue
            carried = in_reply.get(r.id)
            start = (asked or {}).get(r.id, since)
            if carried is not None and carried.first_seq - carried.dropped == start <= since:
                polls[r.id] = carried if start == since else polls_after(carried, since)
                continue
            if not client.service_is_ready():
                polls[r.id] = None
                continue
            req = request_type(id=r.id, since_seq=since, max_samples=r.seq - since)
            future = client.call_async(req)
            waiting[future] = r.id
            self.poll_fetches += 1
        if not waiting:
            self._emit_with_polls(reply, polls)
            return
        # as long as a data request may take: a fetch stuck at a node that died must not
        # hold back the first reply of the node that comes back
        self._poll_fetch = [reply, polls, waiting, time.monotonic() + self.timeout_s]
        for future in list(waiting):
            future.add_done_callback(self._on_polls)

    def _on_polls(self, future) -> None:
        fetch = self._poll_fetch
        if fetch is None or future not in fetch[2]:
            return  # abandoned by the watchdog
        device = fetch[2].pop(future)
        res = future.result()
        ok = res is not None and res.success
        fetch[1][device] = res if ok else None
        if not ok:
            self.poll_fetch_failures += 1
        if not fetch[2]:
            self._poll_fetch = None
            self._emit_with_polls(fetch[0], fetch[1])

    def _expire_poll_fetch(self, now: float) -> None:
        fetch = self._poll_fetch
        if fetch is None or (now <= fetch[3] and self._clients["get_samples"].service_is_ready()):
            return
        self._poll_fetch = None
        for future, device in fetch[2].items():
            self._clients["get_samples"].remove_pending_request(future)
            fetch[1][device] = None
            self.poll_fetch_failures += 1
        self._emit_with_polls(fetch[0], fetch[1])

    def _emit_with_polls(self, reply: Reply, polls: dict[str, object]) -> None:
        self._hand_on(
            Reply(reply.readings, received_s=reply.received_s, rtt_s=reply.rtt_s, polls=polls)
        )
        if self._poll_fetch is None:  # the replies that came meanwhile, then an owed request
            self._drain()

    # -- delivery to the GUI thread -------------------------------------------------------

    def _hand_on(self, reply: Reply) -> None:
        """Queue ``reply`` for the GUI thread; wake it only if nothing was waiting yet."""
        with self._inbox_lock:
            was_empty = not self._inbox
            self._inbox.append(reply)
        if was_empty:
            self._inbox_filled.emit()

    def _schedule_delivery(self) -> None:
        """GUI thread: take the inbox now, or one delivery interval after the last take."""
        if self._delivery.isActive():
            return
        wait = self._delivered_at + DELIVERY_INTERVAL_S - time.monotonic()
        self._delivery.start(max(0, round(wait * 1000)))

    def _deliver(self) -> None:
        """GUI thread: emit the replies waiting as one ``data_received``, oldest first."""
        with self._inbox_lock:
            batch, self._inbox = self._inbox, []
        self._delivered_at = time.monotonic()
        if batch:
            self.data_received.emit(batch)

    _SIGNALS: ClassVar[dict[str, tuple[str, str]]] = {
        "get_sensor_settings": ("settings_received", "settings_failed"),
        "get_samples": ("samples_received", "samples_failed"),
    }

    def _call(self, service: str, device: str, **fields) -> None:
        client = self._clients[service]
        if not client.service_is_ready():
            self._fail(service, device, f"{self.beagle}/{service} is not available")
            return
        try:
            request = self._types[service].Request(**fields)
        except (TypeError, ValueError, AssertionError) as e:
            self._fail(service, device, f"bad request: {e}")
            return
        future = client.call_async(request)
        deadline = time.monotonic() + self.call_timeout_s
        self._pending[future] = (service, device, deadline)
        future.add_done_callback(lambda f: self._on_reply(service, device, f))

    def _expire_calls(self, now: float) -> None:
        """Abandon settings/CPI/samples calls older than ``call_timeout_s`` (watchdog)."""
        for future, (service, device, deadline) in list(self._pending.items()):
            if now > deadline:
                del self._pending[future]
                self._clients[service].remove_pending_request(future)
                self._fail(service, device, f"no answer within {self.call_timeout_s:g} s")

    def _on_reply(self, service: str, device: str, future) -> None:
        if self._pending.pop(future, None) is None:
            return  # abandoned by the watchdog: its failure was already reported
        res = future.result()
        if res is None:
            return
        if service == "set_resolution":
            self.resolution_done.emit(device, bool(res.success), res.message, int(res.cpi))
        elif not res.success:
            self._fail(service, device, res.message)
        elif service == "get_sensor_settings":
            self.settings_received.emit(device, res.settings)
        else:
            self.samples_received.emit(device, res)

    def _fail(self, service: str, device: str, message: str) -> None:
        if service == "set_resolution":
            self.resolution_done.emit(device, False, message, 0)
        else:
            getattr(self, self._SIGNALS[service][1]).emit(device, message)

    def _watchdog(self) -> None:
        self._expire_calls(time.monotonic())
        self._expire_poll_fetch(time.monotonic())
        client = self._clients["get_sensor_data"]
        dropped = False
        while self._in_flight and self._in_flight[0].arrived is None and (
            time.monotonic() - self._in_flight[0].sent > self.timeout_s
        ):
            entry = self._in_flight.popleft()
            client.remove_pending_request(entry.future)
            self.dropped_requests += 1
            self._consecutive_failures += 1
            self.data_failed.emit(f"no reply within {self.timeout_s:g} s")
            if self._consecutive_failures >= 2:
                self._set_state(LOST)
            dropped = True
        if dropped:
            self._drain()  # those after it that came meanwhile
        if not client.service_is_ready() and self._state == CONNECTED:
            self._set_state(LOST)

    def _set_state(self, state: str) -> None:
        if state != self._state:
            self._state = state
            self.connection_changed.emit(state)

    @property
    def state(self) -> str:
        return self._state

    def stats(self) -> BridgeStats:
        """The link figures now (any thread)."""
        rtts = list(self._rtts)
        now = time.monotonic()
        times = [t for t in list(self._reply_times) if now - t <= 2.0]
        rate = (len(times) - 1) / (times[-1] - times[0]) if len(times) > 2 else 0.0
        return BridgeStats(
            self._state,
            statistics.median(rtts) if rtts else float("nan"),
            max(rtts) if rtts else float("nan"),
            rate,
            self.requests,
            self.replies,
            self.skipped_ticks,
            self.dropped_requests,
            self.failed_replies,
        )

    def _publish_stats(self) -> None:
        self.stats_updated.emit(self.stats())

    def _on_diagnostics(self, msg) -> None:
        prefix = self.beagle + ": "  # only the node watched (status names are its full name)
        out = {}
        for status in msg.status:
            if not status.name.startswith(prefix):
                continue
            values = {kv.key: kv.value for kv in status.values}
            values["level"] = int.from_bytes(status.level, "little") if isinstance(
                status.level, bytes
            ) else int(status.level)
            values["message"] = status.message
            out[status.hardware_id] = values
        if out:
            self.diagnostics_received.emit(out)


@dataclass
class _Request:
    """A data request out: its future, when it was sent and came back (time.monotonic(),
    s; None: not yet), the poll cursors it asked from (device -> seq), and whether another
    was out when it was sent."""

    future: object
    sent: float
    asked: dict[str, int]
    overlapped: bool = False
    arrived: float | None = None


def polls_after(polls, since: int):
    """``polls`` (a SensorPolls from ``first_seq - dropped``) from seq ``since`` on: the
    polls a reply before it already brought are cut off; those between ``since`` and its
    first (left the ring) are counted as ``dropped``. Same message type, per-poll
    arrays sliced (an array of another length, e.g. an empty ``poll_cpi``, is kept)."""
    first, n = int(polls.first_seq), len(polls.stamp_ns)
    skip = min(max(since - first, 0), n)
    fields = {}
    for name, kind in polls.get_fields_and_field_types().items():
        value = getattr(polls, name)
        if kind.startswith("sequence<") and len(value) == n:
            value = value[skip:]
        fields[name] = value
    fields["first_seq"] = first + skip
    fields["dropped"] = max(first - since, 0)
    return type(polls)(**fields)


def _qos_from_dict(q: dict):
    """An rclpy QoSProfile from rosbag2's v9 dict (history, depth, reliability, durability)."""
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    return QoSProfile(
        history=HistoryPolicy[q["history"].upper()],
        depth=int(q["depth"]),
        reliability=ReliabilityPolicy[q["reliability"].upper()],
        durability=DurabilityPolicy[q["durability"].upper()],
    )


def _qos_to_dict(p) -> dict:
    """rosbag2's v9 dict of an rclpy QoSProfile (a publisher's offered QoS)."""

    def span(d) -> dict:
        sec, nsec = divmod(int(d.nanoseconds), 1_000_000_000)
        return {"sec": sec, "nsec": nsec}

    return {
        "history": p.history.name.lower(),
        "depth": int(p.depth),
        "reliability": p.reliability.name.lower(),
        "durability": p.durability.name.lower(),
        "deadline": span(p.deadline),
        "lifespan": span(p.lifespan),
        "liveliness": p.liveliness.name.lower(),
        "liveliness_lease_duration": span(p.liveliness_lease_duration),
        "avoid_ros_namespace_conventions": bool(p.avoid_ros_namespace_conventions),
    }
