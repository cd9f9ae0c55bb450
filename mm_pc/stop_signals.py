"""How every mm-* command stops on Ctrl-C (SIGINT) and SIGTERM: soon, cleanly, with its children.

The console-script launcher (:func:`mm_pc.prerequisites.launch`) sets three phases:

1. **While the program imports** nothing has started (no child, no file written), so a
   signal writes one line, ``mm-beagle: stopped by SIGTERM`` (or ``by Ctrl-C``), and ends
   the process at once (``os._exit``: no lock is waited for, no traceback).
2. **While it runs** a signal becomes a KeyboardInterrupt in the main thread (SIGTERM as
   Ctrl-C), which the program's ``try``/``finally`` and ``with`` blocks clean up after;
   never while the main thread is inside the logging module or ``threading`` (a
   KeyboardInterrupt between a lock's acquire and its ``try`` leaves the lock held and the
   next log line deadlocks) or inside an installed package's code (PySide6 turned one that
   landed in its lazy attribute lookup into an AttributeError and a traceback). There it is
   put off by 20 ms at a time, at most 1 s (then raised wherever it lands). A second
   signal while stopping is ignored for 2 s, then ends the process and its children.
   A program with its own handlers (the nodes' :func:`mm_pc.ros.spin.init`, the agent,
   the monitor's Qt loop) replaces these when it installs them.
3. **At the end** any child process still running is ended (SIGTERM, SIGKILL 1 s later).

Exit status after a stop by signal: **0**, as the nodes' own handlers give: a user or a
supervisor asked for the stop and it went cleanly. A signal that was ignored when the
program started (``nohup``, a background job) stays ignored.
"""

from __future__ import annotations

import contextlib
import os
import signal
import threading
import time

EXIT_STOPPED = 0
SIGNALS = (signal.SIGINT, signal.SIGTERM)
#: while the main thread is in these files a KeyboardInterrupt could land inside a lock
_UNSAFE_FILES = (f"{os.sep}logging{os.sep}", f"{os.sep}threading.py")
_PACKAGES = (f"{os.sep}site-packages{os.sep}", f"{os.sep}dist-packages{os.sep}")
_OURS = frozenset({"mm_pc", "mm_beagle", "pln2033", "__main__"})
_DEFER_S = 0.02  # a put-off signal is sent again after this
_DEFER_MAX_S = 1.0  # and raised anyway after this
_SECOND_SIGNAL_S = 2.0  # a repeated signal within this of the first is ignored
_CHILD_GRACE_S = 1.0  # children get this long after SIGTERM, then SIGKILL


def signal_name(signum: int) -> str:
    return "Ctrl-C" if signum == signal.SIGINT else signal.Signals(signum).name


def stop_line(program: str, signum: int) -> str:
    """The one line a stop by signal prints on stderr."""
    return f"{program}: stopped by {signal_name(signum)}"


def _install(handler) -> None:
    for sig in SIGNALS:
        if signal.getsignal(sig) is not signal.SIG_IGN:
            signal.signal(sig, handler)


def during_import(program: str) -> None:
    """Phase 1: a signal ends the process at once with one line and exit 0."""

    def handler(signum, _frame) -> None:
        os.write(2, (stop_line(program, signum) + "\n").encode())
        os._exit(EXIT_STOPPED)

    _install(handler)


class _Running:
    """Phase 2's handler and what it remembers (the first signal, put-off ones)."""

    def __init__(self, program: str) -> None:
        self.program = program
        self.signum = 0  # the signal that started the stop (0: none yet)
        self.first = 0.0
        self.deferred_since = 0.0
        self._again = threading.Event()
        self._again_signum = 0
        # started now, not in the handler: starting a thread takes threading's own locks
        threading.Thread(target=self._redeliver, name="mm-stop-signals", daemon=True).start()

    def _redeliver(self) -> None:
        while True:
            self._again.wait()
            self._again.clear()
            time.sleep(_DEFER_S)
            os.kill(os.getpid(), self._again_signum)

    def handler(self, signum, frame) -> None:
        now = time.monotonic()
        if self.signum:  # already stopping
            if now - self.first > _SECOND_SIGNAL_S:
                os.write(2, f"{stop_line(self.program, signum)} (again: ending now)\n".encode())
                end_children(grace=0.0)
                os._exit(EXIT_STOPPED)
            return
        if in_unsafe_code(frame):
            self.deferred_since = self.deferred_since or now
            if now - self.deferred_since < _DEFER_MAX_S:
                self._again_signum = signum
                self._again.set()  # the event's own lock: the main thread never holds it
                return
        self.signum, self.first = signum, now
        raise KeyboardInterrupt


_running: _Running | None = None


def while_running(program: str) -> None:
    """Phase 2: a signal is a KeyboardInterrupt, raised only outside logging and threading."""
    global _running
    _running = _Running(program)
    _install(_running.handler)


def stopped_by() -> int:
    """The signal that stopped the program in phase 2 (SIGINT for a KeyboardInterrupt that
    came another way, e.g. Python's own Ctrl-C handler)."""
    return _running.signum if _running is not None and _running.signum else signal.SIGINT


def ignore_more() -> None:
    """The program is stopping: further signals must not interrupt its clean-up."""
    if _running is not None and not _running.signum:
        _running.signum, _running.first = signal.SIGINT, time.monotonic()


def in_unsafe_code(frame) -> bool:
    """Whether the main thread, at ``frame``, is inside logging, threading or an installed
    package other than ours (anywhere up its stack)."""
    while frame is not None:
        name = frame.f_code.co_filename
        if any(part in name for part in _UNSAFE_FILES):
            return True
        if any(part in name for part in _PACKAGES):
            module = str(frame.f_globals.get("__name__", ""))
            if module.partition(".")[0] not in _OURS:
                return True
        frame = frame.f_back
    return False


def end_children(grace: float = _CHILD_GRACE_S) -> list[int]:
    """SIGTERM every process this one started (and theirs) that still runs, SIGKILL after
    ``grace`` s. multiprocessing's resource tracker is left alone: it ignores both signals
    and ends when we do. Returns the pids it had to end."""
    try:
        import psutil
    except ImportError:  # a dependency; without it there is nothing to look at
        return []
    try:
        kids = [
            p
            for p in psutil.Process().children(recursive=True)
            if not any("resource_tracker" in part for part in _cmdline(p))
        ]
    except psutil.Error:
        return []
    for p in kids:
        with contextlib.suppress(psutil.Error):
            p.terminate()
    _gone, alive = psutil.wait_procs(kids, timeout=grace)
    for p in alive:
        with contextlib.suppress(psutil.Error):
            p.kill()
    psutil.wait_procs(alive, timeout=1.0)
    return [p.pid for p in kids]


def _cmdline(p) -> list[str]:
    import psutil

    try:
        return p.cmdline()
    except psutil.Error:
        return []
