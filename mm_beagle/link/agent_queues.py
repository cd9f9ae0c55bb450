"""The agent's hand-over between its threads: jobs, lanes, the outbox and the inboxes.

The poll thread never waits on a peer: zenoh's callbacks put requests in an
:class:`Inbox` per key (bounded, the overflow counted), the worker threads hand the poll
thread a :class:`Job` in a bounded :class:`Lane` (one step of at most ``budget_s`` per
service), and the poll thread hands its messages to the sender thread through the
:class:`Outbox` (bounded, the oldest dropped). Used by :mod:`mm_beagle.link.agent`.
"""

from __future__ import annotations

import collections
import queue
import threading
import time
from collections.abc import Callable, Generator

from mm_beagle.link.agent_requests import MAX_REQUEST_BYTES, Refusals

LANE_SIZE = 2  # jobs waiting per lane (each worker waits for its own: at most one)
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
    here (on a zenoh thread, briefly); one whose payload is over ``max_bytes`` or that
    finds :data:`QUERY_QUEUE` waiting is dropped and counted at once (a dropped query
    ends for its sender with no reply), so what waits holds at most ``max_bytes`` each
    (zenoh delivers up to 64 KiB: 16 of those per key were 2 MB of the agent's RSS)."""

    def __init__(self, key: str, refusals: Refusals, max_bytes: int = MAX_REQUEST_BYTES) -> None:
        self.key, self.refusals, self.max_bytes = key, refusals, max_bytes
        self.queue: queue.Queue = queue.Queue(QUERY_QUEUE)
        self.closed = False

    def put(self, request: object) -> None:
        payload = getattr(request, "payload", None)
        if payload is not None and (size := len(payload)) > self.max_bytes:
            self.refusals.refuse(
                self.key,
                "size",
                f"{self.key} request of {size} bytes is too large (limit {self.max_bytes})",
            )
            return
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
