"""Issue 27 item 7 for mm-monitor: Ctrl-C and SIGTERM at fixed moments after the start (a
measurement, not a test; docs/monitor.md "Stopping").

    install/venv/bin/python tests/monitor_signal_moments.py [--runs 4] [MOMENT ...]

``mm-monitor --sim --headless --duration 30`` (the console script, install/setup.bash
sourced) gets SIGINT or SIGTERM MOMENT seconds after it was started (default 0.3 0.5 0.7
1.0 1.5: while it imports PySide6, while its node starts, just before and after its Qt loop
runs), RUNS times per signal. A run is clean if it exits 0 within 3 s with no traceback and
leaves nothing in its TMPDIR (the node's log folder); one still running 15 s after the
signal is aborted with faulthandler's stacks written to the run's folder, then killed.
"""

from __future__ import annotations

import argparse
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time


def one(moment: float, sig: signal.Signals, domain: str) -> tuple[int, float, bool, list]:
    """(exit code, seconds from the signal to the exit, traceback?, files left)."""
    folder = tempfile.mkdtemp(prefix="mm-signal-moment-")
    env = dict(os.environ, TMPDIR=folder, ROS_DOMAIN_ID=domain, PYTHONFAULTHANDLER="1")
    p = subprocess.Popen(["mm-monitor", "--sim", "--headless", "--duration", "30"], env=env,
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)  # fmt: skip
    time.sleep(moment)
    sent = time.monotonic()
    p.send_signal(sig)
    try:
        _out, err = p.communicate(timeout=15)
        seconds = time.monotonic() - sent
    except subprocess.TimeoutExpired:
        p.send_signal(signal.SIGABRT)  # faulthandler: where each thread was
        time.sleep(2)
        p.kill()
        _out, err = p.communicate()
        seconds = float("inf")
        with open(os.path.join(folder, "hung.stderr"), "w") as f:
            f.write(err)
    left = [n for n in os.listdir(folder) if n != "hung.stderr"]
    if "Traceback" in err:
        print(err, file=sys.stderr)
    if seconds != float("inf"):
        shutil.rmtree(folder, ignore_errors=True)
    return p.returncode, seconds, "Traceback" in err, left


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--runs", type=int, default=4)
    p.add_argument("moments", nargs="*", type=float, default=[0.3, 0.5, 0.7, 1.0, 1.5])
    args = p.parse_args()
    domain = str(100 + os.getpid() % 100)
    worst, clean, total = 0.0, 0, 0
    for moment in args.moments:
        for sig in (signal.SIGINT, signal.SIGTERM):
            for _ in range(args.runs):
                code, seconds, traceback, left = one(moment, sig, domain)
                ok = code == 0 and seconds <= 3 and not traceback and not left
                clean, total, worst = clean + ok, total + 1, max(worst, seconds)
                print(f"{moment:4.1f} s {sig.name:7} exit {code:3} in {seconds:5.2f} s"
                      f"{'' if ok else '  NOT CLEAN'}{' traceback' if traceback else ''}"
                      f"{' left ' + str(left) if left else ''}", flush=True)  # fmt: skip
    print(f"clean {clean} of {total}; longest exit {worst:.2f} s")
    return 0 if clean == total else 1


if __name__ == "__main__":
    sys.exit(main())
