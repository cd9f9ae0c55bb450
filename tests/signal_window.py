"""Issue 27 item 7: a signal in the first ms of a console script's start-up (a measurement,
not a test; docs/beagle-node.md "Signals during start-up").

    install/venv/bin/python tests/signal_window.py outcomes [PROG] [RUNS]
    install/venv/bin/python tests/signal_window.py handler-in [RUNS]
    install/venv/bin/python tests/signal_window.py start-time [RUNS]

``outcomes``: for SIGTERM and SIGINT at 10, 20, 35 and 50 ms after the start, RUNS starts of
PROG (mm-watch) as pip's console script (fakes.console_script) in the environment of a shell
that sourced install/setup.bash (which presets the ROS wheels' re-exec: one interpreter
start), and in the same without _ROS_WHEELS_BOOTSTRAP_COMPLETE (the .pth re-executes the
interpreter, as with the setup.bash before issue 27); what happened to each. A command
still running 5 s after the signal is "signal lost", killed.
``handler-in``: when the SIGTERM handler is in (/proc/PID/status SigCgt), ms after the
start, of mm-watch's launcher and of a script whose first line installs one, both ways,
interleaved. ``start-time``: ``mm-watch --help`` from start to exit, both ways interleaved.
Run with install/setup.bash sourced.
"""

from __future__ import annotations

import collections
import json
import os
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
from fakes import console_script

ARGS = {"mm-watch": ["--namespace", "/nobody"]}
BARE = (
    "import _signal, os\n_signal.signal(15, lambda s, f: os._exit(0))\nimport time\ntime.sleep(5)\n"
)


def environments() -> dict[str, dict[str, str]]:
    """As a shell that sourced install/setup.bash starts a command (since issue 27: with the
    bootstrapper's re-exec preset, one start), and the same without the preset (two starts:
    the setup.bash before)."""
    root = Path(__file__).resolve().parents[1]
    bare = {"PATH": "/usr/bin:/bin", "HOME": os.environ.get("HOME", "/")}
    dump = "import json, os; print(json.dumps(dict(os.environ)))"
    out = subprocess.run(
        ["bash", "-c", f"source {root}/install/setup.bash && python -c '{dump}'"],
        env=bare, capture_output=True, text=True, check=True,
    )  # fmt: skip
    once = json.loads(out.stdout)
    twice = {k: v for k, v in once.items() if k != "_ROS_WHEELS_BOOTSTRAP_COMPLETE"}
    return {"setup.bash before (re-exec)": twice, "setup.bash now (one start)": once}


def outcome(p: subprocess.Popen, sig: signal.Signals, prog: str) -> str:
    try:
        _, err = p.communicate(timeout=5)
    except subprocess.TimeoutExpired:
        p.kill()
        p.communicate()
        return "signal lost (still running 5 s later)"
    text = err.decode(errors="replace")
    name = "Ctrl-C" if sig == signal.SIGINT else sig.name
    if text.strip().endswith(f"{prog}: stopped by {name}") and p.returncode == 0:
        return "clean (0, one line)"
    if p.returncode < 0:
        return f"killed ({p.returncode}, {len(text.splitlines())} lines)"
    if "Traceback" in text or "KeyboardInterrupt" in text:
        return f"traceback ({p.returncode})"
    if p.returncode == 0 and not text.strip():
        return "clean (0, silent)"
    return f"other ({p.returncode}: {text.strip()[-80:]!r})"


def outcomes(folder: str, prog: str, runs: int) -> None:
    script = console_script(prog, folder)
    for label, env in environments().items():
        for sig in (signal.SIGTERM, signal.SIGINT):
            for delay_ms in (10, 20, 35, 50):
                seen: collections.Counter = collections.Counter()
                for _ in range(runs):
                    p = subprocess.Popen(
                        [sys.executable, script, *ARGS.get(prog, [])], env=env, cwd=folder,
                        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                    )  # fmt: skip
                    time.sleep(delay_ms / 1000)
                    p.send_signal(sig)
                    seen[outcome(p, sig, prog)] += 1
                print(f"{label}: {sig.name} at {delay_ms} ms: {dict(seen)}", flush=True)


def _caught(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/status") as f:
            caught = next(ln for ln in f if ln.startswith("SigCgt:")).split()[1]
    except (OSError, StopIteration):
        return False
    return bool(int(caught, 16) >> (signal.SIGTERM - 1) & 1)


def handler_in(folder: str, runs: int) -> None:
    watch = console_script("mm-watch", folder)
    (bare := Path(folder) / "bare").write_text(BARE)
    cases = {
        (label, what): (argv, env)
        for label, env in environments().items()
        for what, argv in (
            ("mm-watch launcher", [sys.executable, watch, *ARGS["mm-watch"]]),
            ("handler on line 1", [sys.executable, str(bare)]),
        )
    }
    took: dict = {k: [] for k in cases}
    for _ in range(runs):
        for k, (argv, env) in cases.items():
            p = subprocess.Popen(
                argv, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL
            )
            t0 = time.monotonic()
            while not _caught(p.pid) and time.monotonic() - t0 < 5:
                pass
            took[k].append((time.monotonic() - t0) * 1000)
            p.kill()
            p.wait()
    for (label, what), ms in took.items():
        ms.sort()
        print(
            f"{label:26s} {what:18s} handler in (ms): fastest {ms[0]:5.1f}  "
            f"median {statistics.median(ms):5.1f}  p90 {ms[int(len(ms) * 0.9)]:5.1f}"
        )


def start_time(folder: str, runs: int) -> None:
    """``mm-watch --help`` from start to exit, both environments interleaved: median ms."""
    watch = console_script("mm-watch", folder)
    envs = environments()
    took: dict = {label: [] for label in envs}
    for _ in range(runs):
        for label, env in envs.items():
            t0 = time.monotonic()
            subprocess.run([sys.executable, watch, "--help"], env=env, cwd=folder,
                           stdout=subprocess.DEVNULL, check=True)  # fmt: skip
            took[label].append((time.monotonic() - t0) * 1000)
    for label, ms in took.items():
        ms.sort()
        p90 = ms[int(len(ms) * 0.9)]
        print(f"{label:28s} mm-watch --help (ms): fastest {ms[0]:6.1f}  "
              f"median {statistics.median(ms):6.1f}  p90 {p90:6.1f}")  # fmt: skip


if __name__ == "__main__":
    what = sys.argv[1] if len(sys.argv) > 1 else "outcomes"
    with tempfile.TemporaryDirectory() as folder:
        print(f"load {os.getloadavg()[0]:.2f}", flush=True)
        if what == "start-time":
            start_time(folder, int(sys.argv[2]) if len(sys.argv) > 2 else 20)
        elif what == "outcomes":
            prog = sys.argv[2] if len(sys.argv) > 2 else "mm-watch"
            outcomes(folder, prog, int(sys.argv[3]) if len(sys.argv) > 3 else 20)
        else:
            handler_in(folder, int(sys.argv[2]) if len(sys.argv) > 2 else 40)
        print(f"load {os.getloadavg()[0]:.2f}")
