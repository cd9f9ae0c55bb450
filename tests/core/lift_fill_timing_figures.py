"""Prints the figures of docs/pose-math.md "Lifted sensors" (short lifts on the fill?).

Run from the repository: ``install/venv/bin/python tests/core/lift_fill_timing_figures.py``
(~20 s). The s-curves at 0.5 m/s for 20 s, 1600 CPI floored counts, 10 ms lifts twice a
second per sensor, through the PollTracker; final error in mm per 10 m, each method on
the fills (no lift mask) and switching / dropping (the mask), for lifts on whole polls
at a steady 1 ms, lifts placed in time, and the same with irregular polls. Then, for
lifts placed in time, each gap's filled counts against the true ones (both sensors, X
and Y, counts): RMS error and RMS error / the rule's sigma, for the rule per unit of
time (the polls' intervals, what the tracker uses) and per poll (no intervals: before).
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np

from mm_pc.core.filters import fill_lift_gaps
from mm_pc.core.geometry import DEFAULT_MOUNTS
from mm_pc.core.odometry import Odometry
from mm_pc.core.polls import PollBatch, PollTracker, SensorTotals
from mm_pc.sim import robot as sim
from pln2033 import INCH_M

# tests/fakes.py by its path (tests/ on sys.path would shadow pln2033 with tests/pln2033)
_spec = importlib.util.spec_from_file_location(
    "fakes", Path(__file__).resolve().parents[1] / "fakes.py"
)
assert _spec is not None and _spec.loader is not None
_fakes = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(_fakes)
FakeRing = _fakes.FakeRing

CPI = 1600
SCALE = INCH_M / CPI
V, W = sim.s_curves(speed=0.5, duration=20.0)
N = len(V)
TRUTH = sim.integrate_pose(V, W, sim.DT)[-1]
LENGTH = float(np.sum(np.abs(V)) * sim.DT)


def errors(steps) -> dict:
    out = {}
    for m in ("exact", "two-sensor"):
        for how, mask in (("fill", None), ("mask", steps.lifted)):
            odo = Odometry(DEFAULT_MOUNTS, m)
            odo.integrate(steps.dt, steps.d, lifted=mask)
            p = odo.pose.as_array()
            out[f"{m} {how}"] = round(float(np.hypot(*(p[:2] - TRUTH[:2]))) * 1e4 / LENGTH, 2)
    return out


def whole_polls(seed: int = 3) -> dict:
    rng = np.random.default_rng(seed)
    lifted = np.zeros((N, 2), bool)
    for i in range(2):
        for s in rng.uniform(0, N - 20, 40).astype(int):
            lifted[s : s + 10, i] = True
    ring = FakeRing(V, W, lifted=lifted)
    tr = PollTracker(2)
    tr.baseline(ring.totals(0))
    batches = [PollBatch.from_reply(ring.samples(i, 0, N, N)) for i in (0, 1)]
    return errors(tr.step(ring.totals(N), batches))


def in_time(jitter: bool, seed: int = 3, gap_errors: bool = False) -> dict:
    rng = np.random.default_rng(seed)
    dt = np.full(N, 1e-3)
    if jitter:  # mean 1 ms, irregular, 1 % of the polls stalled 2-8 ms
        dt = rng.exponential(0.5e-3, N) + 0.5e-3
        stall = rng.random(N) < 0.01
        dt[stall] += rng.uniform(2e-3, 8e-3, stall.sum())
    tt = np.arange(N + 1) * sim.DT
    t = np.concatenate([[0.0], np.cumsum(dt)])
    t = t[t <= tt[-1]]
    k = len(t) - 1
    counts, lifted, true = [], [], []
    for m in DEFAULT_MOUNTS:
        cx, cy = sim.cumulative_sensor_path(V, W, sim.DT, m)
        lw = np.zeros(k, bool)
        for s0 in rng.uniform(0, tt[-1] - 0.02, 40):
            lw |= (t[1:] > s0) & (t[:-1] < s0 + 0.01)
        inc = np.stack([np.diff(np.interp(t, tt, cx)), np.diff(np.interp(t, tt, cy))], -1) / SCALE
        true.append(inc.copy())
        inc[lw] = 0.0
        cum = np.floor(np.concatenate([[[0.0, 0.0]], np.cumsum(inc, 0)]))
        counts.append(np.diff(cum, axis=0).astype(np.int64))
        lifted.append(lw)
    stamps = (t[1:] * 1e9).astype(np.int64) + 10**18
    if gap_errors:
        dt_s = np.diff(np.concatenate([[10**18], stamps])) / 1e9
        return {rule: fill_errors(counts, lifted, true, d)
                for rule, d in (("per second", dt_s), ("per poll", None))}  # fmt: skip
    cum = [np.concatenate([[[0, 0]], np.cumsum(c, 0)]) for c in counts]

    def totals(j: int) -> list:
        return [SensorTotals(j, int(stamps[j - 1]) if j else 10**18, int(cum[i][j, 0]),
                             int(cum[i][j, 1]), float(cum[i][j, 0]) * SCALE,
                             float(cum[i][j, 1]) * SCALE) for i in range(2)]  # fmt: skip

    tr = PollTracker(2)
    tr.baseline(totals(0))
    batches = [PollBatch(0, k, 0, CPI, stamps, counts[i][:, 0], counts[i][:, 1],
                         np.where(lifted[i], 1, 2)) for i in range(2)]  # fmt: skip
    return errors(tr.step(totals(k), batches))


def fill_errors(counts, lifted, true, dt) -> dict:
    err, z = [], []
    for c, lw, tr in zip(counts, lifted, true, strict=True):
        filled, gaps = fill_lift_gaps(c, lw, dt=dt)
        for a, b, sigma in gaps:
            e = filled[a:b].sum(0) - tr[a:b].sum(0)
            err.extend(e)
            z.extend(e / sigma)
    rms = lambda v: round(float(np.sqrt(np.mean(np.square(v)))), 2)  # noqa: E731
    return {"gaps": len(err) // 2, "rms err counts": rms(err), "rms err/sigma": rms(z)}


if __name__ == "__main__":
    print("lifts on whole polls, steady 1 ms:", whole_polls())
    print("lifts placed in time, steady 1 ms:", in_time(False))
    print("lifts placed in time, irregular polls:", in_time(True))
    print("fill vs truth per gap, steady 1 ms:", in_time(False, gap_errors=True))
    print("fill vs truth per gap, irregular polls:", in_time(True, gap_errors=True))
