"""Issue 27 item 7: how long the nodes take to exit on SIGINT/SIGTERM under load (a
measurement, not a test; docs/beagle-node.md "Signals while running").

    install/venv/bin/python tests/signal_exit_time.py [--runs 20] [--busy 3] [--before DIR]
        [PROG ...]

PROG: mm-beagle (backend sim), mm-odometry, mm-fusion (default: all three). With ``--busy``
loops (``python -c 'while True: pass'``) running all along, each PROG is started RUNS times
per signal as pip's console script (fakes.console_script) in a private ROS domain, and the
signal goes to its pid alone at a random moment 1-5 s after the start. Per PROG and signal,
over all runs and over those whose node was up at the signal (it had logged a line; under
load many signals land while the program still imports): exit time (s) from the signal to
the exit, max and median; clean runs (exit 0 within 3 s, no Traceback/KeyboardInterrupt on
stderr, no orphan); orphans (descendants seen while it ran still alive 0.5 s after it
exited). A run
still alive 20 s after the signal is killed and counted as such. ``--before DIR``: the
same runs, interleaved, also with the packages of an earlier commit
(``git archive COMMIT mm_pc mm_beagle pln2033 | tar -x -C DIR``, first on PYTHONPATH), so
both are measured under the same load. Run with install/setup.bash sourced.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import random
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import psutil

sys.path.insert(0, str(Path(__file__).parent))
from fakes import console_script

from mm_beagle.tools.harness import isolated_ros_env

ARGS = {
    "mm-beagle": ["--ros-args", "-p", "backend:=sim"],
    "mm-odometry": [],
    "mm-fusion": [],
}
STOP_WITHIN_S = 3.0
GIVE_UP_S = 20.0


def _descendants(ps: psutil.Process, seen: dict) -> None:
    with contextlib.suppress(psutil.Error):
        for child in ps.children(recursive=True):
            with contextlib.suppress(psutil.Error):
                seen.setdefault((child.pid, child.create_time()), child)


def _alive(seen: dict) -> list[psutil.Process]:
    left = []
    for child in seen.values():
        with contextlib.suppress(psutil.Error):
            if child.is_running() and child.status() != psutil.STATUS_ZOMBIE:
                left.append(child)
    return left


def _orphans(seen: dict) -> list[str]:
    """The command lines of the descendants still alive; killed."""
    left = []
    for child in _alive(seen):
        with contextlib.suppress(psutil.Error):
            left.append(" ".join(child.cmdline())[:100])
            child.kill()
    return left


def one_run(script: str, prog: str, sig: signal.Signals, env: dict, cwd: str) -> dict:
    """Start ``prog``, signal it 1-5 s later; exit time, exit code, stderr, orphans."""
    err_path = Path(cwd) / "stderr.txt"
    with open(err_path, "w") as err:
        proc = subprocess.Popen(
            [sys.executable, script, *ARGS.get(prog, [])],
            stdout=subprocess.DEVNULL, stderr=err, cwd=cwd, env=env,
        )  # fmt: skip
    try:
        return _signalled(proc, sig, err_path)
    finally:
        if proc.poll() is None:  # this script stopped mid-run
            proc.kill()
            proc.wait()


def _signalled(proc: subprocess.Popen, sig: signal.Signals, err_path: Path) -> dict:
    ps = psutil.Process(proc.pid)
    seen: dict = {}
    until = time.monotonic() + random.uniform(1.0, 5.0)
    while time.monotonic() < until and proc.poll() is None:
        _descendants(ps, seen)
        time.sleep(0.05)
    _descendants(ps, seen)
    if proc.poll() is not None:
        return {"code": proc.returncode, "seconds": None, "stderr": err_path.read_text(),
                "orphans": _orphans(seen), "before": True, "up": False}  # fmt: skip
    up = "] [" in err_path.read_text()  # a "[INFO] [stamp] [node]" line: the node exists
    sent = time.monotonic()
    proc.send_signal(sig)
    try:
        proc.wait(GIVE_UP_S)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
    seconds = time.monotonic() - sent
    time.sleep(0.5)  # a child ended by SIGTERM takes its moment
    left = _orphans(seen)
    return {"code": proc.returncode, "seconds": seconds, "stderr": err_path.read_text(),
            "orphans": left, "before": False, "up": up}  # fmt: skip


def _clean(run: dict) -> bool:
    text = run["stderr"]
    return (
        run["code"] == 0
        and run["seconds"] is not None
        and run["seconds"] <= STOP_WITHIN_S
        and "Traceback" not in text
        and "KeyboardInterrupt" not in text
        and not run["orphans"]
    )


def summary(runs: list[dict]) -> str:
    """Exit times (s), clean runs, runs over the bound, orphans, runs ended unsignalled."""
    took = sorted(r["seconds"] for r in runs if r["seconds"] is not None)
    clean = sum(_clean(r) for r in runs)
    return (
        f"runs {len(runs):2d}  exit (s): max {max(took, default=0):5.2f}  "
        f"median {statistics.median(took) if took else 0:5.2f}  clean {clean}/{len(runs)}  "
        f"over {STOP_WITHIN_S:g} s {sum(t > STOP_WITHIN_S for t in took)}  "
        f"orphans {sum(len(r['orphans']) for r in runs)}  "
        f"ended before the signal {sum(r['before'] for r in runs)}"
    )


def report(what: str, runs: list[dict]) -> None:
    for label, part in (("all", runs), ("node up", [r for r in runs if r["up"]])):
        print(f"{what} {label:8s} {summary(part)}  load {os.getloadavg()[0]:.2f}", flush=True)
    for r in [r for r in runs if not _clean(r)][:3]:
        tail = r["stderr"].strip().splitlines()[-3:]
        print(f"    not clean: code {r['code']}, {r['seconds']} s, {tail}, "
              f"orphans {r['orphans']}")  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("progs", nargs="*", metavar="PROG", help=", ".join(ARGS))
    parser.add_argument("--runs", type=int, default=20)
    parser.add_argument("--busy", type=int, default=3)
    parser.add_argument("--before", metavar="DIR", help="packages of an earlier commit")
    args = parser.parse_args()
    if unknown := set(args.progs) - set(ARGS):
        parser.error(f"unknown PROG {', '.join(sorted(unknown))}; known: {', '.join(ARGS)}")
    args.progs = args.progs or list(ARGS)
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(1))  # the busy loops end with us
    env = isolated_ros_env(keep_user_domain=False)
    variants = {"now": env}
    if args.before:
        path = [str(Path(args.before).resolve()), env.get("PYTHONPATH", "")]
        variants["before"] = {**env, "PYTHONPATH": os.pathsep.join(p for p in path if p)}
    busy = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(args.busy)]
    try:
        time.sleep(2.0)
        print(f"busy loops {args.busy}, load {os.getloadavg()[0]:.2f}", flush=True)
        with tempfile.TemporaryDirectory() as folder:
            for prog in args.progs:
                script = console_script(prog, folder)
                for sig in (signal.SIGINT, signal.SIGTERM):
                    runs: dict = {name: [] for name in variants}
                    for _ in range(args.runs):  # interleaved: the same load for each
                        for name, variant_env in variants.items():
                            runs[name].append(one_run(script, prog, sig, variant_env, folder))
                    for name, done in runs.items():
                        report(f"{prog:12s} {sig.name:7s} {name:6s}", done)
    finally:
        for p in busy:
            p.kill()
            p.wait()


if __name__ == "__main__":
    main()
