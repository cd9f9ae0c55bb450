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
events and status requests to a sender thread (:class:`Outbox`), and two worker threads
take the command queries and the history requests, refuse what is too large, too
frequent or malformed
(:mod:`mm_beagle.link.agent_requests`), and hand the rest to the poll thread as a
:class:`Job` in a bounded lane; the poll thread runs at most one step of each lane per
service (a patch load goes in steps of a few register transfers), and the workers send
the replies, so a peer that stops reading blocks at most its worker, never the poll.
History replies are at most :data:`HISTORY_REPLY_POLLS` polls and published with
congestion control DROP: a reader that stops reading misses them (the node asks again).
"""

from __future__ import annotations

import base64
import collections
import json
import os
import queue
import random
import sys
import threading
import time
import zlib
from collections.abc import Callable, Generator

from mm_beagle.link import link, link_auth
from mm_beagle.link.agent_requests import (
    COMMAND_KEYS,
    HISTORY_KEYS,
    MAX_REQUEST_BYTES,
    Refusals,
    TokenBucket,
    parse_request,
)
from mm_beagle.poller import commands
from mm_beagle.poller import shared_state as ss
from mm_beagle.poller.poller import Poller, PollerConfig

HEARTBEAT_S = 0.1  # an empty batch at least this often: the node's link watchdog
STATUS_S = 1.0
HISTORY_REPLY_POLLS = 4096  # polls per history reply (~94 kB); the node asks on for the rest
JOB_BUDGET_S = 0.003  # the longest the poll thread spends on one lane's job per service
JOB_TIMEOUT_S = 10.0  # a worker gives up on a job the poll thread has not finished by then
LANE_SIZE = 2  # jobs waiting per lane (each worker waits for its own: at most one)
COMMAND_RATE = (50.0, 50)  # commands per second and burst, all peers together (<= 100/s run)
HISTORY_RATE = (100.0, 50)  # history requests per second and burst, all peers together
QUERY_QUEUE = 16  # requests received and waiting for their worker, per key
OUTBOX_SIZE = 300  # messages waiting for the sender thread (3 s of batches)


class Job:
    """Work for the poll thread: a generator run in steps between polls (its return value is
    the answer), and the event its worker thread waits on."""

    __slots__ = ("cancelled", "done", "gen", "result")

    def __init__(self, gen: Generator[None, None, object]) -> None:
        self.gen = gen
        self.done = threading.Event()
        self.result: object = None
        self.cancelled = False

    def step(self, deadline: float) -> bool:
        """Run until the generator ends (True) or ``deadline`` (perf_counter s) passes."""
        try:
            while True:
                next(self.gen)
                if time.perf_counter() >= deadline:
                    return False
        except StopIteration as stop:
            self.result = stop.value
        except Exception as exc:  # never let one request stop the polls
            self.result = exc
        self.done.set()
        return True


def once(fn: Callable[..., object], *args: object) -> Generator[None, None, object]:
    """A job of one step: ``fn(*args)``."""
    return fn(*args)
    yield  # a generator, run by Job.step


class Lane:
    """Jobs of one kind waiting for the poll thread (appended by one worker thread)."""

    def __init__(self, size: int = LANE_SIZE) -> None:
        self.jobs: collections.deque[Job] = collections.deque()
        self.size = size
        self.current: Job | None = None

    def submit(self, job: Job) -> bool:
        if len(self.jobs) >= self.size:
            return False
        self.jobs.append(job)
        return True

    def step(self, budget_s: float) -> None:
        """The poll thread: one bounded step of the current job (or the next one)."""
        job = self.current
        while job is None:
            if not self.jobs:
                return
            job = self.jobs.popleft()
            if job.cancelled:  # its worker gave up before it started
                job = None
        self.current = None if job.step(time.perf_counter() + budget_s) else job


class Outbox:
    """Messages from the poll thread to the sender thread, (kind, bytes); at most
    :data:`OUTBOX_SIZE` wait, the oldest dropped beyond (the node fetches missed polls)."""

    def __init__(self, size: int = 0) -> None:
        self.items: collections.deque[tuple[str, bytes]] = collections.deque(
            maxlen=size or OUTBOX_SIZE
        )
        self.ready = threading.Event()
        self.closed = False
        self.dropped = 0

    def put(self, item: tuple[str, bytes]) -> None:
        if len(self.items) == self.items.maxlen:
            self.dropped += 1
        self.items.append(item)
        self.ready.set()

    def close(self) -> None:
        self.closed = True
        self.ready.set()


class Inbox:
    """Requests received on one key, waiting for its worker: zenoh's callback puts them
    here (on a zenoh thread, briefly); one that finds :data:`QUERY_QUEUE` waiting is
    dropped and counted (a dropped query ends at once for its sender, with no reply)."""

    def __init__(self, key: str, refusals: Refusals) -> None:
        self.key, self.refusals = key, refusals
        self.queue: queue.Queue = queue.Queue(QUERY_QUEUE)
        self.closed = False

    def put(self, request: object) -> None:
        try:
            self.queue.put_nowait(request)
        except queue.Full:
            self.refusals.refuse(self.key, "queue full", f"{QUERY_QUEUE} requests already wait")

    def get(self) -> object | None:
        """The next request, or None once closed."""
        while not self.closed:
            try:
                return self.queue.get(timeout=0.2)
            except queue.Empty:
                continue
        return None

    def close(self) -> None:
        self.closed = True


class AgentLink:
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
        self.ring_bytes = [
            [poller.state.ring_bytes(f, i) for f in ss.SharedState.RING_FIELDS] for i in range(n)
        ]
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
        n = ch.n
        first = max(first, end - n, 0)
        count = end - first
        arrays = []
        a = first % n
        for mv, item in zip(self.ring_bytes[ch.i], link.ARRAY_ITEM, strict=True):
            if a + count <= n:
                arrays.append(mv[a * item : (a + count) * item])
            else:
                arrays.append([mv[a * item :], mv[: (a + count - n) * item]])
        return link.Block(ch.i, first, count, ch.ints.tobytes(), ch.floats.tobytes(), arrays)

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

    def _worker(self, inbox: Inbox, answer: Callable[[object], None]) -> None:
        """Take requests from ``inbox`` until it is closed; never raise."""
        while (request := inbox.get()) is not None:
            try:
                answer(request)
            except Exception as exc:  # a reply that could not be sent (peer gone)
                self.refusals.refuse("reply", "reply failed", f"{exc!r}")

    def _job(self, lane: Lane, gen: Generator[None, None, object]) -> object:
        """Run ``gen`` on the poll thread and wait for its answer (exceptions returned)."""
        job = Job(gen)
        if not lane.submit(job):
            gen.close()
            raise commands.CommandRefusedError("the agent is busy with other requests; try again")
        if not job.done.wait(JOB_TIMEOUT_S):
            job.cancelled = True
            return RuntimeError(f"the poll thread did not answer within {JOB_TIMEOUT_S:g} s")
        return job.result

    def _command_query(self, query) -> None:
        """One command query: checked here, run on the poll thread, answered from here."""
        try:
            try:
                reply = self.answer_command(query.payload)
            except Exception as exc:  # a bug: still an answer, and the worker goes on
                self.refusals.refuse("command", "failed", repr(exc))
                reply = self._reply(commands.ERROR, f"agent failed: {exc!r}", [])
            query.reply(query.key_expr, reply, attachment=self.auth.tag("reply", reply))
        finally:
            query.drop()

    def answer_command(self, payload) -> bytes:
        """A command (ZBytes or bytes of JSON) -> reply JSON {"status", "payload", "seq"}."""
        try:
            if not self.command_rate.allow():
                raise _RefusedError("rate", f"more than {COMMAND_RATE[0]:g} commands/s; try again")
            msg = parse_request(_bounded_bytes(payload, "command"), "command", COMMAND_KEYS)
            cmd, i, args = commands.from_link(msg, self.poller.cfg.devices)
            if cmd.name == "info":  # the agent's own configuration: nothing on the poll thread
                seqs = [ch.seq for ch in self.poller.channels]
                return self._reply(commands.OK, self.info(), seqs)
            if cmd.name == "load_patch":
                gen = self.load_patch(i, self._patch_words(*args))
            else:
                gen = once(self.run_command, cmd.name, i, args)
            result = self._job(self.command_lane, gen)
        except (
            _RefusedError,
            link.LinkError,
            commands.CommandRefusedError,
        ) as exc:  # nothing changed
            reason = exc.reason if isinstance(exc, _RefusedError) else type(exc).__name__
            self.refusals.refuse("command", reason, str(exc))
            return self._reply(commands.INVALID, str(exc), [])
        if isinstance(result, Exception):
            self.refusals.refuse("command", "failed", repr(result))
            return self._reply(commands.ERROR, f"agent failed: {result!r}", [])
        status, body, seqs = result  # type: ignore[misc]
        return self._reply(status, body, seqs)

    def _reply(self, status: str, body: object, seqs: list) -> bytes:
        """A command reply: its status, payload, the seq after it, the boot that answers."""
        msg = {"status": status, "payload": body, "seq": seqs, "boot_id": self.boot_id}
        return json.dumps(msg).encode()

    def _patch_words(self, name: str) -> list[int]:
        """The words of patch file ``name`` in this agent's patch_dir, read on the worker
        thread: a file the chip's patch RAM cannot hold is refused unread.

        A peer names a file; it never sends a path elsewhere or the code itself."""
        from mm_beagle.poller.patches import (
            PatchPathError,
            check_patch_file_size,
            resolve_patch_file,
        )
        from pln2033.errors import PatchError
        from pln2033.pln2033 import read_patch_file

        try:
            path = resolve_patch_file(self.poller.cfg.patch_dir, name)
            check_patch_file_size(
                path, self.poller.regmap.memory_words - self.poller.regmap.patch_start
            )
            return read_patch_file(path)
        except (PatchPathError, PatchError) as exc:
            raise commands.CommandRefusedError(str(exc)) from None

    def _history_request(self, sample) -> None:
        reply = self.answer_history(sample.payload)
        if reply is not None:
            self.history_pub.put(reply, attachment=self.auth.tag("history", reply))

    def answer_history(self, payload) -> bytes | None:
        """Polls ``since`` onwards of one sensor (at most ``max``): a batch frame numbered
        by the request's ``id``, JSON saying why not, or None (rate limited: no answer)."""
        if not self.history_rate.allow():
            self.refusals.refuse(
                "history", "rate", f"more than {HISTORY_RATE[0]:g} history requests/s"
            )
            return None
        rid = None
        try:
            msg = parse_request(_bounded_bytes(payload, "history"), "history", HISTORY_KEYS)
            rid = msg.get("id")
            n = len(self.poller.channels)
            rid, i, since, most = commands.history_request(msg, n, link.MAX_HISTORY)
            result = self._job(self.history_lane, once(self.history_frame, rid, i, since, most))
            if isinstance(result, commands.CommandRefusedError):
                raise result
        except (_RefusedError, link.LinkError, commands.CommandRefusedError) as exc:
            self.refusals.refuse("history", type(exc).__name__, str(exc))
            rid = rid if isinstance(rid, int) and not isinstance(rid, bool) else None
            return json.dumps({"id": rid, "status": "invalid", "payload": str(exc)}).encode()
        if isinstance(result, Exception):
            self.refusals.refuse("history", "failed", repr(result))
            return json.dumps({"id": rid, "status": "error", "payload": repr(result)}).encode()
        return result  # type: ignore[return-value]

    def info(self) -> dict:
        cfg = self.poller.cfg
        return {
            "devices": cfg.devices,
            "backend": cfg.backend,
            "boot_id": self.boot_id,
            "ring_size": cfg.ring_size,
            "poll_rate": cfg.poll_rate,
            "cpi": cfg.cpi,
            "cpi_range": [self.poller.regmap.cpi_min, self.poller.regmap.cpi_max],
            "cpi_step": self.poller.regmap.cpi_step,
            "chips": self.poller.chips,
            "chip_cpi": [
                [ch.info.cpi.min, ch.info.cpi.max, ch.info.cpi.step] for ch in self.poller.channels
            ],
        }

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


