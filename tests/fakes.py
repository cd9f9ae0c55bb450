"""Small test doubles shared by the test modules (import: ``from fakes import ...``)."""

from __future__ import annotations

import os
import time

#: every test timeout is multiplied by this (``MM_TEST_TIMEOUT_FACTOR=3`` on a slow or busy machine)
TIMEOUT_FACTOR = max(1.0, float(os.environ.get("MM_TEST_TIMEOUT_FACTOR", "1") or 1))


def scaled(seconds: float) -> float:
    """``seconds`` times :data:`TIMEOUT_FACTOR`: the deadline of a wait on a slow machine."""
    return seconds * TIMEOUT_FACTOR


def wait_until(predicate, timeout: float = 10.0, what: str = "the condition",
               interval: float = 0.02, pump=None):
    """Call ``predicate`` until it returns something truthy and return that.

    ``timeout`` (s) is scaled by :data:`TIMEOUT_FACTOR`; on expiry an AssertionError
    names ``what`` and how long it waited, so a slow machine's failure says what did not
    happen rather than a bare ``assert False``. ``interval`` (s) is the pause between calls.
    ``pump`` (no arguments), if given, runs before each pause: a Qt test passes
    ``QApplication.processEvents`` so the GUI's signals and timers are served meanwhile.
    """
    limit = scaled(timeout)
    deadline = time.monotonic() + limit
    while True:
        value = predicate()
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {limit:.1f} s waiting for {what}")
        if pump is not None:
            pump()
        time.sleep(interval)


class FakeClock:
    """A manual clock: tests set ``t`` (seconds); the emulator calls it. Handed to a
    driver as its ``sleep`` too, the driver's sleeps move it (one clock for both)."""

    def __init__(self, t: float = 0.0) -> None:
        self.t = t

    def __call__(self) -> float:
        return self.t

    def sleep(self, dt: float) -> None:
        self.t += dt


class FakeRing:
    """The Beagle node's totals and ring of single polls for a simulated run (no ROS).

    ``v``, ``w`` (and optionally ``vy``): the 1 kHz twist script of
    :mod:`mm_pc.sim.robot`; each poll's counts are the floor of the cumulative
    true counts at ``cpi`` (like the emulator), lifted polls count nothing and
    carry flag 1. ``low_quality`` (same shape as ``lifted``): polls whose chip saw the
    floor too poorly: flag 32, quality ``quality_low`` and the counts of ``junk``
    (n, k, 2) instead of the motion (default nothing), the others quality ``quality_ok``;
    ``quality_ok=None``: a chip without a figure (empty quality arrays, as an old node).
    Poll k (0-based) of every sensor has stamp ``t0_ns + (k+1) ms``.
    ``totals(k)`` are the node's totals after k polls; ``samples(i, since, max)``
    a ``get_samples`` reply (SimpleNamespace) with the ring's ``ring_size``.
    """

    def __init__(self, v, w, mounts=None, cpi=1600, lifted=None, ring_size=65536,
                 t0_ns=1_700_000_000_000_000_000, vy=None, low_quality=None, junk=None,
                 quality_ok=None, quality_low=5):
        import numpy as np

        from mm_pc.sim import robot
        from pln2033 import INCH_M

        self.mounts = tuple(mounts or robot.DEFAULT_MOUNTS)
        self.cpi, self.ring_size, self.t0_ns = cpi, ring_size, t0_ns
        self.v, self.w = np.asarray(v, float), np.asarray(w, float)
        n, k = len(self.v), len(self.mounts)
        step = np.empty((n, k, 2))
        for i, m in enumerate(self.mounts):
            step[:, i, 0], step[:, i, 1] = robot.sensor_displacements(
                self.v, self.w, robot.DT, m, vy)
        step *= cpi / INCH_M
        self.lifted = np.zeros((n, k), bool)
        if lifted is not None:
            lm = np.asarray(lifted, bool)
            self.lifted[:] = lm[:, None] if lm.ndim == 1 else lm
        self.low_quality = np.zeros((n, k), bool)
        if low_quality is not None:
            lq = np.asarray(low_quality, bool)
            self.low_quality[:] = lq[:, None] if lq.ndim == 1 else lq
        step[self.lifted | self.low_quality] = 0.0
        cum = np.floor(np.concatenate([np.zeros((1, k, 2)), np.cumsum(step, axis=0)]))
        self.counts = np.diff(cum, axis=0).astype(np.int64)  # (n, k, 2) per poll
        if junk is not None:
            self.counts[self.low_quality] = np.asarray(junk, np.int64)[self.low_quality]
        self.cum = np.concatenate(
            [np.zeros((1, k, 2), np.int64), np.cumsum(self.counts, axis=0)]
        )
        self.quality = (
            None if quality_ok is None
            else np.where(self.low_quality, quality_low, quality_ok).astype(np.int64)
        )
        self.n_polls = n
        self.scale = INCH_M / cpi

    def stamp(self, k):
        """Stamp (ns) of the newest poll after k polls (k = 0: the start)."""
        return self.t0_ns + k * 1_000_000

    def totals(self, k):
        from mm_pc.core.polls import SensorTotals

        return [
            SensorTotals(seq=k, stamp_ns=self.stamp(k), x_counts=int(self.cum[k, i, 0]),
                         y_counts=int(self.cum[k, i, 1]), x_m=float(self.cum[k, i, 0]) * self.scale,
                         y_m=float(self.cum[k, i, 1]) * self.scale)
            for i in range(len(self.mounts))
        ]

    def samples(self, i, since, max_samples, now):
        """get_samples of sensor i at the moment ``now`` polls were done."""
        from types import SimpleNamespace

        import numpy as np

        first = max(since, now - self.ring_size)
        end = now if max_samples <= 0 else min(now, first + max_samples)
        sl = slice(first, end)
        return SimpleNamespace(
            success=True, message="", first_seq=first, next_seq=end,
            dropped=max(0, first - since), cpi=self.cpi,
            stamp_ns=self.stamp(np.arange(first, end) + 1),
            dx=self.counts[sl, i, 0], dy=self.counts[sl, i, 1],
            status=np.zeros(end - first, np.int64),
            flags=np.where(self.lifted[sl, i], 1, 2) | np.where(self.low_quality[sl, i], 32, 0),
            quality=() if self.quality is None else self.quality[sl, i],
        )


def console_script(name: str, folder) -> str:
    """Write ``folder/name``: the script pip generates for the console script ``name`` of
    pyproject's ``[project.scripts]`` (so a test starts a program exactly as a user's shell
    does, even without the venv's bin/). Returns its path, to run with ``sys.executable``."""
    from pathlib import Path

    import tomllib

    root = Path(__file__).resolve().parents[1]
    scripts = tomllib.loads((root / "pyproject.toml").read_text())["project"]["scripts"]
    module, _, func = scripts[name].partition(":")
    path = Path(folder) / name
    path.write_text(
        f"import sys\nfrom {module} import {func}\n"
        f"if __name__ == '__main__':\n    sys.exit({func}())\n"
    )
    return str(path)
