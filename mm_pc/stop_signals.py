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

Before phase 1 nothing of ours runs: the interpreter starts, ``site`` runs the venv's
``.pth`` files (the ROS wheels' bootstrapper re-executes the interpreter once to set
LD_LIBRARY_PATH, unless ``_ROS_WHEELS_BOOTSTRAP_COMPLETE`` is set; the editable install's
finder imports pathlib and re), then pip's script imports ``commands``. A signal then gets
Python's defaults: SIGTERM ends the process with -15 and no line, SIGINT gives a
KeyboardInterrupt traceback (exit 1 or -2) or exit -2, or is rarely lost. How long that
window is (install/setup.bash presets the re-exec), measured, with the commands that
measure it: docs/beagle-node.md "Signals during start-up". The launcher's own imports are
~2 ms of it: no entry module can install a handler much earlier (tests/test_signals.py
keeps those imports light).

The ROS nodes' launchers end with :func:`exit_now` once the node has stopped cleanly: the
interpreter's finalisation (rclpy's and the DDS libraries' objects torn down one by one)
took seconds under load (docs/beagle-node.md "Signals while running").

Exit status after a stop by signal: **0**, as the nodes' own handlers give: a user or a
supervisor asked for the stop and it went cleanly. A signal that was ignored when the
program started (``nohup``, a background job) stays ignored.
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys
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


@contextlib.contextmanager
def at_once(program: str):
    """Phase 1 again inside the block: for a running program's heavy third-party imports
    made before it has started anything (mm-monitor's PySide6 and rclpy). A
    KeyboardInterrupt landing inside them came out as ``ImportError: libshiboken: could not
    import module 'PySide6.QtGui'`` and a traceback, or left an import lock held (a hang
    of over 15 s); here a signal ends the process with the one line instead. The handlers
    before the block are put back after it."""
    saved = {sig: signal.getsignal(sig) for sig in SIGNALS}
    during_import(program)
    try:
        yield
    finally:
        for sig, handler in saved.items():
            if handler is not None:
                signal.signal(sig, handler)


class _Running:
    """Phase 2's handler and what it remembers (the first signal, put-off ones)."""

    def __init__(self, program: str) -> None:
        self.program = program
        self.signum = 0  # the signal that started the stop (0: none yet)
        self.first = 0.0
        self.deferred_since = 0.0
        self.seen = 0  # the first signal received, put off or not
        self.raised = False  # a KeyboardInterrupt was raised for it
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
        self.seen = self.seen or signum
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
        self.signum, self.first, self.raised = signum, now, True
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


def seen() -> int:
    """The first signal phase 2 received (0: none), also one still put off or one whose
    KeyboardInterrupt a callback swallowed: a program replacing the handlers (a Qt loop
    about to run) acts on it."""
    return _running.seen if _running is not None else 0


def raised() -> bool:
    """Whether phase 2 raised a KeyboardInterrupt: an exception that ends the program after
    it is the stop's (shiboken turned one inside a lazy enum lookup into an
    AttributeError), not a fault."""
    return _running is not None and _running.raised


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


def exit_now(code: int) -> None:
    """End the process with ``code`` at once, without the interpreter's finalisation
    (never returns).

    Only once the program has stopped cleanly (a node: the poller stopped, the node
    destroyed, rclpy shut down, which also closes its log file). Flushed here: Python's
    logging, stdout and stderr; a child still running is ended (:func:`end_children`) and
    multiprocessing's resource tracker is let go and waited for, so nothing outlives us.
    """
    ignore_more()
    end_children()
    _end_resource_tracker()
    logging = sys.modules.get("logging")
    if logging is not None:
        logging.shutdown()
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):  # closed, or a reader that went away
            stream.flush()
    os._exit(code)


def _end_resource_tracker(timeout: float = 1.0) -> None:
    """multiprocessing's resource tracker (started with a spawned child: the poller) ends
    when the pipe we hold closes; without this it outlived an os._exit for a moment as an
    orphan. Waits at most ``timeout`` s (psutil), the pid is reaped."""
    module = sys.modules.get("multiprocessing.resource_tracker")
    tracker = getattr(module, "_resource_tracker", None)
    fd, pid = getattr(tracker, "_fd", None), getattr(tracker, "_pid", None)
    if fd is None or pid is None:
        return
    with contextlib.suppress(OSError):
        os.close(fd)
    tracker._fd = tracker._pid = None
    try:
        import psutil

        psutil.Process(pid).wait(timeout)
    except Exception:  # gone already, not ours, or still busy after timeout: let it be
        pass


def _cmdline(p) -> list[str]:
    import psutil

    try:
        return p.cmdline()
    except psutil.Error:
        return []
