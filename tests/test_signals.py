"""Every command stops on SIGTERM and SIGINT at any moment: within 3 s, exit 0, no traceback,
no child process left (issue 27 item 7; mm_pc/stop_signals.py).

Each command is started as pip's console script starts it (tests/fakes.py console_script)
and signalled at three moments: while it imports (as soon as its SIGTERM handler is in:
/proc/PID/status SigCgt), right after start (0.8 s) and while it runs. The signal goes to
the command's own pid only (not its process group): its children must be ended by it.
"""

from __future__ import annotations

import signal
import subprocess
import sys
import time

import psutil
import pytest
from fakes import console_script, scaled

pytest.importorskip("rclpy")

import contextlib

from mm_beagle.tools.harness import free_port, isolated_ros_env

STOP_WITHIN_S = 3.0
#: (id, console script, arguments, seconds after start that count as "running")
COMMANDS = [
    ("beagle-sim", "mm-beagle", ["--ros-args", "-p", "backend:=sim"], 3.0),
    ("beagle-remote-no-agent", "mm-beagle", ["--ros-args", "-p", "backend:=remote"], 4.0),
    ("agent", "mm-beagle-agent", ["--backend", "sim", "--realtime-priority", "0"], 2.0),
    ("watch", "mm-watch", ["--namespace", "/nobody"], 2.5),
    ("odometry", "mm-odometry", [], 2.5),
    ("bench-agent", "mm-bench", ["agent", "--seconds", "1", "--drops", "1"], 3.0),
    ("bench-poll", "mm-bench", ["poll", "--seconds", "5"], 4.0),
    ("monitor-sim", "mm-monitor", ["--sim", "--headless", "--duration", "60"], 3.5),
]
MOMENTS = ("import", "start", "running")
CASES = [
    pytest.param(cmd, sig, moment, id=f"{cmd[0]}-{sig.name}-{moment}")
    for cmd in COMMANDS
    for sig, moment in (
        (signal.SIGTERM, "import"),
        (signal.SIGINT, "import"),
        (signal.SIGTERM, "start"),
        (signal.SIGINT, "start"),
        (signal.SIGTERM, "running"),
        (signal.SIGINT, "running"),
    )
]


def _catches_sigterm(pid: int) -> bool:
    """The process has a handler for SIGTERM (Python's default has none): ours is in."""
    try:
        with open(f"/proc/{pid}/status") as f:
            caught = next(ln for ln in f if ln.startswith("SigCgt:")).split()[1]
    except (OSError, StopIteration):
        return False
    return bool(int(caught, 16) >> (signal.SIGTERM - 1) & 1)


def _args(name: str, args: list[str]) -> list[str]:
    """Ports of this run: a free one for the agent to listen on, or a node to find nothing."""
    port = free_port()
    if name == "agent":
        return [*args, "--listen", f"tcp/127.0.0.1:{port}"]
    if name == "beagle-remote-no-agent":
        return [*args, "-p", f"agent:=tcp/127.0.0.1:{port}"]
    return args


def _descendants(proc: psutil.Process, seen: dict) -> None:
    try:
        for child in proc.children(recursive=True):
            seen.setdefault((child.pid, child.create_time()), child)
    except psutil.Error:
        pass


def _left(seen: dict) -> list[str]:
    left = []
    for child in seen.values():
        try:
            if child.is_running() and child.status() != psutil.STATUS_ZOMBIE:
                left.append(f"{child.pid} {' '.join(child.cmdline())[:100]}")
        except psutil.Error:
            pass
    return left


def signal_run(tmp_path, cmd, sig: signal.Signals, moment: str) -> dict:
    """Start ``cmd``, signal it at ``moment``; what happened (exit code, seconds to exit,
    stderr, children left). Kills whatever is left, so a failing run leaves nothing."""
    name, prog, args, running_s = cmd
    (bin_dir := tmp_path / "bin").mkdir(exist_ok=True)
    (cwd := tmp_path / "cwd").mkdir(exist_ok=True)
    script = console_script(prog, bin_dir)
    err_path = tmp_path / "stderr.txt"
    env = {
        **isolated_ros_env(),
        "PYTHONUNBUFFERED": "1",
        "QT_QPA_PLATFORM": "offscreen",
        "PYTHONFAULTHANDLER": "1",
    }  # a crash shows where it was
    with open(err_path, "w") as err:
        proc = subprocess.Popen(
            [sys.executable, script, *_args(name, args)],
            stdout=subprocess.DEVNULL, stderr=err, cwd=cwd, env=env,
        )  # fmt: skip
    ps = psutil.Process(proc.pid)
    seen: dict = {}
    started = time.monotonic()
    try:
        if moment == "import":
            deadline = started + scaled(10)
            while not _catches_sigterm(proc.pid) and time.monotonic() < deadline:
                time.sleep(0.001)
        else:
            until = started + (0.8 if moment == "start" else running_s)
            while time.monotonic() < until and proc.poll() is None:
                _descendants(ps, seen)
                time.sleep(0.05)
        assert proc.poll() is None, f"{prog} ended before the signal: {err_path.read_text()}"
        _descendants(ps, seen)
        sent = time.monotonic()
        proc.send_signal(sig)
        with contextlib.suppress(subprocess.TimeoutExpired):
            proc.wait(scaled(STOP_WITHIN_S))
        seconds = time.monotonic() - sent
        code = proc.poll()
        if code is not None:
            time.sleep(0.3)  # a child ended by SIGTERM takes its moment
        return {
            "code": code,
            "seconds": seconds,
            "stderr": err_path.read_text(errors="replace"),
            "left": _left(seen),
            "cwd": sorted(p.name for p in cwd.iterdir()),
        }
    finally:
        for child in [ps, *seen.values()]:
            with contextlib.suppress(psutil.Error):
                child.kill()
        proc.wait(scaled(10))


