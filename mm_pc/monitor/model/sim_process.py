"""The simulated mowing run built in a process of its own (no Qt).

:func:`mm_pc.monitor.model.maps.build_sim_run` takes 2.5-7 s of pure Python
and numpy; on a thread it held the interpreter lock and the monitor's window
stuttered for that long. :class:`SimJob` runs it in a ``spawn``-started
process (no copy of the GUI's Qt or rclpy state) and hands the result back
through a pipe, pickled (~2.8 MB for seed 1). The GUI polls :meth:`SimJob.poll`
from its timer (never blocks) and may :meth:`SimJob.cancel` (the process is
terminated).
"""

from __future__ import annotations

import multiprocessing
import time

__all__ = ["SimJob", "build_in_child"]


def build_in_child(seed: int, conn) -> None:
    """The child's work: build the run for ``seed`` and send ("ok", run) or ("error", text)."""
    try:
        from mm_pc.monitor.model.maps import build_sim_run

        conn.send(("ok", build_sim_run(int(seed))))
    except Exception as e:  # anything: the GUI shows it in the view
        conn.send(("error", f"{type(e).__name__}: {e}"))
    finally:
        conn.close()


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

    @property
    def elapsed_s(self) -> float:
        return time.monotonic() - self.started

    def poll(self) -> tuple[str, object] | None:
        """None while running; then once ("ok", SimRun) or ("error", message)."""
        if self.done:
            return None
        try:
            if not self._recv.poll():
                return None
            result = self._recv.recv()
        except (EOFError, OSError):
            self.process.join(1.0)
            result = ("error", f"the simulation process ended without a result "
                               f"(exit code {self.process.exitcode})")
        self._finish()
        return result

    def cancel(self) -> None:
        """Stop the child (terminated) and forget it; poll() returns None afterwards."""
        if self.done:
            return
        if self.process.is_alive():
            self.process.terminate()
        self._finish()

    def _finish(self) -> None:
        self.done = True
        self.process.join(2.0)
        if self.process.is_alive():
            self.process.kill()
            self.process.join(1.0)
        self._recv.close()
