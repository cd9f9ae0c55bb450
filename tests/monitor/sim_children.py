"""Child functions for SimJob tests (importable by a spawn-started process)."""

from __future__ import annotations

import time


def fail(seed: int, conn) -> None:
    raise RuntimeError(f"no run for seed {seed}")  # the child dies without sending


def report_error(seed: int, conn) -> None:
    conn.send(("error", f"ValueError: seed {seed} refused"))
    conn.close()


def hang(seed: int, conn) -> None:
    time.sleep(60)  # a run that never ends: the test cancels it
