"""Child functions for the SimJob priority test (importable by a spawn-started process)."""

from __future__ import annotations

import os

from mm_pc.monitor.model import sim_process


def report_niceness(seed: int, conn) -> None:
    """What build_in_child does first (lower its priority), then send the niceness."""
    before = os.nice(0)
    sim_process.lower_priority()
    conn.send(("ok", (before, os.nice(0))))
    conn.close()


def send_big(seed: int, conn) -> None:
    """A result of 3 MB (a simulated run is 2.8 MB), numbered bytes."""
    conn.send(("ok", bytes(range(256)) * (3_000_000 // 256)))
    conn.close()
