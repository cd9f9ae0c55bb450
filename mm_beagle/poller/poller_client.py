"""The node's handle on the poller process (no ROS here either).

Starts the poller with the ``spawn`` method (a fresh interpreter: nothing of
rclpy's threads is forked), shares the memory with it, sends commands over a
pipe and waits for the reply with a timeout, and stops it cleanly.
"""

from __future__ import annotations

import contextlib
import multiprocessing as mp
import sys
import threading
import time
from multiprocessing.connection import Connection
from typing import Any

from mm_beagle.poller import shared_state as ss
from mm_beagle.poller.poller import PollerConfig, run_poller

COMMAND_TIMEOUT_S = 2.0


class PollerError(RuntimeError):
    """The poller did not answer or is not running."""


class PollerClient:
    def __init__(self, cfg: PollerConfig) -> None:
        self.cfg = cfg
        ctx = mp.get_context("spawn")
        n = len(cfg.devices)
        self._buffer = ctx.RawArray("b", ss.SharedState.size(n, cfg.ring_size))
        self.state = ss.SharedState(self._buffer, n, cfg.ring_size)
        self.state.ints[:, ss.I_STATE] = ss.STATE_STARTING  # zeroed memory would read "down"
        self._ctx = ctx
        self._lock = threading.Lock()
        self.restarts = 0
        self._make_process()

    def _make_process(self) -> None:
        """A fresh (not yet started) poller process on the same shared memory."""
        ctx = self._ctx
        self._cmd, child_cmd = ctx.Pipe(duplex=True)
        self.events, child_events = ctx.Pipe(duplex=False)
        self.process = ctx.Process(
            target=run_poller,
            args=(self.cfg, self._buffer, child_cmd, child_events),
            name="mm_beagle_poller",
            daemon=True,
        )
        self._abandoned = 0  # commands that timed out; their late replies are dropped
        self._child_ends: tuple[Connection, Connection] = (child_cmd, child_events)
        self._ps: Any = None  # the poller's psutil.Process, made on first use
        self._cpu_last: tuple[float, float] | None = None

    def start(self) -> None:
        """Spawn the poller; it imports only the poller modules, not the node's main."""
        with _main_hidden():
            self.process.start()
        for end in self._child_ends:
            end.close()  # only the child holds these now: EOF tells us it died

    def restart(self) -> None:
        """Kill a stuck poller (SIGKILL: a stopped process never sees SIGTERM), start a new one.

        The new poller carries on from the shared totals (see channel.Channel);
        its sensors are initialised again, so counts the chips held are lost.
        """
        with self._lock:
            self.process.kill()
            self.process.join(2.0)
            self._cmd.close()
            self.events.close()
            self._make_process()
            self.restarts += 1
        self.start()

    @property
    def alive(self) -> bool:
        return self.process.is_alive()

    def index(self, device: str) -> int | None:
        try:
            return self.cfg.devices.index(device)
        except ValueError:
            return None

    def command(self, *msg: object, timeout: float = COMMAND_TIMEOUT_S) -> tuple[str, object]:
        """Send one command, wait for its reply: ("ok"|"invalid"|"error", payload)."""
        with self._lock:
            if not self.alive:
                raise PollerError("the poller process is not running")
            self._cmd.send(msg)
            self.state.glob[ss.G_COMMANDS_SENT] += 1  # after the send: the poller then finds it
            deadline = time.monotonic() + timeout
            # The poller answers in order: replies to commands we gave up on come first.
            while True:
                if not self._cmd.poll(max(0.0, deadline - time.monotonic())):
                    self._abandoned += 1
                    raise PollerError(f"the poller did not answer {msg[0]!r} within {timeout:g} s")
                reply = self._cmd.recv()
                if not self._abandoned:
                    return reply
                self._abandoned -= 1  # a late answer to an earlier command: drop it

    def unavailable(self) -> str:
        """Always '' here: a local poller that is gone stops the node instead."""
        return ""

    def link_values(self) -> dict[str, object]:
        """Nothing: the local backend has no link."""
        return {}

    def cpu_percent(self) -> float:
        """CPU use of the poller process since the previous call (% of one core)."""
        import psutil

        try:
            if self._ps is None:
                self._ps = psutil.Process(self.process.pid)
            t = self._ps.cpu_times()
        except (psutil.Error, ValueError):
            return float("nan")
        busy, wall = t.user + t.system, time.monotonic()
        last, self._cpu_last = self._cpu_last, (busy, wall)
        if last is None or wall <= last[1]:
            return float("nan")
        return 100.0 * (busy - last[0]) / (wall - last[1])

    def drain_events(self) -> list[tuple]:
        """Events the poller sent since the last call (non-blocking)."""
        out = []
        try:
            while self.events.poll():
                out.append(self.events.recv())
        except (EOFError, OSError):
            pass
        return out

    def stop(self, timeout: float = 3.0) -> None:
        """Ask the poller to stop; terminate it if it does not."""
        if self.alive:
            with contextlib.suppress(PollerError, OSError, EOFError):
                self.command("stop", timeout=timeout)
            self.process.join(timeout)
            if self.process.is_alive():
                self.process.terminate()
                self.process.join(1.0)
        self._cmd.close()
        self.events.close()


@contextlib.contextmanager
def _main_hidden():
    """Keep ``spawn`` from re-running ``__main__`` (the node: rclpy, ~20 MB) in the child.

    multiprocessing re-imports the parent's main module in a spawned child
    when it has a ``__spec__`` or ``__file__``; the poller needs none of it.
    """
    main = sys.modules.get("__main__")
    saved = {k: main.__dict__[k] for k in ("__spec__", "__file__") if k in main.__dict__}
    try:
        if "__spec__" in saved:
            main.__spec__ = None
        main.__dict__.pop("__file__", None)
        yield
    finally:
        main.__dict__.update(saved)