@pytest.mark.slow
@pytest.mark.parametrize(("cmd", "sig", "moment"), CASES)
def test_a_signal_at_any_moment_stops_the_command_cleanly(tmp_path, cmd, sig, moment):
    if cmd[1] == "mm-monitor":
        pytest.importorskip("PySide6")
    out = signal_run(tmp_path, cmd, sig, moment)
    tail = out["stderr"][-1500:]
    assert out["code"] is not None, f"still running {STOP_WITHIN_S} s after {sig.name}:\n{tail}"
    assert out["code"] == 0, tail
    assert out["seconds"] <= scaled(STOP_WITHIN_S)
    assert "Traceback" not in out["stderr"] and "KeyboardInterrupt" not in out["stderr"], tail
    assert out["left"] == [], out["left"]
    if moment == "import":  # one line says why it ended, nothing else was printed
        name = "Ctrl-C" if sig == signal.SIGINT else sig.name
        assert out["stderr"].strip().splitlines()[-1] == f"{cmd[1]}: stopped by {name}", tail
    assert out["cwd"] == []


def test_the_early_handler_ends_the_import_at_once_with_one_line(tmp_path):
    """Phase 1 in a bare interpreter: a SIGTERM during a slow import is one line, exit 0."""
    code = (
        "import os, signal, time\n"
        "from mm_pc import stop_signals\n"
        "stop_signals.during_import('mm-x')\n"
        "os.kill(os.getpid(), signal.SIGTERM)\n"
        "time.sleep(5)\n"
        "print('not reached')\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=scaled(30),
        cwd=tmp_path,
    )  # fmt: skip
    assert (out.returncode, out.stdout, out.stderr) == (0, "", "mm-x: stopped by SIGTERM\n")


def test_a_signal_inside_logging_is_put_off_until_the_lock_is_free(tmp_path):
    """Phase 2: a SIGINT that lands while the main thread is inside the logging module
    (a handler's lock held) is raised only once it has left it: the KeyboardInterrupt comes
    from the program's own line, the handler finished, and another thread can still log."""
    code = r"""
import logging, os, signal, threading, time
from mm_pc import stop_signals
stop_signals.while_running("mm-x")
log = logging.getLogger("x")
done = []

class Slow(logging.Handler):
    def emit(self, record):
        if record.msg == "slow":
            os.kill(os.getpid(), signal.SIGINT)  # lands inside handle(): its lock is held
            time.sleep(0.2)
            done.append(1)

log.addHandler(Slow())
log.setLevel(logging.INFO)
try:
    log.info("slow")
    time.sleep(5)
except KeyboardInterrupt as e:
    tb, where = e.__traceback__, []
    while tb:
        where.append(tb.tb_frame.f_code.co_name)
        tb = tb.tb_next
    t = threading.Thread(target=log.info, args=("after",))
    t.start()
    t.join(2)
    print(where[-2], len(done), "deadlock" if t.is_alive() else "clean")  # [-1]: the handler
    os._exit(0)
"""
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=scaled(30),
        cwd=tmp_path,
    )  # fmt: skip
    assert out.stdout.split() == ["<module>", "1", "clean"], out.stderr


def test_a_signal_inside_an_installed_package_is_raised_once_it_returns(tmp_path):
    """Phase 2: a SIGTERM that lands inside an installed package's code (PySide6 turned a
    KeyboardInterrupt inside its lazy lookups into an AttributeError) is raised only back in
    the caller, and the package's call ran to its end."""
    (pkgs := tmp_path / "site-packages").mkdir()
    (pkgs / "fakepkg.py").write_text(
        "import os, signal, time\n"
        "def work():\n"
        "    os.kill(os.getpid(), signal.SIGTERM)\n"
        "    time.sleep(0.2)\n"
        "    return 'finished'\n"
    )
    code = (
        "import sys, time\n"
        f"sys.path.insert(0, {str(pkgs)!r})\n"
        "from mm_pc import stop_signals\n"
        "import fakepkg\n"
        "stop_signals.while_running('mm-x')\n"
        "result = None\n"
        "try:\n"
        "    result = fakepkg.work()\n"
        "    time.sleep(5)\n"
        "except KeyboardInterrupt:\n"
        "    print(result, stop_signals.stopped_by())\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=scaled(30),
        cwd=tmp_path,
    )  # fmt: skip
    assert out.stdout.split() == ["finished", str(int(signal.SIGTERM))], out.stderr


def test_children_left_by_a_program_are_ended_with_it(tmp_path):
    """Phase 3: what launch() does at the end: every child still running is ended."""
    code = (
        "import subprocess, sys\n"
        "from mm_pc import stop_signals\n"
        "kid = subprocess.Popen([sys.executable, '-c', 'import time; time.sleep(60)'])\n"
        "ended = stop_signals.end_children(grace=2.0)\n"
        "print(ended == [kid.pid], kid.poll() is not None)\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=scaled(30),
        cwd=tmp_path,
    )  # fmt: skip
    assert out.stdout.split() == ["True", "True"], out.stderr