class _RefusedError(Exception):
    """A request refused before it was parsed (``reason``: rate, size)."""

    def __init__(self, reason: str, text: str) -> None:
        super().__init__(text)
        self.reason = reason


def _bounded_bytes(payload, what: str) -> bytes:
    """A request's bytes (ZBytes or bytes), its size checked before it is copied."""
    if payload is None:
        return b""
    size = len(payload)
    if size > MAX_REQUEST_BYTES:
        raise _RefusedError(
            "size", f"{what} request of {size} bytes is larger than {MAX_REQUEST_BYTES}"
        )
    return payload if isinstance(payload, bytes) else payload.to_bytes()


class AgentPoller(Poller):
    """The poller with its link served every 10 ms instead of a pipe to a node."""

    service_period = 0.01

    def __init__(self, cfg: PollerConfig, state: ss.SharedState) -> None:
        # no pipes: their only users, emit and service, are overridden below
        super().__init__(cfg, state, None, None)  # type: ignore[arg-type]
        self.link: AgentLink | None = None

    def emit(self, kind: str, *args: object) -> None:
        text = " ".join(str(a) for a in args)
        print(f"mm-beagle-agent: {kind}: {text}", file=sys.stderr, flush=True)
        if self.link is not None:
            self.link.event(kind, args)

    def service(self) -> None:
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
