"""The simulated mowing run built in a process of its own (no Qt).

:func:`mm_pc.monitor.model.maps.build_sim_run` takes 2.5-7 s of pure Python
and numpy; on a thread it held the interpreter lock and the monitor's window
stuttered for that long. :class:`SimJob` runs it in a ``spawn``-started
process (no copy of the GUI's Qt or rclpy state) and hands the result back
through a pipe, pickled (~2.8 MB for seed 1). The GUI polls :meth:`SimJob.poll`
from its timer (never blocks) and may :meth:`SimJob.cancel` (the process is
terminated).

The child lowers its own priority (``os.nice`` by :data:`CHILD_NICE`): on a 2-core PC
it otherwise took a core the window needed, and the window's event loop stalled up to
1.5 s at a load of 5 while the run was built (issue 29). On the GUI thread every poll is
short: the result's modules are imported one a poll while the child builds
(:data:`WARM_MODULES`), the result is read in slices and unpickled with the garbage
collector off (a full pass over the window's heap, set off by its 18 000 objects, took
0.2-1.6 s under load), and the child is not waited for once it has sent it. How long a
build takes is in docs/user-guide.md (measured by ``mm-bench gui``, ``stalls.sim_build_s``).
"""

from __future__ import annotations

import gc
import importlib
import multiprocessing
import os
import pickle
import struct
import time
from contextlib import suppress

__all__ = [
    "CHILD_NICE",
    "SIM_TYPICAL",
    "WARM_MODULES",
    "SimJob",
    "build_in_child",
    "lower_priority",
]

#: how long a build takes, as the view says it (``mm-bench gui``'s ``stalls.sim_build_s``:
#: 5.6-7.4 s on a 2-core PC at a load of 3-7; issue 29 saw ~40 s at a load of 5)
SIM_TYPICAL = "usually 5-15 s; longer while other programs keep the processor busy"
#: bytes of the result read per poll (the view polls every 33 ms; 2.8 MB take ~6 polls)
READ_SLICE = 1 << 19
#: the module of the result's classes (imported before the result is read)
RESULT_MODULE = "mm_pc.sim.field_run"
#: what importing it loads that the window has not (59 ms at a load of 0.5), imported one a
#: poll while the child builds (1-17 ms each), its own dependencies first
WARM_MODULES = (
    "mm_pc.core.fixes.gps",
    "mm_pc.core.fixes.perimeter",
    "mm_pc.core.fixes.wheels",
    "mm_pc.core.uncertainty",
    "mm_pc.core.fusion.ekf",
    "mm_pc.core.fusion.inputs",
    "mm_pc.core.fusion.loop",
    "mm_pc.core.maps.trilateration",
    "mm_pc.sim.robot",
    RESULT_MODULE,
)
#: how much the child lowers its priority (a nice increment): the window comes first
CHILD_NICE = 10


def build_in_child(seed: int, conn) -> None:
    """The child's work: build the run for ``seed`` and send ("ok", run) or ("error", text)."""
    lower_priority()
    try:
        from mm_pc.monitor.model.maps import build_sim_run

        conn.send(("ok", build_sim_run(int(seed))))
    except Exception as e:  # anything: the GUI shows it in the view
        conn.send(("error", f"{type(e).__name__}: {e}"))
    finally:
        conn.close()


def lower_priority() -> None:
    """Lower this process's priority by :data:`CHILD_NICE` (nothing where there is no nice)."""
    with suppress(OSError, AttributeError):  # no os.nice (Windows): the same run, unniced
        os.nice(CHILD_NICE)


def _unpickle(payload: bytes):
    """``pickle.loads`` without the garbage collector: the result's ~18 000 objects set off
    collections inside it, a full one of the window's heap among them (0.2-1.6 s at a load
    of 8-12, issue 29); 9 ms instead of 14-33 on a quiet PC. The objects are collected
    from the next automatic pass on."""
    enabled = gc.isenabled()
    gc.disable()
    try:
        return pickle.loads(payload)
    finally:
        if enabled:
            gc.enable()


