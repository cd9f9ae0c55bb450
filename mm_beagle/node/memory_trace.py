"""A debug aid: where the node's Python memory grows (``MM_BEAGLE_TRACEMALLOC``).

``MM_BEAGLE_TRACEMALLOC=<seconds>`` in the node's environment starts :mod:`tracemalloc`
(25 frames) at start-up; every ``<seconds>`` s a daemon thread writes the :data:`TOP`
allocation sites that grew most since the baseline (taken after one period: the warm-up),
one line each: size difference (KiB), block-count difference, file:line. They go to
stderr, or appended to the file ``MM_BEAGLE_TRACEMALLOC_LOG`` names (the harness sends a
node's stderr to /dev/null). Unset, empty or not a positive number: nothing is started.
tracemalloc makes allocations 2-3x slower: for finding leaks, never in use.
"""

from __future__ import annotations

import os
import sys
import threading
import tracemalloc

ENV = "MM_BEAGLE_TRACEMALLOC"
LOG_ENV = "MM_BEAGLE_TRACEMALLOC_LOG"
TOP = 15


def period_from_env(environ: dict[str, str] | None = None) -> float | None:
    """The dump period (s) the environment asks for, or None (off)."""
    text = (os.environ if environ is None else environ).get(ENV, "").strip()
    try:
        period = float(text)
    except ValueError:
        return None
    return period if 0 < period < 1e6 else None


def growth_lines(
    base: tracemalloc.Snapshot, now: tracemalloc.Snapshot, top: int = TOP
) -> list[str]:
    """The ``top`` sites grown most from ``base`` to ``now``: "+KiB +blocks file:line"."""
    stats = now.compare_to(base, "lineno")
    stats.sort(key=lambda s: s.size_diff, reverse=True)
    return [
        f"{s.size_diff / 1024:+9.1f} KiB {s.count_diff:+8d} blocks  {s.traceback[0]}"
        for s in stats[:top]
    ]


def start(environ: dict[str, str] | None = None, stream=None) -> threading.Thread | None:
    """Start tracing and the dumping thread when the environment asks for it."""
    period = period_from_env(environ)
    if period is None:
        return None
    log = (os.environ if environ is None else environ).get(LOG_ENV, "")
    tracemalloc.start(25)
    out = stream or (open(log, "a", buffering=1) if log else sys.stderr)  # noqa: SIM115

    def dump() -> None:
        stop = threading.Event()
        stop.wait(period)
        base = tracemalloc.take_snapshot()
        n = 0
        while not stop.wait(period):
            n += 1
            now = tracemalloc.take_snapshot()
            lines = growth_lines(base, now)
            print(
                f"mm-beagle: tracemalloc growth after {n * period:g} s "
                f"(traced {tracemalloc.get_traced_memory()[0] / 2**20:.1f} MiB):",
                *lines,
                sep="\n  ",
                file=out,
                flush=True,
            )

    t = threading.Thread(target=dump, name="mm_tracemalloc", daemon=True)
    t.start()
    return t