class SimJob:
    """One simulation in a child process. ``seed``: the run's seed; ``started``:
    time.monotonic() at the start; ``target``: the child's function (tests pass one that
    fails or hangs)."""

    def __init__(self, seed: int, target=build_in_child) -> None:
        self.seed = int(seed)
        self.started = time.monotonic()
        ctx = multiprocessing.get_context("spawn")
        self._recv, send = ctx.Pipe(duplex=False)
        self.process = ctx.Process(target=target, args=(self.seed, send), daemon=True,
                                   name=f"mm-monitor-sim-{self.seed}")
        self.process.start()
        send.close()  # the child holds the other end: EOF when it dies
        self.done = False
        self._buffer = bytearray()  # the result's bytes so far
        self.slices = 0  # reads of the result so far (one a poll)
        self._to_import = list(WARM_MODULES)
        self.warmed = False  # WARM_MODULES imported (one a poll, before the first read)

    @property
    def elapsed_s(self) -> float:
        return time.monotonic() - self.started

    def poll(self) -> tuple[str, object] | None:
        """None while running (or while its result arrives); then once ("ok", SimRun) or
        ("error", message).

        The result is read in slices of :data:`READ_SLICE` bytes, one per call, as the child
        writes it: a whole ``recv()`` on the GUI thread waited for the child to push its
        2.8 MB through the pipe (80 ms on a quiet PC, several hundred under load). No
        thread reads it: a Python thread in a Qt program can run the garbage collector and
        destroy Qt objects off the GUI thread (a deadlock seen in PySide6 6.11)."""
        if self.done:
            return None
        try:
            if not self.warmed:
                # the result's classes imported one module a poll (59 ms in one poll, 124 ms
                # at a load of 8), so the poll that unpickles it (~37 ms) does not do both
                with suppress(ImportError):
                    importlib.import_module(self._to_import.pop(0))
                self.warmed = not self._to_import
            ready = self._recv.poll()
            # a child that died before taking its end of the pipe (spawn hands it over
            # through a helper thread of this process) never closes it: no EOF comes
            if not ready and self.process.exitcode is not None and not self._recv.poll(0.1):
                raise EOFError
            if not ready or not self.warmed:
                return None
            payload = self._read_slice()
            if payload is None:
                return None
            result = _unpickle(payload)
        except (EOFError, OSError):
            result = self._ended_without_result()
        except Exception as e:  # a result that does not unpickle here
            result = ("error", f"the simulation's result is unreadable: {e!r}")
        self._finish(wait=False)
        return result

    def _read_slice(self) -> bytes | None:
        """Read what is there of the message (multiprocessing's framing: a 4-byte big-endian
        length, or -1 and an 8-byte one); the payload once complete, else None."""
        chunk = os.read(self._recv.fileno(), READ_SLICE)
        self.slices += 1
        if not chunk:
            raise EOFError
        self._buffer += chunk
        buf = self._buffer
        if len(buf) < 4:
            return None
        (size,) = struct.unpack("!i", buf[:4])
        head = 4
        if size == -1:
            if len(buf) < 12:
                return None
            (size,) = struct.unpack("!Q", buf[4:12])
            head = 12
        if len(buf) < head + size:
            return None
        return bytes(buf[head : head + size])

    def _ended_without_result(self) -> tuple[str, str]:
        self.process.join(1.0)
        return ("error", f"the simulation process ended without a result "
                         f"(exit code {self.process.exitcode})")

    def cancel(self) -> None:
        """Stop the child (terminated) and forget it; poll() returns None afterwards."""
        if self.done:
            return
        if self.process.is_alive():
            self.process.terminate()
        self._finish()

    def _finish(self, wait: bool = True) -> None:
        """Done: the pipe closed; the child ended (``wait``: within 2 s, else killed).
        Without ``wait`` (it has sent everything) it is left to end on its own: a ``join``
        on the GUI thread waited for its interpreter's shutdown (19-29 ms at a load of 2.5,
        longer under load at its lower priority); it is reaped by the next process start,
        or at exit, as a daemon."""
        self.done = True
        if not wait:
            self.process.join(0)
            self._recv.close()
            return
        self.process.join(2.0)
        if self.process.is_alive():
            self.process.kill()
            self.process.join(1.0)
        self._recv.close()
